"""The one seam between the bridge and a robot, and how robots are found by name.

Modelled on ros2_control: the loop, the controllers and the estimator only ever call ``read()``
(the joint state) and ``write()`` (the command for one control period) on a hardware interface,
so they never know whether a real arm, a simulator or a topic answers. Powers only a simulation
has (teleporting to a start pose, ground truth) sit beside the seam in ``SimulationInterface``,
as Gazebo's ``initSim`` does; a real arm has ``simulation=None``, and the loop moves it to a
start instead (``start_motion``). Nothing the task needs comes from the simulation: reward,
success and the episode's ends are computed from what the arm measures.

Robots are plugins: a package registers a ``RobotPlugin`` under the entry-point group
``robot_bridge_node.robots`` (Python's entry points play pluginlib's role), and the robot process
loads the one named by its ``robot`` parameter. This package never imports an implementation:
``sim_robot_node`` registers ``sim_panda``, ``sim_xarm7`` and ``sim_nextage``; a real Franka would
be one more entry point in its own package. A plugin names its hardware interface kind
(``interface_kinds``), found the same way; a torque robot's description names its URDF, from
which the bridge builds its model (``arm_model``).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from qg_common.params import ParameterSection, load_ros_params, merge_params, package_config
from qg_common.plugins import ROBOT_PLUGIN_GROUP, load_registered, registered_names
from qg_common.types import GroundTruth, JointState, StartPose

__all__ = ["HardwareFault", "Recoverable", "TorqueInterface", "PositionInterface",
           "StampedStates", "ForceTorqueSensor",
           "SimulationInterface", "ToolDescription",
           "RobotDescription", "Robot", "RobotPlugin", "RobotChoice", "ROBOT_SECTION",
           "ROBOT_PLUGIN_GROUP", "robot_names", "robot_plugin", "load_robot", "robot_defaults"]



class HardwareFault(RuntimeError):
    """The robot stopped what it was doing (a reflex, a missed deadline, a lost connection):
    raised by ``read`` or ``write``; the step under way is over. The message is the robot's
    reason. A ``Recoverable`` robot takes commands again only after ``recover``."""


class Recoverable(Protocol):
    """Hardware that must be told to leave a fault, as a Franka's error recovery does."""

    @property
    def fault(self) -> str | None:
        """Why the robot stopped, until ``recover`` (``None``: no fault)."""
        ...

    def recover(self) -> str:
        """Leave the fault (the robot's own recovery); what was done, for the log.

        :raises HardwareFault: if the robot refuses.
        """
        ...


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
    """What only a simulated robot can do: be put at a start at once, and tell the truth
    (for evaluation only)."""

    def teleport(self, start: StartPose) -> None:
        """Put the arm at rest with its tool at ``start``, and the task's parts at their start:
        the shortcut for the motion a real arm makes (``RobotLoop.reset``)."""
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

    A torque robot's model is built from this alone (``arm_model.ArmModel.from_description``):
    the URDF gives the joint count, kinematics, inertias and the torque and velocity limits; the
    description names the joints, the flange and the tool, and overrides a limit where the
    robot's datasheet says otherwise than its URDF.

    :param joint_names: the arm's joints, in the order of every joint vector.
    :param tool: the held tool, for the controller's and the estimator's model.
    :param dt: [s] the control period the hardware runs at.
    :param urdf: the arm's URDF ("" if the bridge needs none).
    :param tool_frame: the frame of that URDF the bridge controls: a torque robot's flange, which
        ``tool.offset`` is relative to; a position robot's IK frame.
    :param torque_limits: (n,) [Nm] instead of the URDF's ``effort`` limits; ``None``: the URDF's.
    :param torque_rate_limits: (n,) [Nm/s] how fast a torque command may change; ``None``:
        unlimited (URDFs have no field for it).
    """
    joint_names: tuple[str, ...]
    tool: ToolDescription
    dt: float
    urdf: str = ""
    tool_frame: str = ""
    torque_limits: tuple[float, ...] | None = None
    torque_rate_limits: tuple[float, ...] | None = None


@dataclass
class Robot:
    """A robot as the bridge gets it from a plugin.

    :param hardware: the interface the loop reads and writes every period.
    :param simulation: the simulation's extra powers; ``None`` on real hardware.
    :param wrist_sensor: a force-torque sensor at the wrist, if the robot has one; the loop's
        wrench then comes from it instead of an estimator.
    :param paced_by_hardware: ``read`` waits for the robot's next state (a real arm's 1 kHz, as
        libfranka's ``readOnce``; the hardware is ``StampedStates``): a realtime loop ticks
        when the robot says, on the states' clock, with no pace of its own.
    :param own_wrench: the robot's own estimate of the external wrench (a Franka's
        ``O_F_ext_hat_K``) in the last state read, if its controller gives one: (6,) in the
        robot's base frame. The loop never uses it; it is published and recorded beside the
        loop's estimate (``RobotPlugin.own_wrench_topic``) so that a cell can compare the two.
    """
    hardware: TorqueInterface | PositionInterface
    simulation: SimulationInterface | None
    description: RobotDescription
    wrist_sensor: ForceTorqueSensor | None = None
    paced_by_hardware: bool = False
    own_wrench: Callable[[], np.ndarray] | None = None


@dataclass(frozen=True)
class RobotPlugin:
    """How a robot package makes its robot: registered as an entry point, loaded by name.

    :param interface: the name of the hardware interface kind it implements, registered under
        ``robot_bridge_node.interfaces`` (``interface_kinds``); the kind decides the bridge's
        loop, controller and parameters (``torque``: hybrid force/impedance and the EKF,
        ``position``: task-space IK and the wrist sensor).
    :param config_files: ``(package, file)`` in ``share/<package>/config`` with the defaults of
        the robot's own parameters and of its controller's gains for this robot.
    :param parameters: the robot's own parameters, declared by the ``sim`` node (a real
        robot's by the ``hardware`` node).
    :param describe: the description from those parameters (nested dict), without building the
        robot (the separate bridge and estimator processes need only this).
    :param create: builds the robot from those parameters.
    :param simulated: a simulation (its robot process has a ``sim`` node: ground truth, a
        simulated clock); False for a real robot (a ``hardware`` node instead).
    :param own_wrench_topic: where the robot's own wrench estimate is published (relative, e.g.
        ``franka/external_wrench``); "" if its robots have none.
    """
    interface: str
    config_files: tuple[tuple[str, str], ...]
    parameters: tuple[ParameterSection, ...]
    describe: Callable[[dict[str, Any]], RobotDescription]
    create: Callable[[dict[str, Any]], Robot]
    simulated: bool = True
    own_wrench_topic: str = ""


@dataclass(frozen=True)
class RobotChoice:
    """Which robot a process runs.

    :param robot: the robot plugin to load, by its entry-point name in the group
        ``robot_bridge_node.robots`` (``sim_panda``, ``sim_xarm7``, ``sim_nextage``, ...).
    """
    robot: str = "sim_panda"


#: The ``robot`` parameter (declared by the node that loads the plugin).
ROBOT_SECTION = ParameterSection("", RobotChoice)


def robot_names() -> list[str]:
    """Names of the robots installed as plugins."""
    return registered_names(ROBOT_PLUGIN_GROUP)


def robot_plugin(name: str) -> RobotPlugin:
    """The plugin registered as ``name``.

    :raises ValueError: if no installed package registers that name (lists those that do).
    """
    return load_registered(ROBOT_PLUGIN_GROUP, name, RobotPlugin, "robot plugin")


def load_robot(name: str, params: dict[str, Any] | None = None) -> Robot:
    """Build the robot ``name`` from its parameters (its config sections; defaults if absent)."""
    return robot_plugin(name).create(params or {})


def robot_defaults(plugin: RobotPlugin, base: Sequence[tuple[str, str]] = (),
                   node: str | None = None) -> dict[str, Any]:
    """The parameters a node gets by default for this robot: the ``base`` files
    ``(package, file)``, then the plugin's own ``config_files`` over them, as the node declares
    them (e.g. the bridge's: ``config/bridge.yaml``, then a robot's gains for itself).

    :param node: the node whose section of each file counts over ``/**`` (``None``: ``/**``).
    """
    params: dict[str, Any] = {}
    for package, name in (*base, *plugin.config_files):
        params = merge_params(params, load_ros_params(package_config(package, name), node))
    return params
