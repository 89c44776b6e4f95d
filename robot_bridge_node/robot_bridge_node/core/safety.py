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
from robot_bridge_node.core.native import TorqueLimiter

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
        self._last_setpoint_time: float | None = None

    @property
    def limits(self) -> SafetyLimits:
        """The task-space limits."""
        return self._limits

    @limits.setter
    def limits(self, limits: SafetyLimits) -> None:
        self._limits = limits
        # The tool's z axis (zx, zy, zz) is inside the cone, at most ``tilt_max - tilt_margin``
        # from straight down, where zx^2 + zy^2 <= tan(that)^2 zz^2 (zz < 0). A millionth less
        # than that bound is inside whatever the rounding of atan2 and hypot: the tick's quick
        # test, ~1 us less than the angle itself (``limit_tilt``).
        self._inside = math.tan(limits.tilt_max - limits.tilt_margin) ** 2 * (1.0 - 1e-6)

    @property
    def joints(self) -> JointLimits | None:
        """The arm's joint limits (``None``: none; ``limit_torques`` then refuses to run)."""
        return self._joints

    @joints.setter
    def joints(self, joints: JointLimits | None) -> None:
        self._joints = joints
        self._limiter = None if joints is None else TorqueLimiter(
            np.asarray(joints.torque, float).tolist(),
            np.asarray(joints.torque_rate, float).tolist(),
            np.asarray(joints.velocity, float).tolist(), VELOCITY_BRAKE_DAMPING)

    def reset(self, tau: np.ndarray | None = None) -> None:
        """Forget the command history; ``tau`` is the torque currently applied (rate limit).

        :raises ValueError: if ``tau`` does not have one entry per joint.
        """
        if self._limiter is not None:
            self._limiter.reset(tau)
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
        zx, zy, zz = rotation[:, 2].tolist()
        if zz < 0.0 and zx * zx + zy * zy < self._inside * (zz * zz):
            return wrench              # well inside: what the angle's comparison below says
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

        In NumPy: ``tau - VELOCITY_BRAKE_DAMPING * (dq - clip(dq, -velocity, velocity))`` when
        any joint is past its limit, then ``min(max(tau, -torque), torque)``, then
        ``min(max(tau, last - rate dt), last + rate dt)``. It runs every tick, so it runs in
        compiled code (``native.TorqueLimiter``, ~0.5 us against ~5 us on Python floats and
        ~15 us in NumPy), whose bounds are NumPy's ``maximum`` / ``minimum`` written out (a NaN
        wins): the result is NumPy's to the bit, a NaN included (``tests/robot/test_safety.py``
        compares the two on random and non-finite inputs).

        :raises RuntimeError: if the filter was built without joint limits.
        :raises ValueError: if ``tau`` or ``dq`` does not have one entry per joint.
        """
        if self._limiter is None:
            raise RuntimeError("this safety filter has no joint limits (SafetyFilter(joints=...))")
        return self._limiter.limit(tau, dt, dq)

    # --- watchdog -----------------------------------------------------------------------
    def feed_watchdog(self, now: float) -> None:
        """A setpoint arrived, or a step ended, at ``now`` [s]: the watchdog's window opens."""
        self._last_setpoint_time = now

    def watchdog_expired(self, now: float) -> bool:
        """No setpoint for longer than the timeout (never true before the first setpoint)."""
        return (self._last_setpoint_time is not None
                and now - self._last_setpoint_time > self.limits.watchdog_timeout)
