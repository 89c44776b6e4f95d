"""The ``position`` interface kind: joint position targets in, task-space IK, a wrist sensor.

Registered as ``position`` in ``robot_bridge_node.interfaces`` (``setup.py``); the Nextage's
plugin names it. The controller's gains come with the robot's own config files
(``position_control.*``), the wrench is the wrist sensor's measurement, so the estimator node has
no parameters and the separate sim publishes the sensor's reading itself.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from qg_common.params import POSITIVE, ParameterSection
from qg_common.types import JointState

from robot_bridge_node.core.hardware_interface import Robot
from robot_bridge_node.core.interface_kinds import STEP_SECTIONS, InterfaceKind
from robot_bridge_node.core.loop_clock import LoopClock
from robot_bridge_node.core.position_control import PositionControlConfig
from robot_bridge_node.core.position_loop import PositionLoop, build_position_loop
from robot_bridge_node.core.wrench_source import WrenchEstimator

__all__ = ["POSITION", "PositionHold"]


def _build(robot: Robot, bridge_params: dict[str, Any], estimator_params: dict[str, Any], *,
           wrench: WrenchEstimator | None = None, clock: LoopClock | None = None) -> PositionLoop:
    del estimator_params          # the wrench is measured: no estimator parameters
    return build_position_loop(robot, bridge_params, wrench, clock)


class PositionHold:
    """A position-controlled arm holds its last target; before any, where it was put."""

    def __init__(self) -> None:
        self._target: np.ndarray | None = None

    def reset(self, state: JointState) -> None:
        self._target = state.q.copy()

    def command(self, state: JointState, last: np.ndarray | None) -> np.ndarray:
        if last is not None:
            return last
        if self._target is None:
            self._target = state.q.copy()
        return self._target


#: ``interface="position"``: the Nextage.
POSITION = InterfaceKind(
    name="position", command_field="position",
    controller_sections=(
        ParameterSection("position_control", PositionControlConfig, ranges={
            "damping": (0.0, 1.0), "orientation_weight": POSITIVE, "max_iterations": (1, 10000),
            "max_iteration_step": (0.0, 3.2), "position_tolerance": (0.0, 0.01),
            "orientation_tolerance": (0.0, 0.1), "linear_speed_limit": (0.0, 1.0),
            "angular_speed_limit": (0.0, 10.0), "joint_speed_limit": (0.0, 10.0),
            "dt": (0.0, 0.01)}),
        *STEP_SECTIONS),
    estimator_sections=(),
    build_loop=_build,
    hold=lambda description, damping: PositionHold(),
    separate_estimator=None)
