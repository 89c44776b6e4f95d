"""One episode of the residual policy as a small state machine over RL steps.

The ROS executor drives it from service calls and at-rest events; the fast runner drives it in a
plain loop. Both get identical transitions, step caps and end reasons from this one class.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from qg_learning_node.executor.noise import ActionNoise
from qg_learning_node.executor.peg_task import PegTask
from qg_learning_node.executor.residual_task import Observation, ResidualTask

__all__ = ["Episode", "TransitionRecord", "Actor"]

#: The local policy: scaled state -> actor output in [-1, 1]^action_dim.
Actor = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class TransitionRecord:
    """One RL step (s, a, r, s'), as published on ``/transitions`` and stored by the learner."""
    episode_id: str
    step: int
    state: np.ndarray
    action: np.ndarray
    reward: float
    next_state: np.ndarray
    terminal: bool
    timeout: bool
    zero_action: bool

    @classmethod
    def from_message(cls, msg: Any) -> TransitionRecord:
        """From a ``qg_interfaces/Transition`` message, live or decoded from a bag (duck-typed)."""
        return cls(msg.episode_id, int(msg.step), np.asarray(msg.state, np.float64),
                   np.asarray(msg.action, np.float64), float(msg.reward),
                   np.asarray(msg.next_state, np.float64), bool(msg.terminal), bool(msg.timeout),
                   bool(msg.zero_action))


class Episode:
    """Step bookkeeping: state, action choice (with exploration in training), rewards, the end.

    :param mode: ``train`` (noise on) or ``test`` (deterministic).
    :param noise: exploration noise, used in training only.
    """

    def __init__(self, episode_id: str, mode: str, initial_pose: int, reward_kind: str,
                 task: ResidualTask | PegTask, noise: ActionNoise | None = None) -> None:
        self.episode_id = episode_id
        self.mode = mode
        self.initial_pose = initial_pose
        self.reward_kind = reward_kind
        self.task = task
        self.noise = noise
        self.max_steps = task.config.max_steps(mode)
        self.step = 0
        self.episode_return = 0.0
        self.success = False
        self.end_reason = ""
        self.state: np.ndarray | None = None
        self._obs: Observation | None = None       # where the step under way began
        #: A simulation's truth of the last observation, for evaluation only (``None`` on a
        #: real arm): whether the shaft was really inserted there.
        self.truly_inserted: bool | None = None

    @property
    def done(self) -> bool:
        return bool(self.end_reason)

    def begin(self, obs: Observation) -> np.ndarray:
        """The settled start: the first state."""
        self.state = self.task.state(obs)
        self._obs = obs
        self._evaluate(obs)
        if self.task.succeeded(obs):   # already inserted: nothing to learn from this start
            self.success, self.end_reason = True, "goal"
        return self.state

    def _evaluate(self, obs: Observation) -> None:
        if obs.truth is not None:
            self.truly_inserted = bool(obs.truth.success)

    def choose_action(self, actor: Actor | None) -> np.ndarray:
        """Actor output (+ noise in training); the zero residual when there is no actor.

        A non-finite actor output is replaced by the zero residual, never sent to the robot.
        """
        assert self.state is not None, "begin() first"
        zero = np.zeros(self.task.action_dim)
        action = zero if actor is None else np.asarray(actor(self.state), dtype=np.float64)
        if not np.all(np.isfinite(action)):
            action = zero
        if self.mode == "train" and self.noise is not None and actor is not None:
            action = self.noise.explore(action)
        return np.clip(action, -1.0, 1.0)

    def observe(self, action: np.ndarray, obs: Observation) -> TransitionRecord:
        """Close the step that executed ``action`` and ended at rest in ``obs``."""
        assert self.state is not None and not self.done, "episode not running"
        next_state = self.task.state(obs, self._obs)
        self._obs = obs
        reward = float(self.task.reward(obs, self.reward_kind))
        terminal = bool(self.task.succeeded(obs))
        self._evaluate(obs)
        self.step += 1
        self.episode_return += reward
        if terminal:
            self.success, self.end_reason = True, "goal"
        elif self.task.left_bore(obs):
            self.end_reason = "left_bore"
        elif self.step >= self.max_steps:
            self.end_reason = "step_cap"
        record = TransitionRecord(
            self.episode_id, self.step - 1, self.state.copy(), np.asarray(action, float).copy(),
            reward, next_state.copy(), terminal, self.done and not terminal,
            bool(np.all(np.asarray(action) == 0.0)))
        self.state = next_state
        return record

    def abort(self, reason: str = "aborted") -> None:
        if not self.done:
            self.end_reason = reason
