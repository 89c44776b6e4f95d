"""Safety limits between the learner and the motors; always on.

A learning agent explores, so nothing it sends may reach the joints unchecked: setpoints with
NaN/inf are rejected (the caller logs the reason), forces and residual torques are clamped, the
tool is kept inside a tilt cone around the vertical, joint torques respect the arm's magnitude
and rate limits (its URDF's and datasheet's, ``arm_model.JointLimits``), a joint faster than its
velocity limit is braked, and in realtime mode a silent commander makes the robot hold its pose.
The task-space limits can be tightened by configuration but never loosened past the hard
ceilings below.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from qg_common.params import config_from_dict
from qg_common.rotations import tilt_from_down
from qg_common.types import WrenchSetpoint

from robot_bridge_node.core.arm_model import JointLimits

__all__ = ["SafetyLimits", "SafetyFilter", "SetpointRejected", "HARD_LIMITS",
           "VELOCITY_BRAKE_DAMPING"]

#: Ceilings no configuration may exceed (SPEC section 1 and the Franka datasheet; the
#: watchdog's: a commander silent for half a second after a step is gone, not late).
HARD_LIMITS = {"tilt_max": math.pi / 4, "force_max": 20.0, "torque_max": 3.0,
               "watchdog_timeout": 0.5}
#: [Nms/rad] Braking torque per rad/s by which a joint exceeds its velocity limit (then clipped
#: to the torque limits like any command). The task moves the joints at a few tenths of their
#: limits, so the brake never acts in it; it stops a runaway within ~0.1 s of a Panda link.
VELOCITY_BRAKE_DAMPING = 10.0


class SetpointRejected(ValueError):
    """A setpoint that must not reach the controller; the message says why."""


@dataclass(frozen=True)
class SafetyLimits:
    """Limits of the safety filter; each at most its entry in ``HARD_LIMITS``."""
    tilt_max: float = math.pi / 4        # [rad] tool z from the vertical
    tilt_margin: float = 0.05            # [rad] the restoring wall starts this far inside
    tilt_stiffness: float = 20.0         # [Nm/rad] restoring torque per rad inside the margin
    force_max: float = 20.0              # [N] norm of the feed-forward force
    torque_max: float = 3.0              # [Nm] each feed-forward torque component
    watchdog_timeout: float = 0.1        # [s] realtime: hold the pose if no step follows a
                                         # step's end within this long

    def __post_init__(self) -> None:
        for name, ceiling in HARD_LIMITS.items():
            value = getattr(self, name)
            if not 0.0 < value <= ceiling:
                raise ValueError(f"{name} must be in (0, {ceiling}], got {value}")
        if not 0.0 <= self.tilt_margin < self.tilt_max:
            raise ValueError(f"tilt_margin must be in [0, tilt_max), got {self.tilt_margin}")
        if self.tilt_stiffness <= 0.0:
            raise ValueError(f"tilt_stiffness must be > 0, got {self.tilt_stiffness}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> SafetyLimits:
        """From the ``safety`` section of ``config/bridge.yaml``."""
        return config_from_dict(cls, params)


class SafetyFilter:
    """Checks setpoints, bounds tilt and joint torques, and watches for a silent commander.

    State: the last torque command (for the rate limit) and the time of the last setpoint (for
    the watchdog); ``reset(tau)`` at every episode start.

    :param limits: the task-space limits.
    :param joints: the arm's joint limits; without them ``limit_torques`` refuses to run (a
        position robot's loop, which sends no torques, needs none).
    """

    def __init__(self, limits: SafetyLimits | None = None,
                 joints: JointLimits | None = None) -> None:
        self.limits = limits or SafetyLimits()
        self.joints = joints
        self._last_tau: list[float] | None = None
        self._last_setpoint_time: float | None = None

    @property
    def joints(self) -> JointLimits | None:
        """The arm's joint limits (``None``: none; ``limit_torques`` then refuses to run)."""
        return self._joints

    @joints.setter
    def joints(self, joints: JointLimits | None) -> None:
        self._joints = joints
        # Their entries as Python floats, read every tick (``limit_torques``).
        self._torque = [] if joints is None else np.asarray(joints.torque, float).tolist()
        self._torque_floor = [-t for t in self._torque]
        self._rate = [] if joints is None else np.asarray(joints.torque_rate, float).tolist()
        self._velocity = [] if joints is None else np.asarray(joints.velocity, float).tolist()

    def reset(self, tau: np.ndarray | None = None) -> None:
        """Forget the command history; ``tau`` is the torque currently applied (rate limit)."""
        self._last_tau = None if tau is None else np.asarray(tau, float).tolist()
        self._last_setpoint_time = None

    # --- setpoints ----------------------------------------------------------------------
    def check_setpoint(self, setpoint: WrenchSetpoint) -> WrenchSetpoint:
        """The setpoint with force and torques clamped to the limits.

        :raises SetpointRejected: on a wrong shape or a non-finite value anywhere.
        """
        wrench = np.asarray(setpoint.wrench, dtype=float)
        if wrench.shape != (6,):
            raise SetpointRejected(f"wrench must have 6 entries, got shape {wrench.shape}")
        if not np.all(np.isfinite(wrench)):
            raise SetpointRejected(f"wrench contains NaN/inf: {wrench.tolist()}")
        ref = setpoint.reference
        if ref is not None and not (np.all(np.isfinite(ref.position))
                                    and np.all(np.isfinite(ref.rotation))):
            raise SetpointRejected("pose reference contains NaN/inf")
        force = wrench[:3]
        norm = float(np.linalg.norm(force))
        if norm > self.limits.force_max:
            force = force * (self.limits.force_max / norm)
        torque = np.clip(wrench[3:], -self.limits.torque_max, self.limits.torque_max)
        return WrenchSetpoint(np.concatenate([force, torque]), ref)

    def limit_tilt(self, wrench: np.ndarray, rotation: np.ndarray) -> np.ndarray:
        """Feed-forward (EEF frame, contact convention) that keeps the tool inside the cone.

        Past ``tilt_max - tilt_margin`` the torque component tilting further is dropped and a
        restoring torque proportional to the excess is added; inside, ``wrench`` is unchanged.
        """
        angle, back = tilt_from_down(rotation)
        start = self.limits.tilt_max - self.limits.tilt_margin
        if angle <= start:
            return wrench
        # The robot applies minus the contact torque: work with what the robot applies.
        applied = -(rotation @ wrench[3:])
        outward = float(applied @ back)
        if outward < 0.0:
            applied = applied - outward * back
        applied = applied + self.limits.tilt_stiffness * (angle - start) * back
        return np.concatenate([wrench[:3], -(rotation.T @ applied)])

    # --- joint torques ------------------------------------------------------------------
    def limit_torques(self, tau: np.ndarray, dt: float,
                      dq: np.ndarray | None = None) -> np.ndarray:
        """``tau`` with a brake on every joint faster than its velocity limit (given ``dq``),
        clipped to the joint torque limits and to the rate limit since the last call.

        It runs every tick, so it works on Python floats: a handful of NumPy calls on 7
        entries cost ~15 us a tick, these loops ~3 us. Each bound is NumPy's ``maximum`` /
        ``minimum`` written out (``a if a >= b or a != a else b``: a NaN wins, as in NumPy), so
        the result is NumPy's ``min(max(tau, -limit), limit)`` to the bit, a NaN included
        (``tests/robot/test_safety.py`` compares the two on random and non-finite inputs).

        :raises RuntimeError: if the filter was built without joint limits.
        :raises ValueError: if ``tau`` or ``dq`` does not have one entry per joint.
        """
        if self._joints is None:
            raise RuntimeError("this safety filter has no joint limits (SafetyFilter(joints=...))")
        torques = self._per_joint("tau", tau)
        if dq is not None:
            torques = self._brake(torques, self._per_joint("dq", dq))
        limited = []
        for t, floor, ceiling in zip(torques, self._torque_floor, self._torque):
            t = t if t >= floor or t != t else floor
            limited.append(t if t <= ceiling or t != t else ceiling)
        last = self._last_tau
        if last is not None:
            for i, (t, before, rate) in enumerate(zip(limited, last, self._rate)):
                step = rate * dt
                floor, ceiling = before - step, before + step
                t = t if t >= floor or t != t else floor
                limited[i] = t if t <= ceiling or t != t else ceiling
        self._last_tau = limited
        return np.array(limited)

    def _per_joint(self, name: str, values: np.ndarray) -> list[float]:
        """``values`` as one float per joint."""
        array = np.asarray(values, float)
        if array.shape != (len(self._torque),):
            raise ValueError(f"{name} must have one entry per joint ({len(self._torque)}), "
                             f"got shape {array.shape}")
        return array.tolist()

    def _brake(self, torques: list[float], speeds: list[float]) -> list[float]:
        """``torques`` less ``VELOCITY_BRAKE_DAMPING`` times each joint's speed beyond its limit
        (a NaN speed makes its torque NaN); unchanged while every joint is within."""
        if all(-v <= s <= v for s, v in zip(speeds, self._velocity)):
            return torques
        braked = []
        for t, s, v in zip(torques, speeds, self._velocity):
            within = s if s >= -v or s != s else -v
            within = within if within <= v or within != within else v
            braked.append(t - VELOCITY_BRAKE_DAMPING * (s - within))
        return braked

    # --- watchdog -----------------------------------------------------------------------
    def feed_watchdog(self, now: float) -> None:
        """A setpoint arrived, or a step ended, at ``now`` [s]: the watchdog's window opens."""
        self._last_setpoint_time = now

    def watchdog_expired(self, now: float) -> bool:
        """No setpoint for longer than the timeout (never true before the first setpoint)."""
        return (self._last_setpoint_time is not None
                and now - self._last_setpoint_time > self.limits.watchdog_timeout)
