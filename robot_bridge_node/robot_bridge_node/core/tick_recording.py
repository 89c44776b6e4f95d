"""The loop's ticks into an episode bag: the sample ring's records as the 1 kHz topics' rows.

Every tick is recorded on ``/joint_states``, ``/wrench_estimate`` (when the loop has an
estimate), ``/ee_pose`` and ``/ee_twist`` (once the controller has a tool pose), and the ticks
the loop computed the ground truth for on ``/sim/ground_truth`` and
``/sim/ground_truth_wrench``, each stamped with its tick's stamp: the messages the robot process
publishes of a tick are these, byte for byte. A block of records costs a few numpy operations
and one quaternion per tick; the writer thread encodes the rows.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from qg_common.rotations import quaternion_from_matrix
from qg_common.types import BASE_FRAME, TOOL_FRAME
from qg_recording.cdr import fixed_layout
from qg_recording.episode_recorder import EpisodeRecorder, ground_truth_columns

from robot_bridge_node.core.sample_ring import HAS_TOOL, HAS_TRUTH, HAS_WRENCH

__all__ = ["record_ticks"]

_GROUND_TRUTH = fixed_layout("qg_interfaces/msg/GroundTruth", TOOL_FRAME)


def record_ticks(recorder: EpisodeRecorder, records: np.ndarray,
                 joint_names: Sequence[str]) -> None:
    """Record ``records`` (``sample_ring.record_dtype``) into ``recorder``'s episode, if any."""
    t = records["t_ns"]
    recorder.record_rows("/joint_states", t, np.hstack([records["q"], records["dq"],
                                                        records["tau"]]), names=joint_names)
    flags = records["flags"]
    wrench = records[(flags & HAS_WRENCH) != 0]
    recorder.record_rows("/wrench_estimate", wrench["t_ns"], wrench["wrench"], TOOL_FRAME)
    tool = records[(flags & HAS_TOOL) != 0]
    quaternions = np.reshape([quaternion_from_matrix(r) for r in tool["tool_rotation"]], (-1, 4))
    recorder.record_rows("/ee_pose", tool["t_ns"], np.hstack([tool["tool_position"], quaternions]),
                         BASE_FRAME)
    recorder.record_rows("/ee_twist", tool["t_ns"], tool["tool_twist"], BASE_FRAME)
    truth = records[(flags & HAS_TRUTH) != 0]
    if len(truth):
        v = truth["truth"]
        values = np.zeros((len(truth), _GROUND_TRUTH.n_values))
        ground_truth_columns(_GROUND_TRUTH, values, v[:, :6], v[:, 6:7], v[:, 7:8], v[:, 8:9],
                             v[:, 9:10], v[:, 10:12], v[:, 12:13], v[:, 13:14])
        recorder.record_rows("/sim/ground_truth", truth["t_ns"], values, TOOL_FRAME)
        recorder.record_rows("/sim/ground_truth_wrench", truth["t_ns"], v[:, :6], TOOL_FRAME)
