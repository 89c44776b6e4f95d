"""The Franka plugin's parameters (section ``franka`` of ``config/franka.yaml``).

Where the robot is, how libfranka may run there, when the robot's own collision reflexes fire,
how long a torque may go unrefreshed, and the part the hand holds. franky-sim and a real arm
differ only here: the address, and the realtime policy (``ignore`` against franky-sim on a normal
kernel, ``enforce`` on a real arm's realtime kernel).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from qg_common.params import ParameterSection, config_from_dict

__all__ = ["HeldTool", "FrankaConfig", "FRANKA_SECTION", "REALTIME_POLICIES"]

#: libfranka's ``RealtimeConfig`` by the name the YAML gives it.
REALTIME_POLICIES = ("ignore", "enforce")


@dataclass(frozen=True)
class HeldTool:
    """The part the hand holds, for the bridge's model and for libfranka's load (``setLoad``).

    :param offset: (3,) [m] the tool frame's origin from the hand's tool centre point
        (``fr3_hand_tcp``), in that frame: the grasp point.
    :param mass: [kg] the held part.
    :param com: (3,) [m] its centre of mass from the tool frame's origin, in that frame (z
        towards the part's tip).
    """
    offset: tuple[float, ...] = (0.0, 0.0, 0.0)
    mass: float = 0.086
    com: tuple[float, ...] = (0.0, 0.0, 0.01)

    def __post_init__(self) -> None:
        for name in ("offset", "com"):
            value = getattr(self, name)
            if len(value) != 3 or not all(math.isfinite(v) for v in value):
                raise ValueError(f"tool.{name} must be 3 finite numbers [m], got {value}")
        if not 0.0 <= self.mass <= 3.0:
            raise ValueError(f"tool.mass must be in [0, 3] kg (the FR3's payload), "
                             f"got {self.mass}")


def _thresholds(name: str, values: tuple[float, ...], n: int) -> None:
    if len(values) != n or not all(math.isfinite(v) and v > 0.0 for v in values):
        raise ValueError(f"{name} must be {n} finite values > 0, got {values}")


@dataclass(frozen=True)
class FrankaConfig:
    """How the plugin reaches and drives the arm.

    :param address: the robot's FCI address (franky-sim: the loopback address it serves on).
    :param realtime: ``ignore`` or ``enforce`` libfranka's realtime scheduling (``enforce``
        refuses to run without a realtime kernel: a real arm's setting).
    :param signal_timeout: [s] libfranka's torque motion ends (``TorqueSignalTimeoutException``)
        when no new torque arrived for this long: a stalled loop cannot leave a stale torque on
        the arm.
    :param state_timeout: [s] ``read`` waits at most this long for the robot's next state.
    :param connect_timeout: [s] connecting (retried while refused, e.g. franky-sim still
        starting) gives up after this long; under 10 s, so an unreachable arm stops the robot
        process quickly.
    :param lower_torque_thresholds: (7,) [Nm] libfranka's collision behaviour: above these the
        robot flags a contact (``joint_contact``).
    :param upper_torque_thresholds: (7,) [Nm] above these the robot's reflex stops the motion.
    :param lower_force_thresholds: (6,) [N, Nm] the same for the wrench at the end effector.
    :param upper_force_thresholds: (6,) [N, Nm]
    :param tool: the part the hand holds.
    """
    address: str = "127.0.0.1"
    realtime: str = "ignore"
    signal_timeout: float = 0.05
    state_timeout: float = 0.1
    connect_timeout: float = 5.0
    # libfranka's examples' setDefaultBehavior for the lower (contact) thresholds; the reflex
    # thresholds twice them, above what the task's push (20 N at most, the safety filter's
    # ceiling) and the fit's friction put on the hand.
    lower_torque_thresholds: tuple[float, ...] = (20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0)
    upper_torque_thresholds: tuple[float, ...] = (40.0, 40.0, 36.0, 36.0, 32.0, 28.0, 24.0)
    lower_force_thresholds: tuple[float, ...] = (20.0, 20.0, 20.0, 25.0, 25.0, 25.0)
    upper_force_thresholds: tuple[float, ...] = (40.0, 40.0, 40.0, 50.0, 50.0, 50.0)
    tool: HeldTool = field(default_factory=HeldTool)

    def __post_init__(self) -> None:
        if not self.address:
            raise ValueError("address must name the robot (an IP address or host name)")
        if self.realtime not in REALTIME_POLICIES:
            raise ValueError(f"realtime must be one of {REALTIME_POLICIES}, got {self.realtime!r}")
        if not 0.0 < self.signal_timeout <= 1.0:
            raise ValueError(f"signal_timeout must be in (0, 1] s, got {self.signal_timeout}")
        if not 0.0 < self.state_timeout <= 1.0:
            raise ValueError(f"state_timeout must be in (0, 1] s, got {self.state_timeout}")
        if not 0.0 < self.connect_timeout < 10.0:
            raise ValueError(f"connect_timeout must be in (0, 10) s, got {self.connect_timeout}")
        for name, n in (("lower_torque_thresholds", 7), ("upper_torque_thresholds", 7),
                        ("lower_force_thresholds", 6), ("upper_force_thresholds", 6)):
            _thresholds(name, getattr(self, name), n)
        for kind in ("torque", "force"):
            lower, upper = (getattr(self, f"{bound}_{kind}_thresholds")
                            for bound in ("lower", "upper"))
            if any(lo > up for lo, up in zip(lower, upper)):
                raise ValueError(f"lower_{kind}_thresholds must not exceed the upper ones, "
                                 f"got {lower} and {upper}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> FrankaConfig:
        """From the ``franka`` section of ``config/franka.yaml`` (``tool`` nested)."""
        values = dict(params)
        if isinstance(values.get("tool"), dict):
            values["tool"] = config_from_dict(HeldTool, values["tool"])
        return config_from_dict(cls, values)


#: The plugin's parameters, declared by the node that builds the robot.
FRANKA_SECTION = ParameterSection("franka", FrankaConfig, ranges={
    "signal_timeout": (0.001, 1.0), "state_timeout": (0.001, 1.0),
    "connect_timeout": (0.1, 9.9), "tool.mass": (0.0, 3.0)})
