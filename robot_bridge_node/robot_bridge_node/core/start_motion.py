"""The way a torque arm gets from wherever it is to an episode's start: a motion, not a teleport.

A real arm cannot be put at a start pose; between episodes it has to back out of the task and
move there, as a robot's operator would teach it. First the held part comes out of its fixture
compliantly (``reset_motion.retreat``): a pull along the fixture's axis, the start's approach,
with ``withdraw_force``, growing to the safety filter's force limit while the part stays in,
under the task's hybrid controller (soft laterally and in rotation, so the fixture guides the
part) until the tool is level with the approach point ``start - approach``. A stiff withdrawal
jams: the joint law below holds the tool's orientation to a fraction of a degree, a fully
inserted part in a fit of 0.1 mm clearance allows 1 degree, and the arm locked in 1 of 4
withdrawals on the simulated Panda and on franky-sim's FR3 (not a millimetre of motion while
its targets left by 45 mm). Then the path has three legs, all tracked by a stiff joint impedance
law (``JointHold``: libfranka's joint impedance example's gains) on joint targets that move
along it:

1. **back out**: straight back along the start's approach axis until the tool is level with the
   approach point, clear of the fixture (a straight line of the tool: the joint targets are its
   inverse kinematics, each from the one before; after the withdrawal there is nothing left of
   it);
2. **joint motion**: a minimum-jerk interpolation of the joints from there to the configuration
   that puts the tool at the approach point with the start's orientation (inverse kinematics of
   the bridge's model from the current joints, so the posture changes least);
3. **approach**: straight along the approach axis into the start;

and then it **arrives**: it holds the start's joints until they are there and still. Joint
stiffness is what makes the arrival precise: the task-space holding gains (10 Nm/rad about the
tool) leave a wrist held by 0.2-1 Nm of joint friction a degree or more from where it should be,
the joint law's 50-600 Nm/rad a hundredth of that.

``StartMotion`` is the plan as a function of time; ``reset_motion.move_to_start`` ticks through
it with ``JointHold`` and the loop settles at the start. Speeds, gains and tolerances are the
bridge's ``reset.*`` parameters.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from qg_common.params import config_from_dict
from qg_common.types import StartPose

from robot_bridge_node.core.arm_model import ArmModel

__all__ = ["ResetConfig", "StartMotion", "JointHold"]


@dataclass(frozen=True)
class ResetConfig:
    """How the bridge resets the robot to an episode's start (the ``reset`` section of
    ``config/bridge.yaml``; a robot's own file may set its gains).

    :param teleport: a simulated robot is put at the start at once (its simulation's shortcut);
        false moves it there as a real arm is moved. A robot without a simulation always moves.
    :param withdraw_force: [N] the pull along the fixture's axis that takes the part out of the
        fixture, under the task's compliant controller (the task pushes with 15 N); it grows to
        ``withdraw_force_max`` over half the timeout while the part stays in.
    :param withdraw_force_max: [N] the strongest pull (the safety filter's ``force_max`` caps
        it).
    :param withdraw_timeout: [s] the part must be out (the tool level with the approach point)
        within this long, or the reset fails.
    :param linear_speed: [m/s] the tool's speed backing out and approaching along the axis.
    :param joint_speed: [rad/s] the peak joint speed of the joint motion.
    :param min_duration: [s] the joint motion takes at least this long.
    :param joint_stiffness: (n,) [Nm/rad] the joint impedance law's stiffness, one a joint
        (libfranka's joint impedance example: 600 for the four base joints, 250, 150, 50).
    :param joint_damping: (n,) [Nms/rad] its damping (the same example's 50, 50, 50, 20, 20,
        20, 10, but 4 on joint 7); a light wrist needs less: the explicit 1 kHz law's limit is
        about 2 I / dt, 13 Nms/rad for the simulated Panda's joint 7, whose hand has no motor
        inertia.
    :param arrive_tolerance: [m] at the end of the path the arm holds the start until its tool
        (forward kinematics of the measured joints) is this close to it, ``arrive_angle``
        [rad] turned from it, and every joint slower than ``arrive_speed`` [rad/s] ...
    :param arrive_timeout: [s] ... or gives up after this long (the reset fails).
    :param arrive_gain: [1/s] while holding the start, its joint targets move by this times the
        integral of the joints' error (what the model does not know: an unknown payload).
    """
    teleport: bool = True
    withdraw_force: float = 10.0
    withdraw_force_max: float = 20.0
    withdraw_timeout: float = 3.0
    linear_speed: float = 0.05
    joint_speed: float = 0.5
    min_duration: float = 0.5
    joint_stiffness: tuple[float, ...] = (600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0)
    joint_damping: tuple[float, ...] = (50.0, 50.0, 50.0, 20.0, 20.0, 20.0, 4.0)
    arrive_tolerance: float = 0.0005
    arrive_angle: float = 0.005
    arrive_speed: float = 0.005
    arrive_timeout: float = 2.0
    arrive_gain: float = 5.0

    def __post_init__(self) -> None:
        for name in ("withdraw_force", "withdraw_force_max", "withdraw_timeout", "linear_speed",
                     "joint_speed",
                     "min_duration", "arrive_tolerance",
                     "arrive_angle", "arrive_speed", "arrive_timeout", "arrive_gain"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"reset.{name} must be finite and > 0, got {value}")
        if len(self.joint_stiffness) != len(self.joint_damping):
            raise ValueError(f"reset.joint_stiffness and reset.joint_damping need one value a "
                             f"joint each, got {len(self.joint_stiffness)} and "
                             f"{len(self.joint_damping)}")
        for name in ("joint_stiffness", "joint_damping"):
            if not all(math.isfinite(v) and v > 0.0 for v in getattr(self, name)):
                raise ValueError(f"reset.{name} must be finite and > 0, got "
                                 f"{getattr(self, name)}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ResetConfig:
        """From the ``reset`` section of ``config/bridge.yaml``."""
        return config_from_dict(cls, params)


def _min_jerk(s: float) -> float:
    """The minimum-jerk profile on [0, 1]: zero velocity and acceleration at both ends."""
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


class StartMotion:
    """The planned path from the arm's configuration ``q`` to ``start`` (see the module doc),
    as joint targets in time.

    :raises RuntimeError: if the approach point or the start is out of the arm's reach.
    """

    def __init__(self, model: ArmModel, q: np.ndarray, start: StartPose,
                 config: ResetConfig) -> None:
        self.model = model
        q = np.asarray(q, float)
        here = model.kinematics(q)
        approach = np.asarray(start.approach, float)
        length = float(np.linalg.norm(approach))
        axis = approach / length if length > 0.0 else np.zeros(3)
        position = np.asarray(start.position, float)
        self.rotation = np.asarray(start.rotation, float)
        entry = position - approach                          # the approach point
        # 1. back out along the axis to the approach point's level, the tool's orientation kept
        depth = max(float(np.dot(here.position - entry, axis)), 0.0)
        self._out = (here.position, here.position - depth * axis, here.rotation)
        self.t_out = depth / config.linear_speed
        self.q_out = q if depth == 0.0 else model.inverse_kinematics(self._out[1],
                                                                     here.rotation, q)
        # 2. the joint motion to the approach point with the start's orientation
        self.q_entry = model.inverse_kinematics(entry, self.rotation, self.q_out)
        travel = float(np.max(np.abs(self.q_entry - self.q_out)))
        # minimum jerk peaks at 1.875 x the mean speed
        self.t_joint = max(config.min_duration, 1.875 * travel / config.joint_speed)
        # 3. along the axis into the start
        self._in = (entry, position, self.rotation)
        self.t_in = length / config.linear_speed
        self.q_start = model.inverse_kinematics(position, self.rotation, self.q_entry)
        self.position = position
        self.duration = self.t_out + self.t_joint + self.t_in
        self._last = q                       # the last straight-line target (warm start)

    def at(self, t: float) -> np.ndarray:
        """(n,) the joint targets at ``t`` [s] after the motion began (the start's beyond it).

        Call it with increasing ``t``: each straight-line target is solved from the one before.
        """
        if t < self.t_out:
            return self._line(self._out, t / self.t_out)
        t -= self.t_out
        if t < self.t_joint:
            self._last = self.q_entry
            return self.q_out + _min_jerk(t / self.t_joint) * (self.q_entry - self.q_out)
        t -= self.t_joint
        if t < self.t_in:
            return self._line(self._in, t / self.t_in)
        return self.q_start

    def error(self, q: np.ndarray) -> tuple[float, float]:
        """How far the tool of the joints ``q`` is from the start: [m] and [rad]."""
        import pinocchio as pin
        tool = self.model.kinematics(q)
        return (float(np.linalg.norm(tool.position - self.position)),
                float(np.linalg.norm(pin.log3(self.rotation @ tool.rotation.T))))

    def _line(self, segment: tuple[np.ndarray, np.ndarray, np.ndarray], s: float) -> np.ndarray:
        begin, end, rotation = segment
        self._last = self.model.inverse_kinematics(begin + s * (end - begin), rotation,
                                                   self._last, tolerance=1e-9)
        return self._last


class JointHold:
    """A joint impedance law with the model's gravity: ``K (q_d - q) + D (dq_d - dq) + g(q)``,
    the reset's controller (libfranka's joint impedance example's, gravity added here because the
    bridge's torques include it).

    :raises ValueError: if the gains are not one a joint of the model.
    """

    def __init__(self, model: ArmModel, config: ResetConfig) -> None:
        if len(config.joint_stiffness) != model.nv:
            raise ValueError(f"reset.joint_stiffness has {len(config.joint_stiffness)} values, "
                             f"the arm {model.nv} joints")
        self.model = model
        self.stiffness = np.asarray(config.joint_stiffness, float)
        self.damping = np.asarray(config.joint_damping, float)

    def torque(self, q: np.ndarray, dq: np.ndarray, q_target: np.ndarray,
               dq_target: np.ndarray) -> np.ndarray:
        """(n,) [Nm] the joint torques towards ``q_target`` moving at ``dq_target``."""
        return (self.stiffness * (q_target - q) + self.damping * (dq_target - dq)
                + self.model.gravity(q))
