"""The data that crosses the stack's seams: the hardware interface, the setpoint interface, the
at-rest event.

``JointState`` is what any robot's hardware interface reads; ``GroundTruth`` is what a simulated
robot can tell beyond that (evaluation and rewards only); ``StepResult`` is how one RL step
ended; ``WrenchSetpoint`` is the command the executor sends the bridge.

Wrench convention (one for setpoints, estimates and ground truth): the **contact wrench** the
environment exerts on the tool, about the tool origin, in the tool (EEF) frame, whose z axis runs
along the shaft towards its tip. A setpoint asks the controller to make the contact wrench equal
the feed-forward part, so the robot itself applies the opposite: ``Fz = -15 N`` (the environment
pushing back on the shaft) means pressing the shaft 15 N into the bore, and at rest against an
obstacle the estimated wrench equals the commanded one.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["N_START_POSES", "TOOL_FRAME", "JointState", "GroundTruth",
           "NO_GROUND_TRUTH", "StepResult", "PoseReference", "WrenchSetpoint", "StartPose"]

#: The task's initial poses, used in a fixed rotating order (SPEC 1).
N_START_POSES = 8
#: Wrenches are in the tool frame (poses and twists in the robot's base frame: its URDF's root
#: link, ``robot_frames.base_frame``).
TOOL_FRAME = "tool"


@dataclass(frozen=True)
class JointState:
    """What a hardware interface reads each millisecond (n joints)."""
    q: np.ndarray      # (n,) joint positions [rad]
    dq: np.ndarray     # (n,) joint velocities [rad/s]
    tau: np.ndarray    # (n,) measured joint torques [Nm] (torque interface: the last command)


@dataclass(frozen=True)
class GroundTruth:
    """Simulator-only truth, for evaluation only: never part of the learner's state, and never
    what a reward, a success or an episode's end is computed from (those are measured).

    ``wrench`` is the contact wrench the environment exerts on the tool (the shaft), about the
    tool frame origin and expressed in the tool frame: the quantity the wrench estimator estimates.
    """
    wrench: np.ndarray            # (6,) [Fx, Fy, Fz, Tx, Ty, Tz] [N, Nm], tool frame
    insertion_depth: float        # [m] shaft tip below the bearing face (negative above it)
    plunger_travel: float         # [m] how far the bearing inner ring has been pushed
    success: bool                 # plunger within tolerance of full travel
    position_error: float         # [m] tool position error to the fully inserted pose
    orientation_error: np.ndarray  # (2,) x/y angle-axis error to the inserted pose [rad], tool
    lateral_offset: float         # [m] tip distance from the hole axis
    tilt: float                   # [rad] angle between the shaft axis and the vertical

    @property
    def orientation_error_norm(self) -> float:
        """dR of the dense reward [rad]."""
        return float(np.linalg.norm(self.orientation_error))

    @property
    def measured(self) -> bool:
        """False for :data:`NO_GROUND_TRUTH` (every field zero: a robot without a simulation);
        a simulation's truth always has its tool somewhere off the goal or at it."""
        return bool(self.success or self.insertion_depth or self.position_error
                    or self.lateral_offset or self.tilt or np.any(self.wrench))


#: What a robot without a simulation reports as ground truth: nothing measured.
NO_GROUND_TRUTH = GroundTruth(wrench=np.zeros(6), insertion_depth=0.0, plunger_travel=0.0,
                              success=False, position_error=0.0, orientation_error=np.zeros(2),
                              lateral_offset=0.0, tilt=0.0)


@dataclass(frozen=True)
class StepResult:
    """How one setpoint ended (the RL step)."""
    duration: float                     # [s] simulated time from the setpoint to rest/timeout
    timed_out: bool                     # rest was not reached within the maximum step time
    linear_speed: float                 # [m/s] tool speed at the end
    angular_speed: float                # [rad/s]
    ground_truth: GroundTruth
    wrench_estimate: np.ndarray | None  # (6,) estimator output at the end, None without one
    fault: str = ""                     # why the robot stopped the step ("" : it did not)


@dataclass(frozen=True)
class PoseReference:
    """Impedance reference pose in the base frame."""
    position: np.ndarray   # (3,) [m]
    rotation: np.ndarray   # (3, 3)


@dataclass(frozen=True)
class StartPose:
    """Where an episode starts: the tool pose the robot moves to, and the way in.

    A real arm gets there by a motion (``RobotLoop.reset``: back out along ``approach``, a joint
    motion to the point ``|approach|`` before the start, then along ``approach`` into it); a
    simulation may put the arm there at once, as a shortcut behind the same call.

    :param position: (3,) tool position, base frame [m].
    :param rotation: (3, 3) tool orientation, base frame.
    :param approach: (3,) base frame: the start is reached moving along this direction (the bore
        axis, tip first) for its length [m]; zero: straight to the start.
    :param label: the task's number of this start (0..7 for the shaft's tilted starts; -1: none),
        for logs and bags; a simulation's start jitter stream is drawn per reset, not per label.
    """
    position: np.ndarray
    rotation: np.ndarray
    approach: np.ndarray = field(default_factory=lambda: np.zeros(3))
    label: int = -1


@dataclass(frozen=True)
class WrenchSetpoint:
    """One RL step's command: feed-forward contact wrench plus the impedance reference.

    :param wrench: (6,) ``[Fx, Fy, Fz, Tx, Ty, Tz]`` [N, Nm] in the EEF frame (see module doc).
    :param reference: pose reference; ``None`` takes the current pose when the step starts
        (the residual policy's choice).
    """
    wrench: np.ndarray
    reference: PoseReference | None = None

    @classmethod
    def residual(cls, force_z: float, torque_x: float, torque_y: float) -> WrenchSetpoint:
        """The residual-policy command ``[0, 0, Fz, tx, ty, 0]`` from the current pose."""
        return cls(np.array([0.0, 0.0, force_z, torque_x, torque_y, 0.0]))
