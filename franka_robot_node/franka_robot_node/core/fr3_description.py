"""The Franka Research 3 as an ``ArmDescription``: its URDF, and what the URDF lacks.

The URDF (``description/fr3.urdf``, Franka's ``franka_description`` with the hand, as franky-sim
ships it: the arm the plugin is rehearsed against) is this package's own, so a real arm's
computer needs no simulator: 7 revolute joints
``fr3_joint1..7``, 16.2 kg of links and hand, ``effort`` limits 87 Nm (joints 1-4) and 12 Nm
(5-7), velocity limits 2.62-5.26 rad/s, as Franka's datasheet gives them. The fingers are locked;
tools are fixed to the hand's tool centre point ``fr3_hand_tcp`` (0.1034 m beyond the flange
``fr3_link8``, turned -45 deg about its z), as the Panda's are to ``panda_hand_tcp``. The URDF
has no torque rate: libfranka's limit is 1000 Nm/s on every joint (``kMaxTorqueRate``).
"""
from __future__ import annotations

from functools import cache
from importlib.resources import files
from pathlib import Path

from qg_common.arm_description import ArmDescription

__all__ = ["fr3_arm", "fr3_urdf_path", "FR3_JOINT_NAMES", "FR3_FLANGE", "FR3_TOOL_FRAME",
           "FR3_READY", "FR3_TORQUE_RATE_LIMIT"]

FR3_JOINT_NAMES = tuple(f"fr3_joint{i}" for i in range(1, 8))
#: libfranka's flange frame F (``setLoad``'s centre of mass is given in it).
FR3_FLANGE = "fr3_link8"
#: The frame the held tool is fixed to: the hand's tool centre point, between the fingertips.
FR3_TOOL_FRAME = "fr3_hand_tcp"
#: [rad] The tool centre point 0.45 m in front of the base and 0.31 m up, pointing straight down
#: (hand x along the base's x), elbow up: above the shaft task's bore, as the Panda's ready pose.
#: Found once with Pinocchio's damped least squares from franky-sim's start pose
#: (0, 0, 0, -1.57, 0, 1.57, 0.785), which holds the tool centre point down at (0.554, 0, 0.521).
FR3_READY = (0.0, -0.272, 0.0, -2.416, 0.0, 2.145, 0.785)
#: [Nm/s] libfranka's torque rate limit (``franka/rate_limiting.h``: 1000 Nm/s on every joint).
FR3_TORQUE_RATE_LIMIT = 1000.0


def fr3_urdf_path() -> Path:
    """The FR3's URDF with the hand, shipped with this package.

    :raises FileNotFoundError: if the package's copy is missing (a broken install).
    """
    path = Path(str(files("franka_robot_node").joinpath("description", "fr3.urdf")))
    if not path.is_file():
        raise FileNotFoundError(f"the FR3's URDF is missing from this package: {path}")
    return path


@cache
def fr3_arm() -> ArmDescription:
    """The FR3's description (the URDF is looked up once, when first asked for)."""
    return ArmDescription(name="Franka Research 3", urdf=str(fr3_urdf_path()),
                          joint_names=FR3_JOINT_NAMES, tool_mount=FR3_TOOL_FRAME, ready=FR3_READY,
                          torque_rate_limits=(FR3_TORQUE_RATE_LIMIT,) * 7)
