"""The Franka Research 3 as an ``ArmDescription``: the URDF franky-sim ships, and what it lacks.

franky-sim (``franky_sim/assets/fr3.urdf``, Franka's ``franka_description`` with the hand) is the
arm the plugin is rehearsed against, so the bridge's model reads that file: 7 revolute joints
``fr3_joint1..7``, 16.2 kg of links and hand, ``effort`` limits 87 Nm (joints 1-4) and 12 Nm
(5-7), velocity limits 2.62-5.26 rad/s, as Franka's datasheet gives them. The fingers are locked;
tools are fixed to the hand's tool centre point ``fr3_hand_tcp`` (0.1034 m beyond the flange
``fr3_link8``, turned -45 deg about its z), as the Panda's are to ``panda_hand_tcp``. The URDF
has no torque rate: libfranka's limit is 1000 Nm/s on every joint (``kMaxTorqueRate``).

The file is found without importing ``franky_sim`` (which loads Pinocchio, MuJoCo's server code
and more): only its folder is looked up.
"""
from __future__ import annotations

import importlib.util
from functools import cache
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
    """franky-sim's FR3 URDF with the hand (``franky_sim/assets/fr3.urdf``).

    :raises FileNotFoundError: if franky-sim is not installed or lacks the file.
    """
    spec = importlib.util.find_spec("franky_sim")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("franky-sim is not installed (scripts/requirements.txt pins it)")
    path = Path(next(iter(spec.submodule_search_locations))) / "assets" / "fr3.urdf"
    if not path.is_file():
        raise FileNotFoundError(f"franky-sim's FR3 URDF not found at {path}")
    return path


@cache
def fr3_arm() -> ArmDescription:
    """The FR3's description (the URDF is looked up once, when first asked for)."""
    return ArmDescription(name="Franka Research 3", urdf=str(fr3_urdf_path()),
                          joint_names=FR3_JOINT_NAMES, flange=FR3_TOOL_FRAME, ready=FR3_READY,
                          torque_rate_limits=(FR3_TORQUE_RATE_LIMIT,) * 7)
