"""Data the simulated robot hands out: joint state (what a driver reads) and ground truth.

They live in ``sim_robot_node`` because ``robot_bridge_node`` depends on this package and not the
reverse; the bridge reuses ``JointState`` as its view of the (simulated or real) hardware.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["JointState", "GroundTruth", "StepResult"]


@dataclass(frozen=True)
class JointState:
    """What the torque interface reports each millisecond."""
    q: np.ndarray      # (7,) joint positions [rad]
    dq: np.ndarray     # (7,) joint velocities [rad/s]
    tau: np.ndarray    # (7,) measured joint torques [Nm] (the last applied command)


@dataclass(frozen=True)
class GroundTruth:
    """Simulator-only truth, for evaluation and rewards; never part of the learner's state.

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


@dataclass(frozen=True)
class StepResult:
    """How one setpoint ended (the RL step)."""
    duration: float                     # [s] simulated time from the setpoint to rest/timeout
    timed_out: bool                     # rest was not reached within the maximum step time
    linear_speed: float                 # [m/s] tool speed at the end
    angular_speed: float                # [rad/s]
    ground_truth: GroundTruth
    wrench_estimate: np.ndarray | None  # (6,) estimator output at the end, None without one
