"""The residual shaft-insertion MDP as a Gymnasium environment, for any robot behind it.

What a robot has to do is two things, as the executor node asks of the robot process: reset to a
start pose and return the settled :class:`Observation`, and execute one residual action until the
tool is at rest. :class:`ResidualEnv` adds everything else from the executor's own cores, so the
in-process environment and the ROS-backed one cannot drift apart from the runner or the node:

- states, rewards, the goal and the bore check from ``ResidualTask``;
- step caps and end reasons from ``Episode`` (the executor's state machine). The goal is
  ``terminated``; the step cap and leaving the bore are ``truncated`` (the stack records them as
  non-terminal ``timeout`` transitions too, so bootstrapping goes on through them);
- the start poses rotate 0..7 over episodes (as the runner's and the demo's), unless
  ``reset(options={"pose": k})`` names one; ``options={"max_steps": n}`` sets one episode's cap
  (the test protocol's 200 on an environment made with the training cap).

``info`` carries ``is_success`` (SB3's key) and the task's errors as the task measures them (the
tool pose of the measured joints against the cell), and ``truly_inserted``, a simulation's truth
for evaluation only (never part of the observation).

``render_mode="rgb_array"`` makes ``render()`` return the picture of the robot as it is now
(``rendering.RobotView``: the renderer of ``qgl render``) with the step, the residual torques
and the wrench estimate written on it; ``"human"`` shows it in a window (needs a display).
A subclass that can be drawn says how (``rendering.RenderedRobot``: ``_view``,
``_joint_positions``).
"""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from qg_common.shaft_task import ShaftTaskGeometry
from qg_common.types import N_START_POSES
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.residual_task import (
    ACTION_DIM,
    Observation,
    ResidualTask,
    TaskConfig,
)

from qg_experiments.gym_envs.rendering import (
    RENDER_FPS,
    RENDER_MODES,
    RenderedRobot,
    check_render_mode,
)

__all__ = ["ResidualEnv"]


class ResidualEnv(RenderedRobot, gymnasium.Env):
    """Base of the residual-policy environments; subclasses say how the robot resets and steps.

    :param task: the executor's task settings (observation, reward scales, ...).
    :param geometry: the cell (its fixture, the target, the starts).
    :param reward: ``dense`` | ``sparse``; ``None``: ``task.reward``.
    :param max_steps: step cap of an episode (``truncated`` when it is reached).
    """

    metadata: dict[str, Any] = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}

    def __init__(self, task: TaskConfig, geometry: ShaftTaskGeometry, reward: str | None,
                 max_steps: int, render_mode: str | None = None) -> None:
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        check_render_mode(render_mode)
        self.render_mode = render_mode
        self._last_action = np.zeros(ACTION_DIM)
        self._last_observation: Observation | None = None
        self.residual = ResidualTask(task, geometry)
        self.reward_kind = reward or task.reward
        if self.reward_kind not in ("dense", "sparse"):
            raise ValueError(f"reward must be dense or sparse, got {self.reward_kind!r}")
        self.max_steps = int(max_steps)
        self.observation_space = spaces.Box(-1.0, 1.0, (self.residual.state_dim,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        self.reward_range = ResidualTask.reward_range(self.reward_kind)
        self.episodes = 0
        self._episode: Episode | None = None

    # --- what a robot provides ---------------------------------------------------------------
    def _reseed(self, seed: int) -> None:
        """``reset(seed=seed)``: start the robot's random streams over (default: nothing)."""

    def _reset_robot(self, pose: int) -> Observation:
        """Reset to start ``pose``; the settled observation."""
        raise NotImplementedError

    def _execute(self, action: np.ndarray) -> Observation:
        """Execute the residual ``action`` (actor units) until the tool is at rest."""
        raise NotImplementedError


    # --- gymnasium -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"pose", "max_steps"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}: pose, max_steps")
        if seed is not None:
            self._reseed(int(seed))
            self.episodes = 0
        pose = int(options.get("pose", self.episodes % N_START_POSES))
        if not 0 <= pose < N_START_POSES:
            raise ValueError(f"pose must be in 0..{N_START_POSES - 1}, got {pose}")
        cap = int(options.get("max_steps", self.max_steps))
        if cap < 1:
            raise ValueError(f"max_steps must be >= 1, got {cap}")
        episode = Episode(f"gym{self.episodes:05d}", "train", pose, self.reward_kind,
                          self.residual)
        episode.max_steps = cap
        self.episodes += 1
        observation = self._reset_robot(pose)
        self._episode = episode
        self._last_action, self._last_observation = np.zeros(ACTION_DIM), observation
        return self._state(episode.begin(observation)), self._info(observation)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        episode = self._episode
        if episode is None or episode.done:
            raise RuntimeError("the episode has ended: call reset()")
        a = np.asarray(action, dtype=np.float64).reshape(ACTION_DIM)
        # as the executor does: a non-finite action becomes the zero residual, never a command
        a = np.clip(a, -1.0, 1.0) if np.all(np.isfinite(a)) else np.zeros(ACTION_DIM)
        observation = self._execute(a)
        self._last_action, self._last_observation = a, observation
        record = episode.observe(a, observation)
        return (self._state(record.next_state), float(record.reward), bool(record.terminal),
                bool(record.timeout), self._info(observation))

    def _render_lines(self) -> list[str]:
        """The step, the residual torques of the last action and the wrench estimate."""
        episode = self._episode
        lines = [f"{self.spec.id if self.spec else type(self).__name__}   "
                 f"episode {self.episodes}, start {episode.initial_pose if episode else '-'}, "
                 f"step {episode.step if episode else 0}"]
        wrench = self.residual.wrench(self._last_action)
        lines.append(f"residual  Tx {wrench[3]:+5.2f}  Ty {wrench[4]:+5.2f} Nm   "
                     f"push Fz {wrench[2]:+6.1f} N")
        observation = self._last_observation
        if observation is not None:
            f = observation.wrench
            lines.append(f"estimate  Fz {f[2]:+6.1f} N   Tx {f[3]:+5.2f}  Ty {f[4]:+5.2f} Nm   "
                         f"to go {self.residual.measure(observation).position_error * 1e3:5.1f} mm")
        return lines

    def close(self) -> None:
        """Close the renderer's world (subclasses release their robot too)."""
        self._close_view()

    @property
    def episode(self) -> Episode | None:
        """The running (or last) episode: step count, return, ``end_reason``."""
        return self._episode

    @staticmethod
    def _state(state: np.ndarray) -> np.ndarray:
        return np.asarray(state, dtype=np.float32)

    def _info(self, observation: Observation) -> dict[str, Any]:
        """The goal and the errors as the task measures them (the tool pose of the measured
        joints); ``truly_inserted``: a simulation's truth, for evaluation (None without one)."""
        episode, m = self._episode, self.residual.measure(observation)
        truth = observation.truth
        return {"is_success": bool(m.inserted),
                "position_error": float(m.position_error),
                "orientation_error": float(m.orientation_error_norm),
                "lateral_offset": float(m.lateral_offset),
                "truly_inserted": None if truth is None else bool(truth.success),
                "pose": -1 if episode is None else episode.initial_pose,
                "end_reason": "" if episode is None else episode.end_reason}
