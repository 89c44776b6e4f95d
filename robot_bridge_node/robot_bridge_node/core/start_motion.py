"""The way a torque arm gets from wherever it is to an episode's start: a motion, not a teleport.

A real arm cannot be put at a start pose; between episodes it has to back out of the task and
move there, as a robot's operator would teach it. The path has three legs, each tracked by the
bridge's impedance law with the stiff holding gains (``HOLD_STIFFNESS``) and a reference that
moves along it:

1. **back out**: straight back along the start's approach axis (the bore's axis) until the tool
   is level with the approach point ``start - approach``, clear of the housing;
2. **joint motion**: a minimum-jerk interpolation of the joints from there to the configuration
   that puts the tool at the approach point with the start's orientation (inverse kinematics of
   the bridge's model, from the current joints, so the posture changes least); the tool's
   reference follows the forward kinematics of the interpolated joints and the null-space
   posture the joints themselves, so the arm moves as a joint motion;
3. **approach**: straight along the approach axis into the start;

and then it **arrives**: it holds the start until the tool is there and at rest. A stiff spring
alone leaves the arm off by what its model does not know (an unknown payload sags the tool
0.3 mm at 3000 N/m, joint friction holds the wrist half a degree away); ``Arrival`` moves the
reference by the integral of the remaining error until the measured tool is at the start.

``StartMotion`` is the plan as a function of time; ``RobotLoop.reset`` ticks through it, then
through ``Arrival``, and settles holding the reference it arrived with. Speeds and tolerances
are the bridge's ``reset.*`` parameters.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from qg_common.params import config_from_dict
from qg_common.types import StartPose

from robot_bridge_node.core.arm_model import ArmModel

__all__ = ["ResetConfig", "StartMotion", "MotionSample", "Arrival"]


@dataclass(frozen=True)
class ResetConfig:
    """How the bridge resets the robot to an episode's start (the ``reset`` section of
    ``config/bridge.yaml``).

    :param teleport: a simulated robot is put at the start at once (its simulation's shortcut);
        false moves it there as a real arm is moved. A robot without a simulation always moves.
    :param linear_speed: [m/s] the tool's speed backing out and approaching along the axis.
    :param joint_speed: [rad/s] the peak joint speed of the joint motion.
    :param min_duration: [s] the joint motion takes at least this long.
    :param arrive_tolerance: [m] at the end of the path the arm holds the start until its tool
        is this close to it, ``arrive_angle`` [rad] turned from it and at rest (the rest
        detector's thresholds) ...
    :param arrive_timeout: [s] ... or gives up after this long (the reset fails).
    :param arrive_gain: [1/s] the rate at which the reference moves to cancel the remaining
        error (the integral action of the arrival).
    """
    teleport: bool = True
    linear_speed: float = 0.05
    joint_speed: float = 0.5
    min_duration: float = 0.5
    arrive_tolerance: float = 0.0002
    arrive_angle: float = 0.005
    arrive_timeout: float = 2.0
    arrive_gain: float = 3.0

    def __post_init__(self) -> None:
        for name in ("linear_speed", "joint_speed", "min_duration", "arrive_tolerance",
                     "arrive_angle", "arrive_timeout", "arrive_gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"reset.{name} must be finite and > 0, got {value}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ResetConfig:
        """From the ``reset`` section of ``config/bridge.yaml``."""
        return config_from_dict(cls, params)


@dataclass(frozen=True)
class MotionSample:
    """Where the motion should be at one instant: the tool's pose and the arm's posture."""
    position: np.ndarray
    rotation: np.ndarray
    posture: np.ndarray


def _min_jerk(s: float) -> float:
    """The minimum-jerk profile on [0, 1]: zero velocity and acceleration at both ends."""
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


class StartMotion:
    """The planned path from the arm's configuration ``q`` to ``start`` (see the module doc).

    :raises RuntimeError: if the approach point is out of the arm's reach.
    """

    def __init__(self, model: ArmModel, q: np.ndarray, start: StartPose,
                 config: ResetConfig) -> None:
        self.model = model
        q = np.asarray(q, float)
        here = model.kinematics(q)
        approach = np.asarray(start.approach, float)
        length = float(np.linalg.norm(approach))
        self.axis = approach / length if length > 0.0 else np.zeros(3)
        self.start_position = np.asarray(start.position, float)
        self.rotation = np.asarray(start.rotation, float)
        self.entry = self.start_position - approach          # the approach point
        # 1. back out along the axis to the approach point's level
        depth = float(np.dot(here.position - self.entry, self.axis))
        self.here_position = here.position
        self.out_position = here.position - max(depth, 0.0) * self.axis
        self.out_rotation = here.rotation
        self.t_out = max(depth, 0.0) / config.linear_speed
        self.q_out = q if depth <= 0.0 else model.inverse_kinematics(
            self.out_position, here.rotation, q)
        # 2. the joint motion to the approach point with the start's orientation
        self.q_entry = model.inverse_kinematics(self.entry, self.rotation, self.q_out)
        travel = float(np.max(np.abs(self.q_entry - self.q_out)))
        # minimum jerk peaks at 1.875 x the mean speed
        self.t_joint = max(config.min_duration, 1.875 * travel / config.joint_speed)
        # 3. along the axis into the start
        self.t_in = length / config.linear_speed
        self.duration = self.t_out + self.t_joint + self.t_in

    def at(self, t: float) -> MotionSample:
        """The path at ``t`` [s] after it began (held at its ends outside ``[0, duration]``)."""
        if t < self.t_out:
            s = max(t, 0.0) / self.t_out
            position = self.here_position + s * (self.out_position - self.here_position)
            return MotionSample(position, self.out_rotation, self.q_out)
        t -= self.t_out
        if t < self.t_joint:
            q = self.q_out + _min_jerk(t / self.t_joint) * (self.q_entry - self.q_out)
            kin = self.model.kinematics(q)
            return MotionSample(kin.position, kin.rotation, q)
        t -= self.t_joint
        s = min(t / self.t_in, 1.0) if self.t_in > 0.0 else 1.0
        position = self.entry + s * (self.start_position - self.entry)
        return MotionSample(position, self.rotation, self.q_entry)



class Arrival:
    """The end of a move to ``start``: the reference moved by the integral of the measured
    tool's error, until the tool is at the start and still (see the module doc).

    :param start: where the tool should be.
    :param config: tolerances, gain and time limit.
    """

    #: The error is integrated within this many tolerances of the start ...
    CATCH_UP = 10.0
    #: [m/s] ... and below this tool speed.
    CATCH_UP_SPEED = 0.01

    def __init__(self, start: StartPose, config: ResetConfig) -> None:
        self.position = np.asarray(start.position, float)
        self.rotation = np.asarray(start.rotation, float)
        self.config = config
        self._shift = np.zeros(3)        # [m] the reference's offset from the start
        self._turn = np.zeros(3)         # [rad] its rotation vector, base frame
        self.position_error = math.inf
        self.angle_error = math.inf

    def reference(self, position: np.ndarray, rotation: np.ndarray, linear_speed: float,
                  dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The reference for the next tick, given the tool's measured pose and speed now.

        The error is integrated only once the arm has caught up with the path (within
        ``CATCH_UP`` times the tolerance, moving slower than ``CATCH_UP_SPEED``): the path's own
        lag (5 mm at 0.05 m/s under the holding gains) would wind the integral up.
        """
        import pinocchio as pin
        error = self.position - position
        turn = pin.log3(self.rotation @ rotation.T)
        self.position_error = float(np.linalg.norm(error))
        self.angle_error = float(np.linalg.norm(turn))
        if (self.position_error < self.CATCH_UP * self.config.arrive_tolerance
                and linear_speed < self.CATCH_UP_SPEED):
            self._shift += self.config.arrive_gain * dt * error
            self._turn += self.config.arrive_gain * dt * turn
        return self.position + self._shift, pin.exp3(self._turn) @ self.rotation

    def arrived(self, linear_speed: float, angular_speed: float, linear_rest: float,
                angular_rest: float) -> bool:
        """At the start within the tolerances, and at rest by the rest detector's thresholds."""
        return (self.position_error < self.config.arrive_tolerance
                and self.angle_error < self.config.arrive_angle
                and linear_speed < linear_rest and angular_speed < angular_rest)
