"""Facts about the Franka Panda that both the simulator and the bridge's model need.

The URDF file (``example-robot-data``'s Panda, with real inertias), joint names, limits, and the
configuration the arm starts from: the robot description, which in ROS 2 both the hardware and
the controllers read, so it lives in the common package and neither side imports the other.
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

import numpy as np

__all__ = ["panda_urdf_path", "N_JOINTS", "JOINT_NAMES", "TAU_MAX", "DTAU_MAX", "Q_READY"]

N_JOINTS = 7
JOINT_NAMES = tuple(f"panda_joint{i}" for i in range(1, 8))
#: Joint torque limits [Nm] (Franka datasheet: 87 Nm for joints 1-4, 12 Nm for 5-7).
TAU_MAX = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
#: Joint torque rate limits [Nm/s] (Franka datasheet: 1000 Nm/s on every joint).
DTAU_MAX = np.full(7, 1000.0)
#: A comfortable configuration with the hand pointing down.
Q_READY = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.785])


def panda_urdf_path() -> Path:
    """Path of the example-robot-data Panda URDF (with real inertias).

    The ``example-robot-data`` wheel (cmeel) ships only data, no Python module, so the file is
    found through the installed distribution.
    :raises FileNotFoundError: if the package or the file is missing.
    """
    try:
        dist = distribution("example-robot-data")
    except PackageNotFoundError as exc:
        raise FileNotFoundError("example-robot-data is not installed") from exc
    path = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots/"
                                     "panda_description/urdf/panda.urdf")))
    if not path.is_file():
        raise FileNotFoundError(f"Panda URDF not found at {path}")
    return path
