"""Kinds of hardware interface, registered by name: how the bridge drives a robot of each kind.

ros2_control tells command interfaces apart by type (``effort``, ``position``) and loads the
controller for each as a plugin; here a robot plugin names its kind (``RobotPlugin.interface``),
and the bridge, the estimator and the separate sim look the kind up in the entry-point group
``robot_bridge_node.interfaces`` instead of branching on the name. A kind says which parameters
the bridge and the wrench estimator declare, builds the 1 kHz loop, names the ``JointState`` field
its commands travel in between processes, and what the separate sim applies when no fresh command
arrives. This package registers ``torque`` (``torque_kind.TORQUE``) and ``position``
(``position_kind.POSITION``); another kind is one more entry point, in any package.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from qg_common.params import ParameterSection
from qg_common.plugins import load_registered, registered_names
from qg_common.types import JointState

from robot_bridge_node.core.hardware_interface import (
    Robot,
    RobotDescription,
)
from robot_bridge_node.core.loop_clock import LoopClock
from robot_bridge_node.core.loop_core import LoopConfig, LoopCore
from robot_bridge_node.core.rest_detector import RestConfig
from robot_bridge_node.core.start_motion import ResetConfig
from robot_bridge_node.core.wrench_source import WrenchEstimator

__all__ = ["InterfaceKind", "CommandHold", "LoopBuilder", "STEP_SECTIONS", "INTERFACE_GROUP",
           "interface_kind", "interface_kind_names"]

#: The entry-point group interface kinds register under (``name = module:InterfaceKind``).
INTERFACE_GROUP = "robot_bridge_node.interfaces"

#: Every kind's step parameters: the rest detector that ends an RL step, the loop timing and
#: how a start is reached.
STEP_SECTIONS = (
    ParameterSection("rest", RestConfig, ranges={
        "linear_threshold": (0.0, 1.0), "angular_threshold": (0.0, 10.0),
        "hold_time": (0.0, 10.0), "min_time": (0.0, 10.0), "max_time": (0.0, 10.0)}),
    ParameterSection("loop", LoopConfig, ranges={"dt": (0.0, 0.01), "settle_time": (0.0, 10.0)}),
    ParameterSection("reset", ResetConfig, ranges={
        "linear_speed": (0.0, 0.5), "joint_speed": (0.0, 2.0), "min_duration": (0.0, 60.0),
        "arrive_tolerance": (0.0, 0.01), "arrive_angle": (0.0, 0.2), "arrive_speed": (0.0, 1.0),
        "arrive_timeout": (0.0, 60.0), "arrive_gain": (0.0, 100.0)}))


class CommandHold(Protocol):
    """What a robot of a kind is given when no fresh command arrives (the separate sim's
    stand-in for the robot's own firmware)."""

    def reset(self, state: JointState) -> None:
        """The robot was just put at ``state`` (a reset): forget earlier commands."""
        ...

    def command(self, state: JointState, last: np.ndarray | None) -> np.ndarray:
        """The command for this period at ``state``; ``last`` is the last command received since
        the reset (``None``: none yet)."""
        ...


class LoopBuilder(Protocol):
    """Builds a kind's 1 kHz loop around a robot."""

    def __call__(self, robot: Robot, bridge_params: dict[str, Any],
                 estimator_params: dict[str, Any], *, wrench: WrenchEstimator | None = None,
                 clock: LoopClock | None = None) -> LoopCore:
        """:param bridge_params: the bridge's parameters (the kind's ``controller_sections``).
        :param estimator_params: the wrench estimator's (the kind's ``estimator_sections``).
        :param wrench: the wrench source instead of the kind's own (a separate process's
            ``wrench_estimate``); ``None``: the kind's (the EKF, or the robot's wrist sensor).
        :param clock: the loop's clock; ``None``: one ``loop.dt`` per tick.
        """
        ...


@dataclass(frozen=True)
class InterfaceKind:
    """How the bridge drives the robots of one hardware interface kind.

    :param name: the kind's registered name (``RobotPlugin.interface``).
    :param command_field: the ``sensor_msgs/JointState`` field that carries a command on
        ``joint_commands`` between processes (``effort``, ``position``).
    :param controller_sections: the bridge's parameters for robots of this kind.
    :param estimator_sections: the ``wrench_estimator`` node's parameters (none if the robot
        measures its wrench).
    :param build_loop: the composed process's loop, and the separate bridge's with ``wrench``
        and ``clock`` given.
    :param hold: ``(description, damping [Nms/rad]) -> CommandHold``: what the separate sim
        applies without a fresh command.
    :param separate_estimator: ``(description, estimator_params) -> WrenchEstimator`` run by the
        separate ``wrench_estimator`` process on ``joint_states``; ``None``: the robot measures
        its wrench, and the separate sim publishes its sensor's reading instead.
    """
    name: str
    command_field: str
    controller_sections: tuple[ParameterSection, ...]
    estimator_sections: tuple[ParameterSection, ...]
    build_loop: LoopBuilder
    hold: Callable[[RobotDescription, float], CommandHold]
    separate_estimator: Callable[[RobotDescription, dict[str, Any]], WrenchEstimator] | None

    def __post_init__(self) -> None:
        if self.command_field not in ("position", "velocity", "effort"):
            raise ValueError(f"command_field must be a JointState field (position, velocity, "
                             f"effort), got {self.command_field!r}")


def interface_kind_names() -> list[str]:
    """Names of the registered interface kinds."""
    return registered_names(INTERFACE_GROUP)


def interface_kind(name: str) -> InterfaceKind:
    """The interface kind registered as ``name``.

    :raises ValueError: if no installed package registers that name (lists those that do).
    """
    kind = load_registered(INTERFACE_GROUP, name, InterfaceKind, "hardware interface kind")
    if kind.name != name:
        raise ValueError(f"the interface kind registered as {name!r} calls itself {kind.name!r}")
    return kind
