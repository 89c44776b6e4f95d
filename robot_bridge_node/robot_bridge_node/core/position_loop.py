"""The 1 kHz loop of a position-controlled robot (the Nextage): read, sense, IK, write.

The loop core's bookkeeping (``loop_core``: robot time, resets, the rest detector that ends an
RL step, the one ``StepResult``), with the position robot's tick: the setpoint's pose reference
goes through the task-space position controller (``position_control``) to joint targets, and the
wrench is what the wrist force-torque sensor measures, not an estimate. A position robot has no
feed-forward wrench: the setpoint's wrench is ignored, its reference is the command.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from qg_common.types import StartPose, WrenchSetpoint

from robot_bridge_node.core.hardware_interface import PositionInterface, Robot, SimulationInterface
from robot_bridge_node.core.loop_clock import LoopClock
from robot_bridge_node.core.loop_core import LoopConfig, LoopCore
from robot_bridge_node.core.position_control import (
    PositionControlConfig,
    TaskSpacePositionController,
    pose_matrix,
)
from robot_bridge_node.core.rest_detector import RestConfig, RestDetector
from robot_bridge_node.core.safety import SetpointRejected
from robot_bridge_node.core.start_motion import ResetConfig
from robot_bridge_node.core.wrench_source import MeasuredWrench, WrenchEstimator

__all__ = ["PositionLoop", "build_position_loop"]


class PositionLoop(LoopCore):
    """One episode's 1 kHz control of a position-controlled robot.

    :param controller: pose reference in, joint targets out (clamped to its workspace box and
        rate-limited: the position robot's safety).
    :param estimator: the wrench source, usually the wrist sensor's ``MeasuredWrench``; ``None`` runs without one.
    """

    #: [s] a reset by motion gives up after this long; [m] and counts the start reached within this.
    MOVE_TIMEOUT = 10.0
    MOVE_TOLERANCE = 1e-3

    hardware: PositionInterface
    controller: TaskSpacePositionController

    def __init__(self, hardware: PositionInterface, controller: TaskSpacePositionController,
                 rest_detector: RestDetector, estimator: WrenchEstimator | None = None,
                 config: LoopConfig | None = None,
                 simulation: SimulationInterface | None = None,
                 clock: LoopClock | None = None,
                 reset_config: ResetConfig | None = None) -> None:
        # No torque safety filter: the controller clamps and rate-limits its own targets.
        super().__init__(hardware, controller, rest_detector, estimator, config, simulation,
                         clock, reset_config)
        self.reference = np.eye(4)

    def begin(self) -> None:
        """Hold the joints where they are until the first setpoint or reset."""
        state = self._restart()
        self.controller.reset(state.q)
        self.controller.measure(state.q, state.dq)
        self.reference = self.controller.pose_command

    def _move_to(self, start: StartPose) -> None:
        """Move the tool's reference to ``start`` and tick until the tool is there (the
        task-space controller is speed-limited and clamped to its workspace).

        :raises RuntimeError: if the start is not reached within ``MOVE_TIMEOUT``.
        """
        self.reference = pose_matrix(np.asarray(start.position, float),
                                     np.asarray(start.rotation, float))
        began = self.time
        while self.time - began < self.MOVE_TIMEOUT:
            self.tick()
            tool = self.controller.tool
            if np.linalg.norm(tool.position - start.position) < self.MOVE_TOLERANCE \
                    and tool.linear_speed < 1e-3:
                return
        raise RuntimeError(f"the start was not reached within {self.MOVE_TIMEOUT} s")

    def command(self, setpoint: WrenchSetpoint) -> None:
        """Move toward the setpoint's pose reference (none: hold the current pose).

        :raises SetpointRejected: for a non-finite reference; the previous command stays.
        """
        if setpoint.reference is None:
            tool = self.controller.tool
            reference = pose_matrix(tool.position, tool.rotation)
        else:
            reference = pose_matrix(setpoint.reference.position, setpoint.reference.rotation)
            if not np.all(np.isfinite(reference)):
                raise SetpointRejected(f"pose reference is not finite: {reference.tolist()}")
        self.reference = reference
        self.rest.reset()

    def feed_watchdog(self) -> None:
        """Nothing to feed: a position robot holds its last target by itself."""

    def tick(self) -> bool:
        """One control period. True when the current step has come to rest or timed out."""
        state = self.hardware.read()
        dt = self._sense(state)
        self.hardware.write(self.controller.step(state.q, self.reference))
        self._count(dt)
        state = self.hardware.read()
        tool = self.controller.measure(state.q, state.dq)
        return self.rest.update(tool.linear_speed, tool.angular_speed, dt)


def build_position_loop(robot: Robot, bridge_params: dict[str, Any] | None = None,
                        wrench: WrenchEstimator | None = None,
                        clock: LoopClock | None = None) -> PositionLoop:
    """The loop of a position-controlled robot from a plugin (``interface="position"``).

    :param bridge_params: the bridge node's parameters (sections ``position_control``, ``rest``,
        ``loop``); missing sections keep the defaults.
    :param wrench: the wrench source; ``None``: the robot's wrist sensor (none without one).
    :param clock: the loop's time; ``None``: one ``loop.dt`` per tick.
    """
    params = bridge_params or {}
    description = robot.description
    controller = TaskSpacePositionController(
        description.urdf, description.tool_frame,
        PositionControlConfig.from_dict(params.get("position_control", {})))
    if wrench is None and robot.wrist_sensor is not None:
        wrench = MeasuredWrench(robot.wrist_sensor.read_wrench)
    return PositionLoop(robot.hardware, controller,
                        RestDetector(RestConfig.from_dict(params.get("rest", {}))), wrench,
                        LoopConfig.from_dict(params.get("loop", {})), robot.simulation, clock,
                        ResetConfig.from_dict(params.get("reset", {})))
