"""One rosbag2-layout bag per episode under a runs folder.

Episodes are the unit of analysis and of offline rebuilding, so each gets its own directory
`runs_dir/<episode_id>/`; the recorder is idle between episodes and its `record_*` calls are then
no-ops, so the 1 kHz loop can call them unconditionally. A high-rate message costs the loop only
copying its numbers into a row of a per-topic buffer; every `ROWS` messages the buffer goes to
the writer thread, which encodes the block with `cdr.FixedLayout.encode_many` (a few numpy
operations for hundreds of messages: see benchmarks/recording_bench.py for the cost per tick),
and every flush interval the writer thread collects the partly filled buffers too, so slow
topics (100 Hz ground truth fills a buffer in 2 s) lose no more than the chunk in progress.
RL-rate messages are encoded on the spot; rclpy messages go through `record_message`, which
imports rclpy only when called.

What a bag holds and how much the folder may take is the recording policy's
(`disk_keeper.RecordingPolicy`): an episode without 1 kHz data registers only the RL-rate
topics and its 1 kHz `record_*` calls are no-ops; one the policy refuses raises
`RecordingRefused` from `start` before anything is written.
"""

from __future__ import annotations

import atexit
import json
import re
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import cdr
from .bag_writer import BagWriter
from .disk_keeper import RL_RATE_TOPICS, DiskKeeper, RecordingPolicy, disk_bytes, free_bytes

__all__ = ["TOPICS", "EpisodeRecorder", "TopicSpec", "ground_truth_columns"]


@dataclass(frozen=True)
class TopicSpec:
    """A recorded topic's type and the QoS its publisher offers (`qg_common.topics`; a stack
    test compares them with what the live graph reports), so replay offers the same QoS."""

    type_name: str
    qos: str
    depth: int
    durability: str = "volatile"


TOPICS: dict[str, TopicSpec] = {
    "/joint_states": TopicSpec("sensor_msgs/msg/JointState", "best_effort", 1),
    "/joint_commands": TopicSpec("sensor_msgs/msg/JointState", "best_effort", 1),
    "/wrench_estimate": TopicSpec("geometry_msgs/msg/WrenchStamped", "best_effort", 1),
    "/ee_pose": TopicSpec("geometry_msgs/msg/PoseStamped", "best_effort", 1),
    "/ee_twist": TopicSpec("geometry_msgs/msg/TwistStamped", "best_effort", 1),
    "/sim/ground_truth": TopicSpec("qg_interfaces/msg/GroundTruth", "best_effort", 1),
    "/sim/ground_truth_wrench": TopicSpec("geometry_msgs/msg/WrenchStamped", "best_effort", 1),
    "/wrench_setpoint": TopicSpec("qg_interfaces/msg/WrenchSetpoint", "reliable", 10),
    "/ee_at_rest": TopicSpec("qg_interfaces/msg/AtRest", "reliable", 10),
    "/transitions": TopicSpec("qg_interfaces/msg/Transition", "reliable", 1000),
    "/episode_status": TopicSpec("qg_interfaces/msg/EpisodeStatus", "reliable", 1, "transient_local"),
    "/robot_description": TopicSpec("std_msgs/msg/String", "reliable", 1, "transient_local"),
    "/tf_static": TopicSpec("tf2_msgs/msg/TFMessage", "reliable", 1, "transient_local"),
    "/scene_markers": TopicSpec("visualization_msgs/msg/MarkerArray", "reliable", 1,
                                "transient_local"),
    "/tf": TopicSpec("tf2_msgs/msg/TFMessage", "reliable", 100),
}
_EPISODE_ID = re.compile(r"^[A-Za-z0-9_.\-]+$")
ROWS = 200  # messages of a 1 kHz topic handed to the writer thread at once (0.2 s)
Vector = cdr.Vector


