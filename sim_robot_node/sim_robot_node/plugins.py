"""The simulated robots as plugins of the bridge (entry-point group ``robot_bridge_node.robots``).

Each adapter puts a pybullet scene behind the bridge's hardware interface (``read``/``write``)
and its simulation interface (``reset``, ``ground_truth``, ``contact_wrench``); ``setup.py``
registers them by name, and ``ros2 run robot_bridge_node robot --ros-args -p robot:=<name>``
loads one. The bridge never imports this module. A torque arm in the shaft scene is
``shaft_arm_plugin(arm, section, config file)``: ``sim_panda`` and ``sim_xarm7`` are two calls.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
from qg_common.arm_description import ArmDescription
from qg_common.panda_description import panda_arm
from qg_common.params import POSITIVE, ParameterSection
from qg_common.peg_task import PEG_TASK_FILE, PEG_TASK_SECTION, PegCell
from qg_common.shaft_task import SHAFT_TASK_FILE, SHAFT_TASK_SECTION, ShaftTaskGeometry
from qg_common.types import GroundTruth, JointState, StartPose
from qg_common.xarm_description import xarm7_arm
from robot_bridge_node.core.hardware_interface import (
    Robot,
    RobotDescription,
    RobotPlugin,
    ToolDescription,
)

from sim_robot_node.core.arm_imperfections import ArmImperfections
from sim_robot_node.core.nextage_scene import NextagePegScene, NextageSceneConfig, nextage_urdf_path
from sim_robot_node.core.shaft_scene import ShaftScene, ShaftSceneConfig

__all__ = ["SimShaftArm", "shaft_arm_plugin", "shaft_scene_section", "SIM_PANDA",
           "SIM_PANDA_MUJOCO", "SIM_PANDA_PYBULLET", "SIM_XARM7",
           "SimNextage", "SIM_NEXTAGE", "NEXTAGE_JOINT_NAMES"]

#: The Nextage right arm's joints, as its URDF names them (the order of every joint vector).
NEXTAGE_JOINT_NAMES = tuple(f"RARM_JOINT{i}" for i in range(6))


class SimShaftArm:
    """A torque-controlled arm in the shaft-into-bearing scene, with the scene's simulation.

    ``write`` applies the torques and steps the physics once: in lockstep the loop's tick is the
    simulation's clock.
    """

    def __init__(self, scene: ShaftScene) -> None:
        self.scene = scene
        self.joint_names = scene.arm_description.joint_names

    # --- torque interface ------------------------------------------------------------------
    def read(self) -> JointState:
        return self.scene.joint_state()

    def write(self, tau: np.ndarray) -> None:
        self.scene.apply_torques(tau)
        self.scene.step()

    # --- simulation interface --------------------------------------------------------------
    def teleport(self, start: StartPose) -> None:
        self.scene.teleport(start)

    def ground_truth(self) -> GroundTruth:
        return self.scene.ground_truth()

    def contact_wrench(self) -> np.ndarray:
        return self.scene.contact_wrench()

    def close(self) -> None:
        """Release the physics (a process that builds many)."""
        self.scene.close()


def shaft_scene_section(prefix: str) -> ParameterSection:
    """A shaft scene's parameters under ``prefix``: every mass, friction and force positive,
    every imperfection >= 0 (0: off)."""
    return ParameterSection(prefix, ShaftSceneConfig, ranges={
        **{name: POSITIVE for name, kind in ShaftSceneConfig.__annotations__.items()
           if kind == "float"},
        **{f"imperfections.{name}": POSITIVE
           for name, kind in ArmImperfections.__annotations__.items() if kind == "float"},
        "imperfections.seed": (0, 2 ** 31 - 1),
        "time_step": (0.0, 0.01), "bore_segments": (8, 10000),
        "counterbore_segments": (8, 10000), "pybullet.solver_iterations": (1, 10000),
        "pybullet.contact_breaking_threshold": POSITIVE, "mujoco.iterations": (1, 10000)})


def shaft_arm_plugin(arm: Callable[[], ArmDescription], section: str,
                     config_files: tuple[str, ...], engine: str | None = None) -> RobotPlugin:
    """The plugin of a torque arm holding the shaft: the cell's geometry from
    ``config/shaft_task.yaml``, its physics the section ``section`` of the ``config_files``
    (this package's, each over the one before; a ``ShaftSceneConfig``: what no file names keeps
    the dataclass default, the task's numbers).

    :param arm: the arm's description (called when the robot is described, not at import).
    :param engine: the physics engine whatever the parameters say (``sim_panda_pybullet``
        stays pybullet when a caller's parameters leave the engine to the default); ``None``:
        the parameters' ``engine``.
    """
    def config(params: dict[str, Any]) -> ShaftSceneConfig:
        config = ShaftSceneConfig.from_dict(params.get(section, {}))
        return config if engine is None else dataclasses.replace(config, engine=engine)

    def geometry(params: dict[str, Any]) -> ShaftTaskGeometry:
        return ShaftTaskGeometry.from_dict(params.get(SHAFT_TASK_SECTION.prefix, {}))

    def describe(params: dict[str, Any]) -> RobotDescription:
        """The arm holding the shaft at its tool mount (the grasp point), the shaft's weight a
        payload; the model is the arm's URDF with its tool mount as the tool's frame."""
        description = arm()
        tool = ToolDescription(offset=np.zeros(3), payload_mass=config(params).shaft_mass,
                               payload_com=geometry(params).shaft_centre)
        return RobotDescription(joint_names=description.joint_names, tool=tool,
                                dt=config(params).time_step, urdf=description.urdf,
                                tool_frame=description.tool_mount,
                                torque_limits=description.torque_limits,
                                torque_rate_limits=description.torque_rate_limits)

    def create(params: dict[str, Any]) -> Robot:
        sim = SimShaftArm(ShaftScene(config(params), geometry(params), arm()))
        return Robot(hardware=sim, simulation=sim, description=describe(params))

    return RobotPlugin(interface="torque",
                       config_files=(SHAFT_TASK_FILE,
                                     *(("sim_robot_node", name) for name in config_files)),
                       parameters=(SHAFT_TASK_SECTION, shaft_scene_section(section)),
                       describe=describe, create=create)


#: ``robot:=sim_panda``: the Panda pressing a shaft into a bearing (config/panda_scene.yaml).
SIM_PANDA = shaft_arm_plugin(panda_arm, "panda_scene", ("panda_scene.yaml",))
#: ``robot:=sim_panda_mujoco``: the same Panda and cell on MuJoCo (config/panda_mujoco.yaml
#: picks the engine over config/panda_scene.yaml).
SIM_PANDA_MUJOCO = shaft_arm_plugin(panda_arm, "panda_scene",
                                    ("panda_scene.yaml", "panda_mujoco.yaml"), engine="mujoco")
#: ``robot:=sim_panda_pybullet``: the same Panda and cell on pybullet.
SIM_PANDA_PYBULLET = shaft_arm_plugin(panda_arm, "panda_scene",
                                      ("panda_scene.yaml", "panda_pybullet.yaml"),
                                      engine="pybullet")
#: ``robot:=sim_xarm7``: the UFACTORY xArm 7 in the same scene (config/xarm_scene.yaml).
SIM_XARM7 = shaft_arm_plugin(xarm7_arm, "xarm_scene", ("xarm_scene.yaml",))


class SimNextage:
    """The Nextage peg scene as a position-controlled arm with a wrist force-torque sensor.

    ``write`` holds the joint targets and steps the physics once. The sensor is tared in free
    air at every teleport (hand and peg weigh on it), so it reads the contact wrench.
    """

    #: [steps] the arm hangs this long after a teleport before the sensor is tared.
    TARE_STEPS = 50

    def __init__(self, scene: NextagePegScene) -> None:
        self.scene = scene
        self.joint_names = scene.joint_names
        self._tare = np.zeros(6)

    # --- position interface and wrist sensor -----------------------------------------------
    def read(self) -> JointState:
        return self.scene.joint_state()

    def write(self, q: np.ndarray) -> None:
        self.scene.set_joint_targets(q)
        self.scene.step()

    def read_wrench(self) -> np.ndarray:
        return self.scene.wrist_wrench() - self._tare

    # --- simulation interface --------------------------------------------------------------
    def teleport(self, start: StartPose) -> None:
        """The peg tip where the start's tool pose puts it (the tool points down), the sensor
        tared in free air."""
        self.scene.reset(start=self.scene.cell.tip(start.position, start.rotation))
        for _ in range(self.TARE_STEPS):
            self.scene.step()
        self._tare = self.scene.wrist_wrench()

    def ground_truth(self) -> GroundTruth:
        """The peg's truth in the stack's terms: position error = tip to hole bottom."""
        truth, g = self.scene.ground_truth(), self.scene.geometry
        return GroundTruth(wrench=self.read_wrench(),
                           insertion_depth=float(g.block_height - truth.tip[2]),
                           plunger_travel=0.0, success=truth.success,
                           position_error=truth.distance, orientation_error=np.zeros(2),
                           lateral_offset=float(np.linalg.norm(truth.tip[:2])), tilt=0.0)

    def contact_wrench(self) -> np.ndarray:
        return self.read_wrench()

    def close(self) -> None:
        """Disconnect the physics (a process that builds many)."""
        self.scene.close()


def _nextage_config(params: dict[str, Any]) -> NextageSceneConfig:
    return NextageSceneConfig.from_dict(params.get("scene", {}))


def _peg_cell(params: dict[str, Any]) -> PegCell:
    return PegCell.from_dict(params.get(PEG_TASK_SECTION.prefix, {}))


def _describe_nextage(params: dict[str, Any]) -> RobotDescription:
    """The Nextage's right arm, its tool frame at the hand holding the peg (the IK's frame)."""
    config, cell = _nextage_config(params), _peg_cell(params)
    tool = ToolDescription(offset=np.zeros(3), payload_mass=cell.geometry.peg_mass,
                           payload_com=np.zeros(3))
    return RobotDescription(joint_names=NEXTAGE_JOINT_NAMES, tool=tool, dt=config.time_step,
                            urdf=str(nextage_urdf_path()), tool_frame=NextagePegScene.TOOL_LINK)


def _create_nextage(params: dict[str, Any]) -> Robot:
    sim = SimNextage(NextagePegScene(_nextage_config(params), _peg_cell(params)))
    return Robot(hardware=sim, simulation=sim, description=_describe_nextage(params),
                 wrist_sensor=sim)


#: The Nextage scene's parameters (``scene.*``); the cell's are ``peg_task.*``.
_NEXTAGE_SCENE = ParameterSection("scene", NextageSceneConfig, ranges={
    "time_step": (0.0, 0.01), "position_gain": (0.0, 1.0), "velocity_gain": POSITIVE,
    "effort_scale": POSITIVE, "solver_iterations": (1, 10000)})

#: ``robot:=sim_nextage``: the Nextage arm with the clearance-fit peg (config/peg_task.yaml: the
#: cell; config/nextage.yaml: the scene and the task-space position controller's gains for this
#: arm).
SIM_NEXTAGE = RobotPlugin(interface="position",
                          config_files=(PEG_TASK_FILE, ("sim_robot_node", "nextage.yaml")),
                          parameters=(PEG_TASK_SECTION, _NEXTAGE_SCENE),
                          describe=_describe_nextage, create=_create_nextage)
