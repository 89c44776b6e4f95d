"""``robot:=franka``: a Franka FR3 through libfranka, registered under the bridge's entry-point
group ``robot_bridge_node.robots`` (``setup.py``); the bridge never imports this module.

The robot is a real arm to the bridge (``simulation=None``: resets are motions, reward and
success are measured): against franky-sim as against a real FR3 the plugin only speaks
libfranka's protocol, and only ``franka.address`` and ``franka.realtime``
(``config/franka.yaml``) change between the two. Its ``read`` waits for the robot's next state,
so the robot paces the bridge's realtime loop (``paced_by_hardware``).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from robot_bridge_node.core.hardware_interface import (
    Robot,
    RobotDescription,
    RobotPlugin,
    ToolDescription,
)

from franka_robot_node.core.fr3_description import fr3_arm
from franka_robot_node.core.franka_arm import FrankaArm
from franka_robot_node.core.franka_config import FRANKA_SECTION, FrankaConfig

__all__ = ["FRANKA", "franka_config", "describe_franka"]

#: [s] libfranka's control period.
FRANKA_DT = 0.001


def franka_config(params: dict[str, Any]) -> FrankaConfig:
    """The plugin's parameters from a node's (nested) parameters, section ``franka``."""
    return FrankaConfig.from_dict(params.get("franka", {}))


def describe_franka(params: dict[str, Any]) -> RobotDescription:
    """The FR3 holding the configured part at its hand's tool centre point: the bridge's model
    is franky-sim's FR3 URDF (hand included), the part a payload."""
    tool, arm = franka_config(params).tool, fr3_arm()
    held = ToolDescription(offset=np.array(tool.offset), payload_mass=tool.mass,
                           payload_com=np.array(tool.offset) + np.array(tool.com))
    return RobotDescription(joint_names=arm.joint_names, tool=held, dt=FRANKA_DT, urdf=arm.urdf,
                            tool_frame=arm.tool_mount, torque_limits=arm.torque_limits,
                            torque_rate_limits=arm.torque_rate_limits)


def _create(params: dict[str, Any]) -> Robot:
    description = describe_franka(params)
    arm = FrankaArm.connect(franka_config(params), description)
    return Robot(hardware=arm, simulation=None, description=description, paced_by_hardware=True,
                 own_wrench=arm.external_wrench)


#: ``robot:=franka`` (config/franka.yaml).
FRANKA = RobotPlugin(interface="torque", config_files=(("franka_robot_node", "franka.yaml"),),
                     parameters=(FRANKA_SECTION,), describe=describe_franka, create=_create,
                     simulated=False, own_wrench_topic="franka/external_wrench")