def ground_truth_columns(layout: cdr.FixedLayout, values: np.ndarray, contact_wrench: Any,
                         insertion_depth: Any, plunger_travel: Any, success: Any,
                         position_error: Any, orientation_error: Any, lateral_offset: Any,
                         tilt: Any) -> None:
    """Fill `qg_interfaces/GroundTruth` numbers by field name (a renamed field fails loudly):
    one row (scalars and vectors) or many (columns and blocks), as `values` is 1-D or 2-D."""
    c = layout.slices
    values[..., c["contact_wrench"]] = contact_wrench
    values[..., c["insertion_depth"]] = insertion_depth
    values[..., c["plunger_travel"]] = plunger_travel
    values[..., c["success"]] = success
    values[..., c["position_error"]] = position_error
    values[..., c["orientation_error"]] = orientation_error
    values[..., c["lateral_offset"]] = lateral_offset
    values[..., c["tilt"]] = tilt


class _Rows:
    """Numbers of one fixed-layout topic not yet handed to the writer thread."""

    __slots__ = ("writer", "topic", "layout", "frame_id", "names", "t", "values", "n")

    def __init__(self, writer: BagWriter, topic: str, layout: cdr.FixedLayout) -> None:
        self.writer, self.topic, self.layout = writer, topic, layout
        # The objects the layout was made for: the same objects again need no layout lookup.
        self.frame_id: str | None = None
        self.names: object = None
        self._fresh()

    def _fresh(self) -> None:
        self.t = np.empty(ROWS, dtype=np.int64)
        self.values = np.zeros((ROWS, self.layout.n_values))  # fields a caller leaves out are 0
        self.n = 0

    def hand_off(self) -> None:
        """Queue the buffered messages; the arrays now belong to the writer thread."""
        if self.n:
            self.writer.write_rows(self.topic, self.layout, self.t[:self.n], self.values[:self.n])
            self._fresh()

    def next(self, t_ns: int) -> np.ndarray:
        """The value row of the next message, stamped `t_ns` (a full buffer is handed off first)."""
        i = self.n
        if i == ROWS:
            self.hand_off()
            i = 0
        self.t[i] = t_ns
        self.n = i + 1
        return self.values[i]


