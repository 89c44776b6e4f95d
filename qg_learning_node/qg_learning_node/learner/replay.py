"""FIFO replay memory shared by vanilla DDPG and QG-DDPG, so both train on identical data.

Preallocated numpy arrays (converted to torch only in the train step). Bounded memories overwrite
the oldest slot; ``capacity=None`` grows by doubling. Lower bounds are not stored here: they change
as the Q-Graph grows, so the caller fills ``Batch.lower_bounds`` at sampling time.

Each real transition also remembers its trajectory neighbours (the previous and next real
transition of the same episode), which the n-step bounds of He et al. (2017) need. Synthetic
transitions (zero-action self-loops) have no neighbours and do not break the chain. Several
robots feeding one memory interleave their steps: each robot is its own ``stream``, and a
transition continues the chain of its own stream only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ['Batch', 'NStepContext', 'ReplayMemory']


class Batch(NamedTuple):
    """A minibatch; ``lower_bounds`` holds the graph bounds, ``-inf`` where unknown."""

    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_states: np.ndarray
    terminals: np.ndarray
    lower_bounds: np.ndarray
    indices: np.ndarray | None = None


class NStepContext(NamedTuple):
    """Up to ``horizon`` real transitions after and before each sampled one (He et al. 2017).

    ``future_*[:, j-1]`` describe transition t+j, ``past_*[:, j-1]`` transition t-j; ``*_valid``
    marks the ones that exist (a future chain stops after a terminal transition).
    """

    future_rewards: np.ndarray
    future_next_states: np.ndarray
    future_terminals: np.ndarray
    future_valid: np.ndarray
    past_states: np.ndarray
    past_actions: np.ndarray
    past_rewards: np.ndarray
    past_valid: np.ndarray


_FIELDS = ('states', 'actions', 'rewards', 'next_states', 'terminals', 'serial', 'prev', 'next')


class ReplayMemory:
    """Ring buffer of transitions.

    :param capacity: maximum number of stored transitions, ``None`` = unbounded.
    :param state_dim: length of a state vector.
    :param action_dim: length of an action vector.
    """

    def __init__(self, capacity: int | None, state_dim: int, action_dim: int) -> None:
        if capacity is not None and capacity < 1:
            raise ValueError(f'capacity must be >= 1 or None, got {capacity}')
        if state_dim < 1 or action_dim < 1:
            raise ValueError(f'dimensions must be >= 1, got {state_dim}, {action_dim}')
        self.capacity = capacity
        self.state_dim, self.action_dim = state_dim, action_dim
        self._allocate(capacity if capacity is not None else 1024)
        self._added = 0  # serial number of the next transition
        # per stream: serial of its last real transition, and that one's s' (None after a
        # terminal one), which the stream's next transition continues if it starts there
        self._chain_ends: dict[str, tuple[int, np.ndarray | None]] = {}

    def _allocate(self, size: int) -> None:
        self.states = np.zeros((size, self.state_dim))
        self.actions = np.zeros((size, self.action_dim))
        self.rewards = np.zeros(size)
        self.next_states = np.zeros((size, self.state_dim))
        self.terminals = np.zeros(size, dtype=bool)
        self.serial = np.full(size, -1, dtype=np.int64)  # -1 = empty slot
        self.prev = np.full(size, -1, dtype=np.int64)  # serial of the neighbours, -1 = none
        self.next = np.full(size, -1, dtype=np.int64)

    def _grow(self) -> None:
        old = {name: getattr(self, name) for name in _FIELDS}
        self._allocate(2 * len(self.rewards))
        for name, array in old.items():
            getattr(self, name)[:len(array)] = array

    def __len__(self) -> int:
        return min(self._added, len(self.rewards))

    def _slot(self, serial: np.ndarray) -> np.ndarray:
        return serial % len(self.rewards)

    def _alive(self, serial: np.ndarray) -> np.ndarray:
        """True where the transition with this serial is still stored."""
        ok = serial >= 0
        return ok & (self.serial[self._slot(np.where(ok, serial, 0))] == serial)

    def add(self, s: np.ndarray, a: np.ndarray, r: float, s_next: np.ndarray, terminal: bool,
            synthetic: bool = False, stream: str = '') -> None:
        """Store a transition; ``synthetic`` ones (never executed) stay out of trajectories.

        :param stream: the robot the transition comes from (one robot: the default).
        """
        if self.capacity is None and self._added == len(self.rewards):
            self._grow()
        serial = self._added
        slot = serial % len(self.rewards)
        self.states[slot], self.actions[slot], self.rewards[slot] = s, a, r
        self.next_states[slot], self.terminals[slot] = s_next, terminal
        self.serial[slot], self.prev[slot], self.next[slot] = serial, -1, -1
        if not synthetic:
            last_real, last_next_state = self._chain_ends.get(stream, (-1, None))
            last = np.array(last_real)
            if (last_next_state is not None and self._alive(last)
                    and np.array_equal(last_next_state, self.states[slot])):
                self.prev[slot] = last_real
                self.next[self._slot(last)] = serial
            self._chain_ends[stream] = (serial,
                                        None if terminal else self.next_states[slot].copy())
        self._added += 1

    def sample(self, batch_size: int, rng: np.random.Generator) -> Batch:
        """Uniform minibatch with replacement; lower bounds set to ``-inf``."""
        if len(self) == 0:
            raise ValueError('cannot sample from an empty replay memory')
        idx = rng.integers(0, len(self), size=batch_size)
        return Batch(self.states[idx], self.actions[idx], self.rewards[idx],
                     self.next_states[idx], self.terminals[idx], np.full(batch_size, -np.inf), idx)

    def reward_range(self) -> tuple[float, float]:
        """Lowest and highest stored reward (the 'empirical' bounds baseline)."""
        stored = self.rewards[:len(self)]
        return float(stored.min()), float(stored.max())

    def trajectory_context(self, indices: np.ndarray, horizon: int) -> NStepContext:
        """Neighbouring real transitions of the sampled slots, up to ``horizon`` steps each way."""
        n = len(indices)
        fut = (np.zeros((n, horizon)), np.zeros((n, horizon, self.state_dim)),
               np.zeros((n, horizon), dtype=bool), np.zeros((n, horizon), dtype=bool))
        past = (np.zeros((n, horizon, self.state_dim)), np.zeros((n, horizon, self.action_dim)),
                np.zeros((n, horizon)), np.zeros((n, horizon), dtype=bool))
        forward, forward_ok = self.next[indices], ~self.terminals[indices]
        backward, backward_ok = self.prev[indices], np.ones(n, dtype=bool)
        for j in range(horizon):
            forward_ok &= self._alive(forward)
            slot = self._slot(np.where(forward_ok, forward, 0))
            fut[0][:, j], fut[1][:, j] = self.rewards[slot], self.next_states[slot]
            fut[2][:, j], fut[3][:, j] = self.terminals[slot], forward_ok
            forward_ok = forward_ok & ~self.terminals[slot]
            forward = self.next[slot]
            backward_ok &= self._alive(backward)
            slot = self._slot(np.where(backward_ok, backward, 0))
            past[0][:, j], past[1][:, j] = self.states[slot], self.actions[slot]
            past[2][:, j], past[3][:, j] = self.rewards[slot], backward_ok
            backward = self.prev[slot]
        return NStepContext(*fut, *past)

    def state_dict(self) -> dict:
        state = {name: getattr(self, name)[:len(self.rewards)].copy() for name in _FIELDS}
        state.update(capacity=self.capacity, state_dim=self.state_dim, action_dim=self.action_dim,
                     added=self._added, chain_ends=dict(self._chain_ends))
        return state

    def load_state_dict(self, state: dict) -> None:
        if (state['capacity'], state['state_dim'], state['action_dim']) != (
                self.capacity, self.state_dim, self.action_dim):
            raise ValueError('replay state does not match this memory\'s capacity/dimensions')
        for name in _FIELDS:
            setattr(self, name, state[name].copy())
        self._added = state['added']
        self._chain_ends = dict(state['chain_ends'] if 'chain_ends' in state   # else: one robot
                                else {'': (state['last_real'], state['last_next_state'])})
