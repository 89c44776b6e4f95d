"""The one seam between the bridge and a robot, and how robots are found by name.

Modelled on ros2_control: the loop, the controllers and the estimator only ever call ``read()``
(the joint state) and ``write()`` (the command for one control period) on a hardware interface,
so they never know whether a real arm, a simulator or a topic answers. Powers only a simulation
has (teleporting to a start pose, ground truth) sit beside the seam in ``SimulationInterface``,
as Gazebo's ``initSim`` does; a real arm has ``simulation=None``.

Robots are plugins: a package registers a ``RobotPlugin`` under the entry-point group
``robot_bridge_node.robots`` (Python's entry points play pluginlib's role), and the robot process
loads the one named by its ``robot`` parameter. This package never imports an implementation:
``sim_robot_node`` registers ``sim_panda`` and ``sim_nextage``; a real Franka would be one more
entry point in its own package.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any, Literal, Protocol

import numpy as np
from qg_common.params import ParameterSection
from qg_common.types import GroundTruth, JointState

__all__ = ["TorqueInterface", "PositionInterface", "StampedStates", "ForceTorqueSensor",
           "SimulationInterface", "ToolDescription",
           "RobotDescription", "Robot", "RobotPlugin", "RobotChoice", "ROBOT_SECTION",
           "ROBOT_PLUGIN_GROUP", "robot_names", "robot_plugin", "load_robot"]

#: The entry-point group robots register under (``name = module:RobotPlugin instance``).
ROBOT_PLUGIN_GROUP = "robot_bridge_node.robots"


class TorqueInterface(Protocol):
    """A torque-controlled arm (the Panda): joint torques in, joint state out."""
    joint_names: tuple[str, ...]

    def read(self) -> JointState:
        """The joint state now; ``tau`` is the measured torque."""
        ...

    def write(self, tau: np.ndarray) -> None:
        """Apply joint torques [Nm] for one control period (a simulation steps here)."""
        ...


class PositionInterface(Protocol):
    """A position-controlled arm (the Nextage): joint position targets in, joint state out."""
    joint_names: tuple[str, ...]

    def read(self) -> JointState:
        """The joint state now; ``tau`` is the motor torque."""
        ...

    def write(self, q: np.ndarray) -> None:
        """Hold joint position targets [rad] for one control period."""
        ...


class StampedStates(Protocol):
    """Hardware whose states carry the time they were measured: a robot behind a network (the
    separate sim process over topics), where the loop can miss states or get them late, so a
    tick may cover more or less than one control period."""

    def state_time(self) -> float:
        """[s] when the state the last ``read`` returned was measured, on the robot's clock."""
        ...


class ForceTorqueSensor(Protocol):
    """A wrist force-torque sensor (the Nextage's): the wrench it measures, tared."""

    def read_wrench(self) -> np.ndarray:
        """(6,) ``(Fx, Fy, Fz, Tx, Ty, Tz)`` [N, Nm] in the sensor frame (z along the tool)."""
        ...


class SimulationInterface(Protocol):
    """What only a simulated robot can do: start an episode anywhere, and tell the truth."""

    def reset(self, initial_pose: int, housing_yaw: float = 0.0) -> None:
        """Teleport to start ``initial_pose`` at rest (the housing turned by ``housing_yaw``)."""
        ...

    def ground_truth(self) -> GroundTruth:
        """Evaluation-only truth: contact wrench, insertion state, pose errors."""
        ...

    def contact_wrench(self) -> np.ndarray:
        """(6,) the true contact wrench on the tool, tool frame: a perfect wrist sensor."""
        ...


@dataclass(frozen=True)
class ToolDescription:
    """What the bridge's robot model needs to know about the tool the arm holds.

    :param offset: (3,) tool frame origin relative to the flange frame, in that frame [m].
    :param payload_mass: [kg] the held part.
    :param payload_com: (3,) its centre of mass in the flange frame [m].
    """
    offset: np.ndarray
    payload_mass: float
    payload_com: np.ndarray


@dataclass(frozen=True)
class RobotDescription:
    """What the bridge knows about a robot without talking to it.

    :param joint_names: the arm's joints, in the order of every joint vector.
    :param tool: the held tool, for the controller's and the estimator's model.
    :param dt: [s] the control period the hardware runs at.
    :param urdf: the arm's URDF, for a position robot's task-space controller ("" if unused).
    :param tool_frame: the controlled frame of that URDF.
    """
    joint_names: tuple[str, ...]
    tool: ToolDescription
    dt: float
    urdf: str = ""
    tool_frame: str = ""


@dataclass
class Robot:
    """A robot as the bridge gets it from a plugin.

    :param hardware: the interface the loop reads and writes every period.
    :param simulation: the simulation's extra powers; ``None`` on real hardware.
    :param wrist_sensor: a force-torque sensor at the wrist, if the robot has one; the loop's
        wrench then comes from it instead of an estimator.
    """
    hardware: TorqueInterface | PositionInterface
    simulation: SimulationInterface | None
    description: RobotDescription
    wrist_sensor: ForceTorqueSensor | None = None


@dataclass(frozen=True)
class RobotPlugin:
    """How a robot package makes its robot: registered as an entry point, loaded by name.

    :param interface: which hardware interface it implements; it decides the bridge's
        controller (``torque``: hybrid force/impedance, ``position``: task-space IK).
    :param config_files: ``(package, file)`` in ``share/<package>/config`` with the defaults of
        the robot's own parameters and of its controller's gains for this robot.
    :param parameters: the robot's own parameters, declared by the ``sim`` node.
    :param describe: the description from those parameters (nested dict), without building the
        robot (the separate bridge and estimator processes need only this).
    :param create: builds the robot from those parameters.
    """
    interface: Literal["torque", "position"]
    config_files: tuple[tuple[str, str], ...]
    parameters: tuple[ParameterSection, ...]
    describe: Callable[[dict[str, Any]], RobotDescription]
    create: Callable[[dict[str, Any]], Robot]


@dataclass(frozen=True)
class RobotChoice:
    """Which robot a process runs.

    :param robot: the robot plugin to load, by its entry-point name in the group
        ``robot_bridge_node.robots`` (``sim_panda``, ``sim_nextage``, ...).
    """
    robot: str = "sim_panda"


#: The ``robot`` parameter (declared by the node that loads the plugin).
ROBOT_SECTION = ParameterSection("", RobotChoice)


def robot_names() -> list[str]:
    """Names of the robots installed as plugins."""
    return sorted(ep.name for ep in entry_points(group=ROBOT_PLUGIN_GROUP))


def robot_plugin(name: str) -> RobotPlugin:
    """The plugin registered as ``name``.

    :raises ValueError: if no installed package registers that name (lists those that do).
    """
    found = [ep for ep in entry_points(group=ROBOT_PLUGIN_GROUP) if ep.name == name]
    if not found:
        raise ValueError(f"no robot plugin named {name!r}; installed: {robot_names()}")
    plugin = found[0].load()
    if not isinstance(plugin, RobotPlugin):
        raise TypeError(f"entry point {name!r} is {type(plugin).__name__}, not a RobotPlugin")
    return plugin


def load_robot(name: str, params: dict[str, Any] | None = None) -> Robot:
    """Build the robot ``name`` from its parameters (its config sections; defaults if absent)."""
    return robot_plugin(name).create(params or {})
