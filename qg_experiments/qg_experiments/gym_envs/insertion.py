"""``QGInsertion-v0``: the Panda shaft insertion in process, on the core's ``InsertionRobot``.

The robot side is the core's (``qg_experiments.core``: simulator, the bridge's 1 kHz loop, the
EKF, read from the same ``config/`` files); the MDP is the executor's (:class:`~.residual_env.ResidualEnv`). A run of
``RunSpec(seed=s)`` and this environment after ``reset(seed=s)`` meet the same robot and, given
the same actions, take the same steps.

Seeds: ``reset(seed=s)`` builds the robot afresh, with the arm of seed ``s`` (the realistic arm's
biases, housing error and noise streams; ``arm_seed`` fixes one instead) and the start poses from
0 again, so a seeded episode is the same every time. A reset without a seed goes on with the
robot as it is.

The core (and with it the robot plugin and its physics engine) is imported when an environment
is made, not with this module: registering or listing the environments loads none of it. Neither
loads the learner, torch or ROS.
"""
from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
from qg_learning_node.executor.residual_task import Observation

from qg_experiments.gym_envs.rendering import RobotView
from qg_experiments.gym_envs.residual_env import ResidualEnv

if TYPE_CHECKING:
    from qg_experiments.core.insertion_robot import InsertionRobot

__all__ = ["InsertionEnv", "TRAIN_MAX_STEPS"]

#: The grid's training cap (``config/experiments.yaml``, profile ``thesis``).
TRAIN_MAX_STEPS = 50


class InsertionEnv(ResidualEnv):
    """The residual force policy on the simulated Panda (see the module docstring).

    :param observation: the state (``residual_task.OBSERVATIONS``); ``None``: ``executor.yaml``'s.
    :param reward: ``dense`` | ``sparse``; ``None``: ``executor.yaml``'s.
    :param max_steps: step cap of an episode (default: the grid's training cap, 50).
    :param arm: ``realistic`` (the imperfect arm, default) | ``ideal`` (``panda_ideal.yaml``).
    :param arm_seed: which realistic arm; ``None``: the seed of the last seeded reset (0 before).
    :param estimator: ``ekf`` (as the stack) | ``ground_truth`` (a perfect wrench sensor).
    :param housing_yaw: [rad] the housing's rotation about the vertical (start tilts turn with it).
    :param config_dir: the stack's ``config/``; ``None``: the installed files.
    :param robot: the robot plugin (``sim_panda``, ``sim_panda_mujoco``, ...); ``None``: the
        core's default (``core.DEFAULT_ROBOT``).
    :param render_mode: ``rgb_array`` | ``human`` | None (``residual_env``).
    """

    def __init__(self, observation: str | None = None, reward: str | None = None,
                 max_steps: int = TRAIN_MAX_STEPS, arm: str = "realistic",
                 arm_seed: int | None = None, estimator: str = "ekf", housing_yaw: float = 0.0,
                 config_dir: str | None = None, robot: str | None = None,
                 render_mode: str | None = None) -> None:
        from qg_experiments.core import ARMS, DEFAULT_ROBOT, ESTIMATORS, StackSettings
        if arm not in ARMS:
            raise ValueError(f"arm must be one of {ARMS}, got {arm!r}")
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
        settings = StackSettings.load(config_dir, arm, robot or DEFAULT_ROBOT)
        if housing_yaw:
            settings = settings.with_cell(housing_yaw=float(housing_yaw))
        task = dataclasses.replace(settings.task,
                                   observation=observation or settings.task.observation)
        super().__init__(task, settings.geometry, reward, max_steps, render_mode)
        self.settings = dataclasses.replace(settings, task=task)
        self.arm, self.arm_seed, self.estimator = arm, arm_seed, estimator
        self.robot: InsertionRobot | None = None

    def _reseed(self, seed: int) -> None:
        self._build(seed if self.arm_seed is None else self.arm_seed)

    def _build(self, arm_seed: int) -> None:
        from qg_experiments.core.insertion_robot import InsertionRobot
        self.close()
        self.robot = InsertionRobot(self.settings.with_arm_seed(arm_seed), self.estimator)

    def _reset_robot(self, pose: int) -> Observation:
        if self.robot is None:
            self._build(0 if self.arm_seed is None else self.arm_seed)
        assert self.robot is not None
        return self.robot.reset(pose)

    def _execute(self, action: np.ndarray) -> Observation:
        assert self.robot is not None
        return self.robot.step(action)

    def _view(self) -> RobotView:
        return RobotView(self.settings.robot_name, self.settings.robot, self.render_mode)

    def _joint_positions(self) -> np.ndarray:
        if self.robot is None:
            raise RuntimeError("render() before reset(): there is no robot yet")
        return self.robot.loop.hardware.read().q

    def close(self) -> None:
        """Release the simulation (its pybullet client) and the renderer's."""
        super().close()
        if self.robot is not None:
            self.robot.close()
            self.robot = None
