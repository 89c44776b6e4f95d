"""The robot side of the stack in one process: the robot plugin, the bridge's loop and the wrench
estimator, with the shaft task's MDP.

Why: the runs, the Gymnasium environment and the benchmarks execute a residual action exactly as
the executor asks the robot process to over DDS, without DDS.
"""
from __future__ import annotations

import numpy as np
from qg_common.types import StepResult, WrenchSetpoint
from qg_learning_node.executor.observation import observation_from_step
from qg_learning_node.executor.residual_task import Observation, ResidualTask
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig
from robot_bridge_node.core.wrench_source import MeasuredWrench

from qg_experiments.core.stack_settings import StackSettings

__all__ = ["ESTIMATORS", "InsertionRobot"]

#: The wrench the loop is given: ``ekf`` (what the ROS stack runs) or ``ground_truth`` (the
#: simulation's contact wrench: a perfect sensor).
ESTIMATORS = ("ekf", "ground_truth")


class InsertionRobot:
    """The robot side of the stack in-process: the robot plugin, the bridge loop and the wrench
    estimator, on the shaft task.

    It answers what the executor asks over DDS: the move to a start, and one wrench executed
    until rest, each as an :class:`Observation` (the tool pose of the measured joints).
    :param estimator: ``ekf`` (what the ROS stack runs) or ``ground_truth`` (a perfect sensor).
    """

    def __init__(self, settings: StackSettings, estimator: str = "ekf") -> None:
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
        ekf = WrenchEKFConfig.from_dict(settings.ekf)
        self.settings = settings
        self.loop: RobotLoop = build_loop(
            load_robot(settings.robot_name, settings.robot), settings.bridge,
            (lambda robot, model: WrenchEKF(ekf, model)) if estimator == "ekf"
            else (lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench)))
        self.loop.begin()
        self.residual = ResidualTask(settings.task, settings.geometry)
        self.sim_time = 0.0
        self.steps = 0
        self.step_timeouts = 0

    def _observe(self, result: StepResult) -> Observation:
        tool = self.loop.controller.tool
        return observation_from_step(result, tool.position, tool.rotation)

    def reset(self, initial_pose: int) -> Observation:
        """The task's start ``initial_pose`` reached and settled, observed like the end of a
        step."""
        self.loop.reset(self.residual.start_pose(initial_pose))
        return self._observe(self.loop.result(self.loop.time))

    def step(self, action: np.ndarray) -> Observation:
        """Execute the residual ``action`` (actor units) until the tool is at rest."""
        result = self.loop.execute(WrenchSetpoint(self.residual.wrench(action)))
        self.sim_time += result.duration
        self.steps += 1
        self.step_timeouts += int(result.timed_out)
        return self._observe(result)

    def close(self) -> None:
        """Release the simulation (the robot plugin's physics world) where it offers that;
        a process that builds many tasks, like a seeded Gymnasium environment, needs it."""
        close = getattr(self.loop.simulation, "close", None)
        if close is not None:
            close()
