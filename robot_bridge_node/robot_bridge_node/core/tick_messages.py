"""The loop's ticks as the 1 kHz topics' messages, for the episode bag and for the live topics.

Every tick is a message on ``/joint_states`` (the measured joint torques as ``effort``),
``/joint_commands`` (the commanded ones), ``/wrench_estimate`` (when the loop has an estimate),
the robot's own estimate where it has one (``/franka/external_wrench``, base frame),
``/ee_pose`` and ``/ee_twist`` (once the controller has a tool pose, in the robot's base frame:
its URDF's root link), and the ticks
the loop computed the ground truth for are messages on ``/sim/ground_truth`` and
``/sim/ground_truth_wrench``, each stamped with its tick's stamp. A block of the sample ring's
records becomes one row of numbers per message (a few numpy operations for the whole block,
quaternions included). The bag writer's thread encodes the rows it is handed; the robot process
publishes the same rows encoded as serialized messages (``TopicRows.encode``), so the live
messages and the recorded ones are the same bytes, and no tick costs a Python message object per
topic
(`benchmarks/publish_bench.py`: 108 µs of the publishing thread per tick with message objects,
16 µs with the serialized rows).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from qg_common.rotations import quaternions_from_matrices
from qg_common.types import TOOL_FRAME
from qg_recording.cdr import FixedLayout, fixed_layout, joint_state_layout
from qg_recording.episode_recorder import TOPICS, EpisodeRecorder, ground_truth_columns

from robot_bridge_node.core.sample_ring import HAS_OWN_WRENCH, HAS_TOOL, HAS_TRUTH, HAS_WRENCH

__all__ = ["TickNames", "TopicRows", "tick_rows", "serialized_ticks", "record_ticks"]

_GROUND_TRUTH = fixed_layout("qg_interfaces/msg/GroundTruth", TOOL_FRAME)
_WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"


@dataclass(frozen=True)
class TickNames:
    """The names a robot's 1 kHz messages carry: its joints (in the order of every joint
    vector), its base frame (its URDF's root link: ``robot_frames.urdf_root_link``) and the
    topic of its own wrench estimate (``RobotPlugin.own_wrench_topic``; "" none)."""
    joint_names: tuple[str, ...]
    base_frame: str
    own_wrench_topic: str = ""


@dataclass(frozen=True)
class TopicRows:
    """The messages of one topic in a block of ticks, as rows of numbers.

    :param ticks: (n_records,) which of the block's records have a message on this topic.
    :param t_ns: (n,) the messages' stamps; :param values: (n, layout.n_values) their numbers.
    :param names: the joint names of a ``JointState`` (None for the other types).
    :param fixed_layout: the layout, where neither the topic's type and ``frame_id`` nor
        ``names`` give it (a ``tf2_msgs/TFMessage``'s: ``cdr.tf_layout``).
    """
    topic: str
    ticks: np.ndarray
    t_ns: np.ndarray
    values: np.ndarray
    frame_id: str = ""
    names: tuple[str, ...] | None = None
    fixed_layout: FixedLayout | None = None

    @property
    def layout(self) -> FixedLayout:
        if self.fixed_layout is not None:
            return self.fixed_layout
        if self.names is not None:
            return joint_state_layout(self.frame_id, self.names)
        return fixed_layout(TOPICS[self.topic].type_name, self.frame_id)

    def since(self, t_ns: int) -> TopicRows:
        """The messages stamped ``t_ns`` or later."""
        keep = self.t_ns >= t_ns
        ticks = self.ticks.copy()
        ticks[np.flatnonzero(self.ticks)[~keep]] = False
        return replace(self, ticks=ticks, t_ns=self.t_ns[keep], values=self.values[keep])

    def encode(self) -> list[bytes]:
        """The serialized messages (CDR, as rclpy publishes and subscribes them), in order."""
        layout = self.layout
        data = layout.encode_many(self.t_ns, self.values).tobytes()
        return [data[k:k + layout.size] for k in range(0, len(data), layout.size)]


def tick_rows(records: np.ndarray, names: TickNames) -> list[TopicRows]:
    """The messages of ``records`` (``sample_ring.record_dtype``), topic by topic."""
    flags = records["flags"]
    every = np.ones(len(records), dtype=bool)
    rows = [TopicRows("/joint_states", every, records["t_ns"],
                      np.hstack([records["q"], records["dq"], records["tau"]]),
                      names=names.joint_names),
            TopicRows("/joint_commands", every, records["t_ns"],
                      np.hstack([np.zeros_like(records["q"]), np.zeros_like(records["dq"]),
                                 records["tau_cmd"]]), names=names.joint_names)]
    has_wrench = (flags & HAS_WRENCH) != 0
    wrench = records[has_wrench]
    rows.append(TopicRows("/wrench_estimate", has_wrench, wrench["t_ns"], wrench["wrench"],
                          TOOL_FRAME))
    has_own = (flags & HAS_OWN_WRENCH) != 0
    if names.own_wrench_topic and has_own.any():
        own = records[has_own]
        rows.append(TopicRows(f"/{names.own_wrench_topic}", has_own, own["t_ns"],
                              own["own_wrench"], names.base_frame,
                              fixed_layout=fixed_layout(_WRENCH_STAMPED, names.base_frame)))
    has_tool = (flags & HAS_TOOL) != 0
    tool = records[has_tool]
    quaternions = quaternions_from_matrices(tool["tool_rotation"])
    rows.append(TopicRows("/ee_pose", has_tool, tool["t_ns"],
                          np.hstack([tool["tool_position"], quaternions]), names.base_frame))
    rows.append(TopicRows("/ee_twist", has_tool, tool["t_ns"], tool["tool_twist"],
                          names.base_frame))
    has_truth = (flags & HAS_TRUTH) != 0
    if has_truth.any():
        truth = records[has_truth]
        v = truth["truth"]
        values = np.zeros((len(truth), _GROUND_TRUTH.n_values))
        ground_truth_columns(_GROUND_TRUTH, values, v[:, :6], v[:, 6:7], v[:, 7:8], v[:, 8:9],
                             v[:, 9:10], v[:, 10:12], v[:, 12:13], v[:, 13:14])
        rows.append(TopicRows("/sim/ground_truth", has_truth, truth["t_ns"], values,
                              TOOL_FRAME))
        rows.append(TopicRows("/sim/ground_truth_wrench", has_truth, truth["t_ns"], v[:, :6],
                              TOOL_FRAME))
    return rows


def serialized_ticks(records: np.ndarray, names: TickNames,
                     publish: np.ndarray | None = None, extra: Sequence[TopicRows] = ()
                     ) -> list[tuple[int, list[tuple[str, bytes]]]]:
    """The serialized messages of ``records`` tick by tick, as (stamp, [(topic, CDR bytes)]),
    for every tick that has any: the 1 kHz topics of the ticks ``publish`` marks (default all)
    and the ``extra`` rows made of the same records (``/tf``)."""
    if publish is None:
        publish = np.ones(len(records), dtype=bool)
    by_tick: list[list[tuple[str, bytes]]] = [[] for _ in range(len(records))]
    published = np.flatnonzero(publish)
    for rows in tick_rows(records[publish], names):
        for tick, message in zip(published[rows.ticks].tolist(), rows.encode()):
            by_tick[tick].append((rows.topic, message))
    for rows in extra:
        for tick, message in zip(np.flatnonzero(rows.ticks).tolist(), rows.encode()):
            by_tick[tick].append((rows.topic, message))
    stamps = records["t_ns"].tolist()
    return [(stamps[k], messages) for k, messages in enumerate(by_tick) if messages]


def record_ticks(recorder: EpisodeRecorder, records: np.ndarray, names: TickNames,
                 extra: Sequence[TopicRows] = ()) -> None:
    """Record ``records`` (``sample_ring.record_dtype``) into ``recorder``'s episode, if any,
    with the ``extra`` rows made of them (the ``/tf`` of ``robot_frames``)."""
    for rows in (*tick_rows(records, names), *extra):
        recorder.record_rows(rows.topic, rows.t_ns, rows.values, rows.frame_id, rows.names,
                             rows.fixed_layout)
