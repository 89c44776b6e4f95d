"""Learner core: replay memory, Q-Graph and DDPG agent driven by 20-step training cycles (SPEC §2).

Shared by the ROS learner node and the fast experiment runner, so both learn identically. It only
sees transitions: ``add_transition`` after every RL step returns True when training is due, then
``train_cycle`` runs the due train steps and bumps ``actor_version`` (the executor should switch
to the new actor). Two schedules decide when training is due:

* ``cycle`` (the thesis): ``iterations_per_cycle`` train steps after every ``cycle_steps`` steps;
* ``async`` (beyond the thesis, as SERL's actor-learner split): the learner keeps training while
  the robot moves, ``updates_per_step`` train steps per received transition on average, and
  hands out a new actor every ``publish_every`` train steps. The learner node runs it in its own
  thread; the in-process runner, which has no second thread, trains the same number of steps
  synchronously, so its results are the deterministic stand-in for the node's.

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

import numpy as np
import torch

from qg_learning_node.learner.ddpg import DDPG, DIAGNOSTIC_KEYS
from qg_learning_node.learner.learner_config import (
    RUNTIME_FIELDS,
    SCHEDULES,
    LearnerConfig,
    differences,
    with_runtime_settings,
)
from qg_learning_node.learner.qgraph import TRANSITION_KINDS, QGraph
from qg_learning_node.learner.replay import ReplayMemory

__all__ = ['LearnerConfig', 'LearnerCore', 'RUNTIME_FIELDS', 'SCHEDULES',
           'with_runtime_settings']


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
        self.graph = (QGraph(config.ddpg.gamma, config.replay_capacity, self.zero_action,
                             config.graph_resolution) if config.use_qgraph else None)
        self.agent = DDPG(config.ddpg, state_dim, action_dim)
        self.steps = 0
        self.updates = 0
        self.actor_version = 0
        self._census: dict = {}
        # Train steps owed beyond (steps // cycle_steps) * iterations_per_cycle: nonzero once a
        # run-time change of either (``reconfigure``) starts counting anew from where it stood.
        self._owed_offset = 0

    def add_transition(self, s: np.ndarray, a: np.ndarray, r: float, s_next: np.ndarray,
                       terminal: bool, robot: str = '') -> bool:
        """Store one executed step of ``robot`` (its trajectory stream in replay memory; one
        robot: the default); True when a training cycle is due."""
        s, a = np.asarray(s, dtype=np.float64), np.asarray(a, dtype=np.float64)
        s_next = np.asarray(s_next, dtype=np.float64)
        self.replay.add(s, a, r, s_next, terminal, stream=robot)
        if self.zero_action is not None and not terminal and not np.array_equal(s, s_next):
            self.replay.add(s_next, self.zero_action, r, s_next, False, synthetic=True)
        if self.graph is not None:
            self.graph.add(s, a, r, s_next, terminal)
        self.steps += 1
        return self.training_due()

    def training_due(self) -> bool:
        """Whether ``train_cycle`` should run now: train steps are owed for the transitions so
        far (false again once they are done, so ``while training_due(): train_cycle()`` is safe)."""
        if self.config.schedule == 'async':
            return self.updates + self.config.publish_every <= (self.config.updates_per_step
                                                                * self.steps)
        owed = (self._owed_offset
                + (self.steps // self.config.cycle_steps) * self.config.iterations_per_cycle)
        return self.steps % self.config.cycle_steps == 0 and self.updates < owed

    def reconfigure(self, config: LearnerConfig) -> dict[str, tuple]:
        """Take ``config`` between two cycles: it may differ from the current one only in
        ``RUNTIME_FIELDS``. The training owed so far stays owed, and from here on each
        ``cycle_steps`` steps owe ``iterations_per_cycle`` updates (no burst to catch up).

        :returns: dotted name -> (old, new) of what changed.
        :raises ValueError: if a setting outside ``RUNTIME_FIELDS`` differs.
        """
        changed = {name: pair for name, pair in differences(self.config, config)}
        fixed = sorted(set(changed) - RUNTIME_FIELDS)
        if fixed:
            raise ValueError(f'{fixed} cannot change while the learner runs (its networks, '
                             'graph and replay memory are built with them)')
        owed = (self._owed_offset
                + (self.steps // self.config.cycle_steps) * self.config.iterations_per_cycle)
        self._owed_offset = owed - (self.steps // config.cycle_steps) * config.iterations_per_cycle
        self.agent.set_learning_rates(config.ddpg.critic_lr, config.ddpg.effective_actor_lr)
        self.config = config
        return changed

    def train_cycle(self) -> dict:
        """The due train steps (``iterations_per_cycle``, or ``publish_every`` when ``async``);
        averaged diagnostics, census and the new actor version."""
        iterations = (self.config.publish_every if self.config.schedule == 'async'
                      else self.config.iterations_per_cycle)
        ddpg = self.config.ddpg
        totals = dict.fromkeys(DIAGNOSTIC_KEYS, 0.0)
        for _ in range(iterations):
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
        self.updates += iterations
        result = {k: v / iterations for k, v in totals.items()}
        if self.graph is not None:
            if self.actor_version % self.config.census_every == 0:
                census = self.graph.census()
                self._census = {k: census[k] for k in (*TRANSITION_KINDS, 'total')}
            result.update(self._census)
        self.actor_version += 1
        result.update(actor_version=self.actor_version, steps=self.steps, updates=self.updates,
                      replay_size=len(self.replay))
        return result

    def state_dict(self) -> dict:
        """Everything needed to continue exactly where this learner stands: the networks and
        their optimisers, replay memory, graph, sampling generator and counters (a snapshot)."""
        return {
            'config': dataclasses.asdict(self.config),
            'dims': (self.state_dim, self.action_dim),
            'agent': self.agent.state_dict(),
            'replay': self.replay.state_dict(),
            'graph': None if self.graph is None else self.graph.state_dict(),
            'rng': self.rng.bit_generator.state,
            'steps': self.steps,
            'updates': self.updates,
            'actor_version': self.actor_version,
            'census': self._census,
            'owed_offset': self._owed_offset,
        }

    @classmethod
    def from_state_dict(cls, state: dict) -> LearnerCore:
        """The learner ``state_dict`` was taken of, to continue its training to the bit."""
        core = cls(LearnerConfig.from_dict(state['config']), *state['dims'])
        core.agent.load_state_dict(state['agent'])
        core.replay.load_state_dict(state['replay'])
        if state['graph'] is not None:
            core.graph = QGraph.from_state_dict(state['graph'])
        core.rng.bit_generator.state = state['rng']
        core.steps, core.actor_version = state['steps'], state['actor_version']
        core.updates = state.get('updates', core.actor_version * core.config.iterations_per_cycle)
        core._census = state['census']
        core._owed_offset = state.get('owed_offset', 0)
        return core

    def save(self, path: pathlib.Path) -> None:
        """Checkpoint ``state_dict`` to ``path``."""
        torch.save(self.state_dict(), pathlib.Path(path))

    @classmethod
    def load(cls, path: pathlib.Path) -> LearnerCore:
        return cls.from_state_dict(torch.load(pathlib.Path(path), weights_only=False))
