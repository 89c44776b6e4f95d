"""Learner core: replay memory, Q-Graph and DDPG agent driven by 20-step training cycles (SPEC §2).

Shared by the ROS learner node and the fast experiment runner, so both learn identically. It only
sees transitions: ``add_transition`` after every RL step returns True when a cycle of
``cycle_steps`` steps is complete, then ``train_cycle`` runs ``iterations_per_cycle`` train steps
and bumps ``actor_version`` (the executor should switch to the new actor).

Zero actions: when ``zero_action`` is set, the never-executed self-loop ``(s', a_zero, r, s')`` goes
into the Q-Graph AND into replay memory. Decision and reason: the thesis trains the zero-action
variants (ch. 8.3.2.4 'vanilla-ZA' and 'QG-ZA', and the QG-DDPG condition of ch. 9.4.4) on data
enhanced with those loops, which turns loose ends into loops the critic itself is fitted on; a
vanilla DDPG run with the same ``zero_action`` therefore sees exactly the same replay data as
QG-DDPG, and one without it sees only executed steps.

Capacity: ``replay_capacity`` counts replay slots (zero-action loops included); the graph keeps the
same number of real transitions, so it always covers every transition still in replay.
"""

from __future__ import annotations

import dataclasses
import pathlib
from dataclasses import dataclass, field

import numpy as np
import torch

from qg_learning_node.ddpg import DDPG, DIAGNOSTIC_KEYS, DDPGConfig
from qg_learning_node.qgraph import TRANSITION_KINDS, QGraph
from qg_learning_node.replay import ReplayMemory

__all__ = ['LearnerConfig', 'LearnerCore']

_GRAPH_BOUNDS = ('qgraph', 'qgraph+apriori')


@dataclass(frozen=True)
class LearnerConfig:
    """Learner settings.

    :param ddpg: network and bound settings.
    :param replay_capacity: replay slots, ``None`` = unbounded (SPEC: also 300 in one study).
    :param use_qgraph: maintain the Q-Graph (required by the ``qgraph*`` bound modes; without them
        it only feeds the census diagnostics).
    :param zero_action: action that leaves the state unchanged, or ``None``.
    :param iterations_per_cycle: train steps after every cycle (SPEC: 10 or 50).
    :param cycle_steps: RL steps per training cycle.
    :param batch_size: minibatch size.
    :param census_every: recompute the graph census every this many cycles (it walks the whole
        graph, ~0.1 s per 80k transitions); the last census is reported in between.
    :param seed: seed of minibatch sampling (the networks use ``ddpg.seed``).
    """

    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    replay_capacity: int | None = None
    use_qgraph: bool = True
    zero_action: tuple[float, ...] | None = None
    iterations_per_cycle: int = 10
    cycle_steps: int = 20
    batch_size: int = 64
    census_every: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        if self.zero_action is not None:
            object.__setattr__(self, 'zero_action', tuple(float(x) for x in self.zero_action))
        if self.replay_capacity is not None and self.replay_capacity < 1:
            raise ValueError(f'replay_capacity must be >= 1 or None, got {self.replay_capacity}')
        if self.ddpg.bounds in _GRAPH_BOUNDS and not self.use_qgraph:
            raise ValueError(f'bounds={self.ddpg.bounds!r} needs use_qgraph=True')
        for name in ('iterations_per_cycle', 'cycle_steps', 'batch_size', 'census_every'):
            if getattr(self, name) < 1:
                raise ValueError(f'{name} must be >= 1, got {getattr(self, name)}')

    @classmethod
    def from_dict(cls, values: dict) -> 'LearnerConfig':
        unknown = set(values) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f'unknown learner config keys: {sorted(unknown)}')
        values = dict(values)
        if isinstance(values.get('ddpg'), dict):
            values['ddpg'] = DDPGConfig.from_dict(values['ddpg'])
        return cls(**values)


