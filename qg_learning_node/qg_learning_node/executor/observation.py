"""The robot loop's step result as the executor's :class:`Observation`.

The fast in-process runner gets a ``StepResult`` straight from ``RobotLoop.execute``; the ROS
executor gets the same numbers in an ``AtRest`` message. This converter is the in-process path,
so both paths hand the episode logic the same five fields: the estimated wrench (what the policy
sees) and the simulator's truth (only for rewards, success and the bore check).
"""
from __future__ import annotations

import numpy as np
from qg_common.types import StepResult

from qg_learning_node.executor.residual_task import Observation

__all__ = ["observation_from_step"]


def observation_from_step(result: StepResult, tool_rotation: np.ndarray | None = None,
                          tool_position: np.ndarray | None = None) -> Observation:
    """Observation at the end of one RL step.

    :param tool_rotation: (3, 3) tool orientation from forward kinematics of the measured joints
        (the ``ee_pose`` of the ROS path's ``AtRest``), for the ``tilt`` observation.
    :param tool_position: (3,) tool position, the same way (the peg task's state).

    :raises ValueError: if the loop ran without a wrench estimator (the state would be unknown).
    """
    if result.wrench_estimate is None:
        raise ValueError("the robot loop has no wrench estimator: the state needs one")
    truth = result.ground_truth
    return Observation(wrench=np.asarray(result.wrench_estimate, dtype=np.float64).copy(),
                       success=bool(truth.success), position_error=float(truth.position_error),
                       orientation_error=truth.orientation_error_norm,
                       lateral_offset=float(truth.lateral_offset),
                       tool_rotation=None if tool_rotation is None
                       else np.array(tool_rotation, dtype=np.float64),
                       tool_position=None if tool_position is None
                       else np.array(tool_position, dtype=np.float64))
