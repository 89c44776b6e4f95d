"""The UFACTORY xArm 7 as an ``ArmDescription``: the second torque-controlled arm of the stack.

The URDF is ``example-robot-data``'s ``xarm_description/urdf/xarm7.urdf`` (generated from
UFACTORY's ``xarm_ros2`` xacro, BSD-3-Clause): 7 revolute joints, 11.3 kg of links, ``effort``
limits 50, 50, 30, 30, 30, 20, 20 Nm and 3.14 rad/s on every joint, as UFACTORY's datasheet
gives them. Tools are fixed to the flange (``link_eef``, z out of the flange). UFACTORY publishes
no torque rate limit; the Panda's 1000 Nm/s is taken, which the rate limiter reaches only on
impacts (the task's torques change by a few Nm per 10 ms).
"""
from __future__ import annotations

from functools import cache

from qg_common.arm_description import ArmDescription, example_robot_data_arm

__all__ = ["xarm7_arm", "XARM7_JOINT_NAMES", "XARM7_FLANGE", "XARM7_READY"]

XARM7_JOINT_NAMES = tuple(f"joint{i}" for i in range(1, 8))
#: The flange frame (a fixed frame of the URDF at ``link7``).
XARM7_FLANGE = "link_eef"
#: [rad] Near the flange pointing down above the shaft task's bore (0.45 m in front of the base,
#: 0.31 m up; exactly there at (0, 0.016, 0, 0.918, 0, 0.902, 0)), elbow up, the arm in the
#: base's x-z plane: what the inverse kinematics starts from.
XARM7_READY = (0.0, 0.0, 0.0, 0.9, 0.0, 0.9, 0.0)


@cache
def xarm7_arm() -> ArmDescription:
    """The xArm 7's description (the URDF is looked up once, when first asked for)."""
    return example_robot_data_arm("UFACTORY xArm 7", "xarm_description/urdf/xarm7.urdf",
                                  joint_names=XARM7_JOINT_NAMES, tool_mount=XARM7_FLANGE,
                                  ready=XARM7_READY, torque_rate_limits=(1000.0,) * 7)
