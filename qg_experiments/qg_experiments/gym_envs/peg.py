"""The clearance-fit peg-in-hole (thesis ch. 3.1.1, 8.3.2) as Gymnasium environments.

``QGPeg-v0``: the free peg of experiment 5 (``sim_robot_node``'s ``PegEnv``: a force-limited
drive moves the upright peg, no arm), exactly the environment of ``experiments/peg.py``'s runs,
so a standard agent (Stable-Baselines3's) can be run on the thesis's own task beside them.

``QGNextagePeg-v0``: the Nextage peg-in-hole in process, on the runner's ``NextagePeg``.

The simulated Nextage under the bridge's task-space position loop and the executor's
``PegTask`` (tip position state, position-offset actions, ``exp(-d/0.03) - 1`` or sparse reward),
read from the stack's ``config/`` files. The start is the ``k``-th seeded free tip position of the
workspace: ``reset(options={"start": k})`` names it; otherwise it is drawn from the environment's
generator, so ``reset(seed=s)`` starts the same episode every time.

``render_mode="rgb_array"`` | ``"human"``: the arm, the peg and the block as ``qgl render``
draws them (``rendering.RobotView``).
"""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from qg_common.params import config_file, load_ros_params
from qg_learning_node.executor.peg_task import PEG_ACTION_DIM, PEG_STATE_DIM

from qg_experiments.environments import make_environment
from qg_experiments.gym_envs.rendering import (
    RENDER_FPS,
    RENDER_MODES,
    RenderedRobot,
    RobotView,
    check_render_mode,
)
from qg_experiments.nextage_peg import NextagePeg

__all__ = ["FreePegEnv", "NextagePegEnv"]

#: Start indices are drawn below this (any int the simulator's generator takes).
_START_RANGE = 2**31 - 1


def _start(options: dict[str, Any] | None, rng: np.random.Generator) -> int:
    """The start index ``reset`` asked for (``options["start"]``), else one from ``rng``.

    :raises ValueError: on another option.
    """
    options = dict(options or {})
    unknown = set(options) - {"start"}
    if unknown:
        raise ValueError(f"unknown reset options {sorted(unknown)}: start")
    return int(options["start"]) if "start" in options else int(rng.integers(_START_RANGE))


class FreePegEnv(gymnasium.Env):
    """The free peg (see the module docstring): the state the tip's position in the 20 cm
    workspace scaled to [-1, 1]^3, an action a 3-D offset of at most 1 cm per axis, the reward
    ``exp(-d/0.03) - 1`` of the tip's distance to the hole bottom; inserted ends the episode.
    ``reset(options={"start": k})`` starts at the ``k``-th seeded free position (the one the
    experiment's episode ``k`` would draw); otherwise the environment's generator picks it.

    :param max_steps: step cap of an episode (``truncated``; the thesis: 200).
    :param config_dir: the stack's ``config/`` (``peg_env.yaml``); ``None``: the installed files.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, max_steps: int = 200, config_dir: str | None = None) -> None:
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        self.peg = make_environment("peg", load_ros_params(config_file("peg_env.yaml",
                                                                       config_dir)),
                                    episode_steps=max_steps)
        self.observation_space = spaces.Box(-1.0, 1.0, (self.peg.state_dim,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (self.peg.action_dim,), np.float32)
        self._running = False

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        start = _start(options, self.np_random)
        state = self.peg.reset(seed=start)
        self._running = True
        return state.astype(np.float32), {"start": start, **self._info()}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """:raises ValueError: on a non-finite action (the peg does not move)."""
        if not self._running:
            raise RuntimeError("the episode has ended: call reset()")
        state, reward, terminal = self.peg.step(np.asarray(action, dtype=np.float64))
        truncated = not terminal and self.peg.truncated
        self._running = not (terminal or truncated)
        return state.astype(np.float32), float(reward), bool(terminal), truncated, self._info()

    def _info(self) -> dict[str, Any]:
        distance = float(np.linalg.norm(self.peg.tip() - self.peg.geometry.goal))
        return {"is_success": distance < self.peg.geometry.goal_tolerance,
                "position_error": distance}

    def close(self) -> None:
        self.peg.close()


class NextagePegEnv(RenderedRobot, gymnasium.Env):
    """The Nextage peg (see the module docstring).

    :param reward: ``dense`` | ``sparse``.
    :param max_steps: step cap of an episode (``truncated``; the thesis's peg: 200).
    :param config_dir: the stack's ``config/``; ``None``: the installed files.
    """

    metadata: dict[str, Any] = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}

    def __init__(self, reward: str = "dense", max_steps: int = 200,
                 config_dir: str | None = None, render_mode: str | None = None) -> None:
        check_render_mode(render_mode)
        self.render_mode = render_mode
        self._last_action = np.zeros(PEG_ACTION_DIM)
        if reward not in ("dense", "sparse"):
            raise ValueError(f"reward must be dense or sparse, got {reward!r}")
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        self.peg = NextagePeg(config_dir, episode_steps=max_steps, reward=reward)
        self.observation_space = spaces.Box(-1.0, 1.0, (PEG_STATE_DIM,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (PEG_ACTION_DIM,), np.float32)
        self.reward_range = (-1.0, 0.0)
        self._running = False

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        start = _start(options, self.np_random)
        state = self.peg.reset(start)
        self._running = True
        return state.astype(np.float32), self._info(start)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self._running:
            raise RuntimeError("the episode has ended: call reset()")
        a = np.asarray(action, dtype=np.float64).reshape(PEG_ACTION_DIM)
        a = np.clip(a, -1.0, 1.0) if np.all(np.isfinite(a)) else np.zeros(PEG_ACTION_DIM)
        self._last_action = a
        state, reward, terminal = self.peg.step(a)
        truncated = not terminal and self.peg.truncated
        self._running = not (terminal or truncated)
        return state.astype(np.float32), float(reward), bool(terminal), truncated, self._info()

    def _info(self, start: int | None = None) -> dict[str, Any]:
        observation = self.peg.observation
        assert observation is not None
        task = self.peg.task
        info: dict[str, Any] = {"is_success": task.succeeded(observation),
                                "position_error": task.distance(observation),
                                "tip": self.peg.tip()}
        if start is not None:
            info["start"] = start
        return info

    def _view(self) -> RobotView:
        return RobotView("sim_nextage", self.peg.robot_params, self.render_mode)

    def _joint_positions(self) -> np.ndarray:
        return self.peg.loop.hardware.read().q

    def _render_lines(self) -> list[str]:
        observation = self.peg.observation
        scale = 100 * self.peg.task.config.action_scale       # [cm] of a unit action
        lines = [f"QGNextagePeg-v0   step {self.peg.steps}",
                 "offset  " + "  ".join(f"{v * scale:+5.2f}" for v in self._last_action)
                 + " cm"]
        if observation is not None:
            distance = self.peg.task.distance(observation)
            lines.append(f"tip to the hole bottom {distance * 1e3:5.1f} mm")
        return lines

    def close(self) -> None:
        self._close_view()
        self.peg.close()
