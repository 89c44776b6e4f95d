"""Setpoint messages <-> the bridge core's ``WrenchSetpoint``.

The converters of the simulated hardware's messages (joint states, wrenches, poses, ground truth,
at-rest events) live in ``sim_robot_node.conversions``; these need the bridge's own types.
"""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from qg_interfaces.msg import WrenchSetpoint as WrenchSetpointMsg
from sim_robot_node.conversions import matrix_from_quaternion, pose_msg, wrench_from_msg, wrench_msg

from robot_bridge_node.core.types import PoseReference, WrenchSetpoint

__all__ = ["setpoint_from_msg", "setpoint_msg"]


def setpoint_from_msg(msg: WrenchSetpointMsg) -> WrenchSetpoint:
    """The core setpoint; values are not checked here (the safety filter rejects NaN/inf)."""
    reference = None
    if not msg.reference_from_current:
        p, o = msg.pose_reference.position, msg.pose_reference.orientation
        reference = PoseReference(np.array([p.x, p.y, p.z]),
                                  matrix_from_quaternion(o.x, o.y, o.z, o.w))
    return WrenchSetpoint(wrench_from_msg(msg.wrench), reference)


def setpoint_msg(seq: int, setpoint: WrenchSetpoint, stamp: Time) -> WrenchSetpointMsg:
    """The message of a core setpoint (what the executor sends)."""
    msg = WrenchSetpointMsg(seq=int(seq), wrench=wrench_msg(setpoint.wrench),
                            reference_from_current=setpoint.reference is None)
    if setpoint.reference is not None:
        msg.pose_reference = pose_msg(setpoint.reference.position, setpoint.reference.rotation)
    msg.header.stamp = stamp
    return msg
