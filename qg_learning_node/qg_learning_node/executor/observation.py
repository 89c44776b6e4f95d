"""The robot loop's step result as the executor's :class:`Observation`.

The fast in-process runner gets a ``StepResult`` straight from ``RobotLoop.execute``; the ROS
executor gets the same numbers in an ``AtRest`` message. This converter is the in-process path,
so both paths hand the episode logic the same fields: the estimated wrench (what the policy
sees), the tool pose from the measured joints (the tilt state, and what reward, success and the
bore check are measured on) and the simulator's truth (evaluation only).
"""
from __future__ import annotations

import numpy as np
from qg_common.types import StepResult

from qg_learning_node.executor.residual_task import Observation

__all__ = ["observation_from_step"]


def observation_from_step(result: StepResult, tool_position: np.ndarray,
                          tool_rotation: np.ndarray) -> Observation:
    """Observation at the end of one RL step.

    :param tool_position: (3,) tool position from forward kinematics of the measured joints
        (the ``ee_pose`` of the ROS path's ``AtRest``).
    :param tool_rotation: (3, 3) tool orientation, the same way.

    :raises ValueError: if the loop ran without a wrench estimator (the state would be unknown).
    """
    if result.wrench_estimate is None:
        raise ValueError("the robot loop has no wrench estimator: the state needs one")
    truth = result.ground_truth
    return Observation(wrench=np.asarray(result.wrench_estimate, dtype=np.float64).copy(),
                       tool_position=np.array(tool_position, dtype=np.float64),
                       tool_rotation=np.array(tool_rotation, dtype=np.float64),
                       truth=truth if truth.measured else None)
