"""Messages <-> the executor/learner cores' plain types (message types stay at the edge)."""
from __future__ import annotations

import numpy as np
from qg_common.conversions import ground_truth_from_msg
from qg_common.rotations import matrix_from_quaternion
from qg_interfaces.msg import ActorParameters, AtRest, Transition

from qg_learning_node.executor.episode import TransitionRecord
from qg_learning_node.executor.residual_task import Observation

__all__ = ["observation_from_msg", "transition_to_msg",
           "actor_to_msg", "actor_tensors_from_msg"]


def observation_from_msg(msg: AtRest) -> Observation:
    """What the robot measured at rest: the wrench estimate and the tool pose of its joints; the
    ground truth rides along for evaluation (all zeros from a real arm: then ``None``)."""
    w, q, p = msg.wrench_estimate, msg.ee_pose.orientation, msg.ee_pose.position
    truth = ground_truth_from_msg(msg.ground_truth)
    return Observation(
        wrench=np.array([w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]),
        tool_position=np.array([p.x, p.y, p.z]),
        tool_rotation=matrix_from_quaternion(q.x, q.y, q.z, q.w),
        truth=truth if truth.measured else None)


def transition_to_msg(t: TransitionRecord) -> Transition:
    return Transition(episode_id=t.episode_id, step=t.step, state=t.state.tolist(),
                      action=t.action.tolist(), reward=t.reward, next_state=t.next_state.tolist(),
                      terminal=t.terminal, timeout=t.timeout, zero_action=t.zero_action)


def actor_to_msg(version: int, tensors: list[tuple[str, np.ndarray]]) -> ActorParameters:
    msg = ActorParameters(version=version)
    msg.tensor_names = [name for name, _ in tensors]
    msg.tensor_ndims = [t.ndim for _, t in tensors]
    msg.tensor_shapes = [int(d) for _, t in tensors for d in t.shape]
    msg.weights = np.concatenate([t.astype(np.float32).ravel() for _, t in tensors]).tolist()
    return msg


def actor_tensors_from_msg(msg: ActorParameters) -> list[tuple[str, np.ndarray]]:
    """The inverse of :func:`actor_to_msg`.

    :raises ValueError: if the shapes do not add up to the weights.
    """
    weights = np.asarray(msg.weights, dtype=np.float32)
    shapes = list(msg.tensor_shapes)
    tensors, offset, dim_i = [], 0, 0
    for name, ndim in zip(msg.tensor_names, msg.tensor_ndims):
        shape = tuple(int(d) for d in shapes[dim_i:dim_i + ndim])
        dim_i += ndim
        size = int(np.prod(shape))
        if offset + size > weights.size:
            raise ValueError(f"actor message too short for tensor {name} {shape}")
        tensors.append((name, weights[offset:offset + size].reshape(shape)))
        offset += size
    if offset != weights.size or dim_i != len(shapes):
        raise ValueError("actor message: shapes and weights do not match")
    return tensors