class EpisodeRecorder:
    """Records episodes into `runs_dir/<episode_id>/` bags.

    :param runs_dir: parent folder of the episode bags (created on first start).
    :param chunk_size, compression, flush_interval_s: passed to `BagWriter`.
    :param policy: what bags hold and the folder's budget (default: everything, no budget).
    :param free_space: bytes free on the folder's disk (`disk_keeper.free_bytes`; a test may
        simulate a full disk).
    :param log: where dropped 1 kHz data is reported.
    """

    def __init__(
        self,
        runs_dir: Path,
        chunk_size: int = 512 * 1024,
        compression: str = "zstd",
        flush_interval_s: float = 1.0,
        policy: RecordingPolicy | None = None,
        free_space: Callable[[Path], int] = free_bytes,
        log: Callable[[str], None] = lambda _: None,
    ) -> None:
        self.runs_dir = Path(runs_dir)
        self._writer_options = {"chunk_size": chunk_size, "compression": compression,
                                "flush_interval_s": flush_interval_s}
        self.keeper = DiskKeeper(self.runs_dir, policy or RecordingPolicy(), free_space, log)
        self._writer: BagWriter | None = None
        self._pending: dict[str, _Rows] = {}
        # start/stop may come from another thread (a service callback) than the 1 kHz calls.
        self._lock = threading.Lock()
        self.episode_id = ""
        self._high_rate = True          # this episode records its 1 kHz topics
        self._planned_high_rate = True  # ... began to
        self._high_rate_limit: int | None = None  # [bytes] ... while its bag stays below this
        #: [bytes] on disk of the last bag closed (as written, before any 1 kHz data dropped).
        self.last_bytes = 0
        self.last_high_rate = False     # whether it was recorded with (some of) its 1 kHz topics

    @property
    def active(self) -> bool:
        return self._writer is not None

    @property
    def unwritten_bytes(self) -> int:
        """Uncompressed bytes of the open bag not in its file yet (queued, in the open chunk)."""
        writer = self._writer
        return 0 if writer is None else writer.unwritten_bytes

    def start(self, episode_id: str, metadata: Mapping[str, Any] | None = None) -> Path:
        """Open `runs_dir/<episode_id>/`, ending the episode being recorded if any.

        :param metadata: episode facts (mode, seed, ...) kept in metadata.yaml `custom_data`;
            non-string values are stored as JSON.
        :raises ValueError: for an episode id that is not a plain directory name.
        :raises FileExistsError: if that episode was recorded already.
        :raises RecordingRefused: if the policy refuses the episode (disk nearly full, budget
            full of RL-rate data); nothing of it is written.
        """
        if not _EPISODE_ID.match(episode_id):
            raise ValueError(f"episode id must be a plain directory name, got {episode_id!r}")
        self.stop()
        if (self.runs_dir / episode_id).exists():
            raise FileExistsError(f"{self.runs_dir / episode_id} already holds a bag")
        high_rate, limit = self.keeper.plan(episode_id)
        custom = {"episode_id": episode_id}
        for key, value in (metadata or {}).items():
            custom[str(key)] = value if isinstance(value, str) else json.dumps(value)
        if not (high_rate and self.keeper.policy.mode == "all"):   # today's bags stay as they were
            custom["recording"] = self.keeper.policy.mode if high_rate else "rl_rate"
        writer = BagWriter(self.runs_dir / episode_id, custom_data=custom, collect=self._hand_off_rows,
                           **self._writer_options)
        for topic, spec in TOPICS.items():  # all up front: no registration check per message
            if high_rate or topic in RL_RATE_TOPICS:
                writer.add_topic(topic, spec.type_name, spec.qos, spec.depth, spec.durability)
        with self._lock:
            self._writer, self.episode_id = writer, episode_id
            self._high_rate, self._high_rate_limit = high_rate, limit
            self._planned_high_rate = high_rate
        atexit.register(self.stop)  # Ctrl-C: hand the buffered rows over before the bag closes
        return writer.directory

    def _hand_off_rows(self) -> None:
        """Queue every buffered row (the writer thread calls this every flush interval, so rows
        reach the disk with the chunk of their time: a SIGKILL loses at most that chunk)."""
        with self._lock:
            if self._writer is not None:
                self._check_limit()
            for rows in self._pending.values():
                rows.hand_off()

    def _check_limit(self) -> None:
        """Stop this episode's 1 kHz topics once its bag reaches the size the budget leaves it
        (lock held, recorder active); their buffered rows are dropped."""
        limit = self._high_rate_limit
        if limit is None or not self._high_rate:
            return
        # on disk, queued, in the open chunk, and still in the row buffers: uncompressed
        buffered = sum(rows.n * (rows.layout.size + 47) for rows in self._pending.values())
        size = disk_bytes(self._writer.directory) + self._writer.unwritten_bytes + buffered
        if size >= limit:
            self._high_rate = False
            self._pending.clear()
            self._writer.set_custom("high_rate_cut", f"at {size} bytes: recording.budget_mb")

    def stop(self) -> Path | None:
        """Close the current bag (drains every queued message); returns its directory.

        Record calls of other threads never wait for the draining: they see an idle recorder.
        """
        with self._lock:
            writer, self._writer = self._writer, None
            if writer is None:
                return None
            for rows in self._pending.values():
                rows.hand_off()
            self._pending.clear()
            high_rate = self._planned_high_rate
        atexit.unregister(self.stop)
        writer.close()
        self.last_high_rate = high_rate
        self.last_bytes = self.keeper.closed(writer.directory, high_rate)
        return writer.directory

    def _ensure_topic(self, topic: str, type_name: str | None) -> BagWriter:
        """The writer (lock held, recorder active), with `topic` added if it is new."""
        if not self._writer.has_topic(topic):
            if type_name is None:
                raise ValueError(f"unknown topic {topic}: pass its type name")
            self._writer.add_topic(topic, type_name)
        return self._writer

    # -- 1 kHz messages: numbers buffered per topic, encoded in blocks by the writer thread ------
    # `topic` must be one of TOPICS (see record_fixed for others).

    def _rows_for(self, topic: str, layout: cdr.FixedLayout, frame_id: str, names: object = None) -> _Rows:
        """The buffer of `topic` for messages of `layout` (handing off one of another layout)."""
        recorded_as = self._writer.topic_type(topic)
        if recorded_as != layout.type_name:
            raise ValueError(f"{topic} is recorded as {recorded_as}, not {layout.type_name} (see TOPICS)")
        rows = self._pending.get(topic)
        if rows is None or rows.layout is not layout:
            if rows is not None:
                rows.hand_off()
            rows = self._pending[topic] = _Rows(self._writer, topic, layout)
        rows.frame_id, rows.names = frame_id, names
        return rows

    def _stamped_row(self, topic: str, type_name: str, frame_id: str, t_ns: int) -> np.ndarray:
        """The value row of the next `type_name` message on `topic` (lock held, recorder active)."""
        rows = self._pending.get(topic)
        if rows is None or rows.frame_id is not frame_id:
            rows = self._rows_for(topic, cdr.fixed_layout(type_name, frame_id), frame_id)
        return rows.next(t_ns)

    def record_joint_state(
        self, t_ns: int, names: Sequence[str], position: Vector, velocity: Vector, effort: Vector,
        frame_id: str = "", topic: str = "/joint_states",
    ) -> None:
        """A JointState; position, velocity and effort need len(names) values each."""
        with self._lock:
            if self._writer is None or not self._high_rate:
                return
            rows = self._pending.get(topic)
            if rows is None or rows.names is not names or rows.frame_id is not frame_id:
                rows = self._rows_for(topic, cdr.joint_state_layout(frame_id, tuple(names)), frame_id, names)
            n = len(names)
            v = rows.next(t_ns)
            v[:n] = position
            v[n:2 * n] = velocity
            v[2 * n:] = effort

    def record_wrench(
        self, t_ns: int, force: Vector, torque: Vector, frame_id: str = "tool", topic: str = "/wrench_estimate",
    ) -> None:
        with self._lock:
            if self._writer is not None and self._high_rate:
                v = self._stamped_row(topic, "geometry_msgs/msg/WrenchStamped", frame_id, t_ns)
                v[:3] = force
                v[3:] = torque

    def record_pose(
        self, t_ns: int, position: Vector, quaternion_xyzw: Vector, frame_id: str = "base",
        topic: str = "/ee_pose",
    ) -> None:
        with self._lock:
            if self._writer is not None and self._high_rate:
                v = self._stamped_row(topic, "geometry_msgs/msg/PoseStamped", frame_id, t_ns)
                v[:3] = position
                v[3:] = quaternion_xyzw

    def record_twist(
        self, t_ns: int, linear: Vector, angular: Vector, frame_id: str = "base", topic: str = "/ee_twist",
    ) -> None:
        with self._lock:
            if self._writer is not None and self._high_rate:
                v = self._stamped_row(topic, "geometry_msgs/msg/TwistStamped", frame_id, t_ns)
                v[:3] = linear
                v[3:] = angular

    def record_ground_truth(
        self, t_ns: int, contact_wrench: Vector, insertion_depth: float, plunger_travel: float,
        success: bool, position_error: float, orientation_error: Vector, lateral_offset: float,
        tilt: float, frame_id: str = "tool", topic: str = "/sim/ground_truth",
    ) -> None:
        """qg_interfaces/GroundTruth, filled by field name (a renamed field fails loudly)."""
        with self._lock:
            if self._writer is not None and self._high_rate:
                v = self._stamped_row(topic, "qg_interfaces/msg/GroundTruth", frame_id, t_ns)
                ground_truth_columns(self._pending[topic].layout, v, contact_wrench,
                                     insertion_depth, plunger_travel, success, position_error,
                                     orientation_error, lateral_offset, tilt)

    def record_fixed(self, topic: str, t_ns: int, values: Vector, frame_id: str = "",
                     type_name: str | None = None) -> None:
        """Any fixed-size message with a leading header, from its numbers in definition order
        (`cdr.fixed_layout(type_name).columns` names them).

        :param type_name: needed for topics not in `TOPICS`.
        """
        with self._lock:
            if self._writer is not None and (self._high_rate or topic in RL_RATE_TOPICS):
                writer = self._ensure_topic(topic, type_name)
                self._stamped_row(topic, writer.topic_type(topic), frame_id, t_ns)[:] = values

    def record_rows(self, topic: str, t_ns: np.ndarray, values: np.ndarray, frame_id: str = "",
                    names: Sequence[str] | None = None,
                    layout: cdr.FixedLayout | None = None) -> None:
        """Many messages of a fixed-layout topic at once, one row of numbers each (as
        `record_fixed` takes them; a JointState's rows are position, velocity, effort of
        `names`): the loop's ticks as its sample ring hands them over, encoded by the writer
        thread in one block.

        :param t_ns: (n,) stamps; :param values: (n, layout.n_values).
        :param layout: the messages' layout where the type, `frame_id` and `names` do not give
            it (`cdr.tf_layout`).
        """
        with self._lock:
            if self._writer is None or len(t_ns) == 0:
                return
            self._check_limit()
            if not (self._high_rate or topic in RL_RATE_TOPICS):
                return
            writer = self._ensure_topic(topic, None if layout is None else layout.type_name)
            type_name = writer.topic_type(topic)
            if layout is None:
                layout = (cdr.joint_state_layout(frame_id, tuple(names)) if names is not None
                          else cdr.fixed_layout(type_name, frame_id))
            elif layout.type_name != type_name:
                raise ValueError(f"{topic} is recorded as {type_name}, not {layout.type_name}")
            rows = self._pending.pop(topic, None)
            if rows is not None:             # single messages of this topic go first
                rows.hand_off()
            writer.write_rows(topic, layout, np.array(t_ns, dtype=np.int64),
                              np.array(values, dtype=float).reshape(len(t_ns), layout.n_values))

    # -- RL-rate messages ----------------------------------------------------------------------

    def record_transition(
        self, t_ns: int, step: int, state: Vector, action: Vector, reward: float, next_state: Vector,
        terminal: bool, timeout: bool = False, zero_action: bool = False, topic: str = "/transitions",
    ) -> None:
        """A transition of the current episode (episode id filled in)."""
        with self._lock:
            if self._writer is not None:
                self._writer.write(topic, cdr.encode_transition(
                    self.episode_id, step, state, action, reward, next_state, terminal, timeout, zero_action), t_ns)

    def record_raw(self, topic: str, t_ns: int, data: bytes, type_name: str | None = None) -> None:
        """An already serialized CDR message (e.g. from a raw subscription).

        :param type_name: needed for topics not in `TOPICS` (recorded as reliable, depth 10).
        """
        with self._lock:
            if self._writer is not None and (self._high_rate or topic in RL_RATE_TOPICS):
                self._ensure_topic(topic, type_name).write(topic, data, t_ns)

    def record_message(self, topic: str, t_ns: int, msg: Any, type_name: str | None = None) -> None:
        """An rclpy message, serialized with rclpy (imported here: the module stays ROS-free)."""
        if self._writer is None:
            return
        from rclpy.serialization import serialize_message

        if type_name is None and topic not in TOPICS:
            module, name = type(msg).__module__.split(".")[0], type(msg).__name__
            type_name = f"{module}/msg/{name}"
        self.record_raw(topic, t_ns, serialize_message(msg), type_name)
