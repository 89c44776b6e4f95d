"""The simulated robots as plugins of the bridge (entry-point group ``robot_bridge_node.robots``).

Each adapter puts a pybullet scene behind the bridge's hardware interface (``read``/``write``)
and its simulation interface (``reset``, ``ground_truth``, ``contact_wrench``); ``setup.py``
registers them by name, and ``ros2 run robot_bridge_node robot --ros-args -p robot:=<name>``
loads one. The bridge never imports this module.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from qg_common.panda_description import JOINT_NAMES
from qg_common.params import POSITIVE, ParameterSection
from qg_common.types import GroundTruth, JointState
from robot_bridge_node.core.hardware_interface import (Robot, RobotDescription, RobotPlugin,
                                                       ToolDescription)

from sim_robot_node.core.panda_scene import PandaSceneConfig, PandaShaftScene

__all__ = ["SimPanda", "SIM_PANDA"]


class SimPanda:
    """The Panda shaft-into-bearing scene as a torque-controlled arm with a simulation.

    ``write`` applies the torques and steps the physics once: in lockstep the loop's tick is the
    simulation's clock.
    """

    joint_names = JOINT_NAMES

    def __init__(self, scene: PandaShaftScene) -> None:
        self.scene = scene

    # --- torque interface ------------------------------------------------------------------
    def read(self) -> JointState:
        return self.scene.joint_state()

    def write(self, tau: np.ndarray) -> None:
        self.scene.apply_torques(tau)
        self.scene.step()

    # --- simulation interface --------------------------------------------------------------
    def reset(self, initial_pose: int, housing_yaw: float = 0.0) -> None:
        self.scene.reset(initial_pose, housing_yaw)

    def ground_truth(self) -> GroundTruth:
        return self.scene.ground_truth()

    def contact_wrench(self) -> np.ndarray:
        return self.scene.contact_wrench()


def _panda_config(params: dict[str, Any]) -> PandaSceneConfig:
    return PandaSceneConfig.from_dict(params.get("panda_scene", {}))


def _describe_panda(params: dict[str, Any]) -> RobotDescription:
    """The Panda holding the shaft at the grasp point, the shaft's weight a payload."""
    config = _panda_config(params)
    tool = ToolDescription(offset=config.tool_offset, payload_mass=config.shaft_mass,
                           payload_com=config.tool_offset + config.shaft_com)
    return RobotDescription(joint_names=JOINT_NAMES, tool=tool, dt=config.time_step)


def _create_panda(params: dict[str, Any]) -> Robot:
    sim = SimPanda(PandaShaftScene(_panda_config(params)))
    return Robot(hardware=sim, simulation=sim, description=_describe_panda(params))


#: The Panda scene's parameters: every length, mass and friction positive.
_PANDA_SCENE = ParameterSection("panda_scene", PandaSceneConfig, ranges={
    **{name: POSITIVE for name, kind in PandaSceneConfig.__annotations__.items()
       if kind == "float"},
    "time_step": (0.0, 0.01), "solver_iterations": (1, 10000), "bore_segments": (8, 10000)})

#: ``robot:=sim_panda``: the Panda pressing a shaft into a bearing (config/panda_scene.yaml).
SIM_PANDA = RobotPlugin(interface="torque", config_files=(("sim_robot_node", "panda_scene.yaml"),),
                        parameters=(_PANDA_SCENE,), describe=_describe_panda,
                        create=_create_panda)
