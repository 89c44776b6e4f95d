"""What the simulator and the bridge's model both need to know about a torque-controlled arm.

In ROS 2 the robot description is what the hardware and the controllers both read, so it lives in
the common package and neither side imports the other. An ``ArmDescription`` names the arm's URDF
and, of that URDF, the joints the arm is driven by (every other joint, a gripper's fingers say, is
locked) and the frame a tool is fixed to (its mount: a flange, or a hand's tool centre point). Everything the URDF already says (kinematics,
inertias, torque and velocity limits) is read from it through Pinocchio by the bridge and loaded
into pybullet by the simulator; the description only adds what a URDF cannot carry: the torque
rate limit of the drives and a comfortable configuration to start inverse kinematics from.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path
from typing import Any

__all__ = ["ArmDescription", "example_robot_data_urdf", "example_robot_data_arm"]


@dataclass(frozen=True)
class ArmDescription:
    """A torque-controlled arm as its URDF and its datasheet describe it.

    :param name: a short name for messages.
    :param urdf: the URDF file (kinematics, inertias, torque and velocity limits).
    :param joint_names: the driven joints, in the order of every joint vector; any other movable
        joint of the URDF is locked at its neutral position.
    :param tool_mount: the URDF frame the tool is fixed to (the flange, or a hand's tool centre
        point); the tool's offset is relative to it.
    :param ready: (n,) [rad] a configuration near the task with the tool mount pointing down, from
        which inverse kinematics starts.
    :param torque_rate_limits: (n,) [Nm/s] how fast each drive's torque may change (a
        datasheet figure: URDFs have no field for it).
    :param torque_limits: (n,) [Nm] overrides the URDF's ``effort`` limits; ``None`` keeps them.
    """
    name: str
    urdf: str
    joint_names: tuple[str, ...]
    tool_mount: str
    ready: tuple[float, ...]
    torque_rate_limits: tuple[float, ...]
    torque_limits: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        if n == 0 or len(set(self.joint_names)) != n:
            raise ValueError(f"{self.name}: joint_names must be distinct and non-empty, "
                             f"got {self.joint_names}")
        for field_name in ("ready", "torque_rate_limits", "torque_limits"):
            values = getattr(self, field_name)
            if values is None:
                continue
            if len(values) != n:
                raise ValueError(f"{self.name}: {field_name} needs {n} entries (one a joint), "
                                 f"got {len(values)}")
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"{self.name}: {field_name} must be finite, got {values}")
        for field_name in ("torque_rate_limits", "torque_limits"):
            values = getattr(self, field_name)
            if values is not None and min(values) <= 0.0:
                raise ValueError(f"{self.name}: {field_name} must be > 0, got {values}")

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)


def example_robot_data_urdf(relative: str) -> Path:
    """A URDF of the ``example-robot-data`` package (Gepetto/LAAS's maintained robot models, on
    PyPI as a cmeel wheel), e.g. ``panda_description/urdf/panda.urdf``.

    The wheel ships only data, no Python module, so the file is found through the installed
    distribution.
    :raises FileNotFoundError: if the package or the file is missing.
    """
    try:
        dist = distribution("example-robot-data")
    except PackageNotFoundError as exc:
        raise FileNotFoundError("example-robot-data is not installed") from exc
    path = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots/"
                                     + relative)))
    if not path.is_file():
        raise FileNotFoundError(f"URDF not found at {path}")
    return path


def example_robot_data_arm(name: str, urdf: str, **description: Any) -> ArmDescription:
    """The description of an arm whose URDF ``example-robot-data`` ships (``urdf`` relative to
    its ``robots`` folder); ``description``: the other fields of ``ArmDescription``.

    :raises FileNotFoundError: if the package or the file is missing.
    """
    return ArmDescription(name=name, urdf=str(example_robot_data_urdf(urdf)), **description)
