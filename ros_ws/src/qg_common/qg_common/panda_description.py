"""The Franka Panda as an ``ArmDescription``: its URDF and what the URDF does not say.

The URDF is ``example-robot-data``'s Panda (real inertias; its ``effort`` limits, 87 Nm for
joints 1-4 and 12 Nm for 5-7, and velocity limits are the Franka datasheet's). The fingers are
locked; tools are fixed to ``panda_hand_tcp``.
"""
from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np

from qg_common.arm_description import (
    ArmDescription,
    example_robot_data_arm,
    example_robot_data_urdf,
)

__all__ = ["panda_arm", "panda_urdf_path", "JOINT_NAMES", "TOOL_MOUNT", "DTAU_MAX", "Q_READY"]

#: The URDF in example-robot-data's ``robots`` folder.
PANDA_URDF = "panda_description/urdf/panda.urdf"
JOINT_NAMES = tuple(f"panda_joint{i}" for i in range(1, 8))
#: The frame tools are fixed to: the hand's tool centre point.
TOOL_MOUNT = "panda_hand_tcp"
#: Joint torque rate limits [Nm/s] (Franka datasheet: 1000 Nm/s on every joint).
DTAU_MAX = np.full(7, 1000.0)
#: A comfortable configuration with the hand pointing down.
Q_READY = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.785])


def panda_urdf_path() -> Path:
    """Path of the example-robot-data Panda URDF (with real inertias).

    :raises FileNotFoundError: if the package or the file is missing.
    """
    return example_robot_data_urdf(PANDA_URDF)


@cache
def panda_arm() -> ArmDescription:
    """The Panda's description (the URDF is looked up once, when first asked for)."""
    return example_robot_data_arm("Franka Panda", PANDA_URDF, joint_names=JOINT_NAMES,
                                  tool_mount=TOOL_MOUNT, ready=tuple(Q_READY.tolist()),
                                  torque_rate_limits=tuple(DTAU_MAX.tolist()))