class LearnerCore:
    """Replay + Q-Graph + DDPG, trained in cycles.

    :param config: learner settings.
    :param state_dim: length of the scaled state.
    :param action_dim: length of the action.
    """

    def __init__(self, config: LearnerConfig, state_dim: int, action_dim: int) -> None:
        self.config = config
        self.state_dim, self.action_dim = state_dim, action_dim
        self.rng = np.random.default_rng(config.seed)
        self.zero_action = (None if config.zero_action is None
                            else np.asarray(config.zero_action, dtype=np.float64))
        if self.zero_action is not None and self.zero_action.shape != (action_dim,):
            raise ValueError(f'zero_action needs {action_dim} entries, '
                             f'got {len(config.zero_action)}')
        self.replay = ReplayMemory(config.replay_capacity, state_dim, action_dim)
        self.graph = (QGraph(config.ddpg.gamma, config.replay_capacity, self.zero_action)
                      if config.use_qgraph else None)
        self.agent = DDPG(config.ddpg, state_dim, action_dim)
        self.steps = 0
        self.actor_version = 0
        self._census: dict = {}

    def add_transition(self, s: np.ndarray, a: np.ndarray, r: float, s_next: np.ndarray,
                       terminal: bool) -> bool:
        """Store one executed step; True when a training cycle is due."""
        s, a = np.asarray(s, dtype=np.float64), np.asarray(a, dtype=np.float64)
        s_next = np.asarray(s_next, dtype=np.float64)
        self.replay.add(s, a, r, s_next, terminal)
        if self.zero_action is not None and not terminal and not np.array_equal(s, s_next):
            self.replay.add(s_next, self.zero_action, r, s_next, False, synthetic=True)
        if self.graph is not None:
            self.graph.add(s, a, r, s_next, terminal)
        self.steps += 1
        return self.steps % self.config.cycle_steps == 0

    def train_cycle(self) -> dict:
        """``iterations_per_cycle`` train steps; averaged diagnostics, census and actor version."""
        ddpg = self.config.ddpg
        totals = dict.fromkeys(DIAGNOSTIC_KEYS, 0.0)
        for _ in range(self.config.iterations_per_cycle):
            batch = self.replay.sample(self.config.batch_size, self.rng)
            if self.graph is not None:
                batch = batch._replace(
                    lower_bounds=self.graph.lower_bounds(batch.states, batch.actions))
            reward_range = self.replay.reward_range() if ddpg.bounds == 'empirical' else None
            context = (self.replay.trajectory_context(batch.indices, ddpg.he_horizon)
                       if ddpg.bounds == 'he2017' else None)
            diagnostics = self.agent.train_step(batch, reward_range, context)
            for key in DIAGNOSTIC_KEYS:
                totals[key] += diagnostics[key]
        result = {k: v / self.config.iterations_per_cycle for k, v in totals.items()}
        if self.graph is not None:
            if self.actor_version % self.config.census_every == 0:
                census = self.graph.census()
                self._census = {k: census[k] for k in (*TRANSITION_KINDS, 'total')}
            result.update(self._census)
        self.actor_version += 1
        result.update(actor_version=self.actor_version, steps=self.steps,
                      replay_size=len(self.replay))
        return result

    def save(self, path: pathlib.Path) -> None:
        """Checkpoint everything needed to continue exactly where this learner stands."""
        torch.save({
            'config': dataclasses.asdict(self.config),
            'dims': (self.state_dim, self.action_dim),
            'agent': self.agent.state_dict(),
            'replay': self.replay.state_dict(),
            'graph': None if self.graph is None else self.graph.state_dict(),
            'rng': self.rng.bit_generator.state,
            'steps': self.steps,
            'actor_version': self.actor_version,
            'census': self._census,
        }, pathlib.Path(path))

    @classmethod
    def load(cls, path: pathlib.Path) -> 'LearnerCore':
        state = torch.load(pathlib.Path(path), weights_only=False)
        core = cls(LearnerConfig.from_dict(state['config']), *state['dims'])
        core.agent.load_state_dict(state['agent'])
        core.replay.load_state_dict(state['replay'])
        if state['graph'] is not None:
            core.graph = QGraph.from_state_dict(state['graph'])
        core.rng.bit_generator.state = state['rng']
        core.steps, core.actor_version = state['steps'], state['actor_version']
        core._census = state['census']
        return core
