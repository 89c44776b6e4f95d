"""The ``recorder`` node: one MCAP bag (rosbag2 layout) per episode, written in the robot process.

The 1 kHz data (joint states, wrench estimate, EEF pose/twist, ground truth) is every tick of the
loop as its loop process wrote it into the sample ring (``record_samples``, on the thread that
reads the ring, in blocks: the loop spends no time on it and no sample is dropped); each is
stamped with its tick's stamp, the one the live messages of that tick carry. The ground truth
is recorded as often as the loop computes it (``sim.ground_truth_rate``). The RL-rate
topics (setpoints, at-rest events, transitions, episode status) arrive by subscription and are
logged at their arrival on the same clock, the loop's (``LoopLink.now_ns``: simulated time in
lockstep, the wall clock in realtime), as rosbag2 logs receive times: one time base per bag, and
a bag starts with its first message. Episode boundaries come from ``/episode_status``: a bag
opens when an episode starts resetting and closes once the episode has ended and all of its
transitions and ticks have arrived (the ticks come in blocks, behind the RL-rate messages: a
CI run under load closed a bag before the last step's ticks, and its bag had no tick at all).

What the bags hold and how much their folder may take is ``recording.*``
(``qg_recording.disk_keeper``): an episode the policy refuses (disk nearly full, budget full of
RL-rate data) gets no bag, and the robot's reset, which waits for the bag, fails with the
reason, so the executor ends the episode ``aborted`` before its first step.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from qg_common import topics
from qg_common.node_parameters import declare_parameters, on_parameter_change
from qg_common.params import ParameterSection, config_from_dict, runs_dir
from qg_interfaces.msg import AtRest, EpisodeStatus, Transition, WrenchSetpoint
from qg_recording.disk_keeper import MB, RecordingPolicy, RecordingRefused
from qg_recording.episode_recorder import EpisodeRecorder
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message

from robot_bridge_node.core.tick_messages import TickNames, TopicRows, record_ticks

__all__ = ["RecorderConfig", "RECORDER_SECTION", "RecorderNode"]

_FINAL = ("done", "aborted")
#: [s] the most a new episode's first status waits for the ticks of the episode before it.
_TICKS_WAIT = 0.5
#: [s] a bag stays open at least this long after its episode ended (see ``_close_if_complete``).
_SETTLE = 0.1
#: ``/episode_status`` as its publisher offers it (transient local: a late recorder still gets
#: the episode's state), but deep: the executor may publish several statuses back to back (the
#: last step's ``running`` and ``done``), and a depth of 1 would keep only the last of them.
_STATUS_QOS = QoSProfile(depth=100, reliability=topics.LATCHED.reliability,
                         durability=topics.LATCHED.durability)


@dataclass(frozen=True)
class RecorderConfig:
    """The recorder's parameters (``config/recorder.yaml``).

    :param record: record episodes at all (changeable while running: from the next episode).
    :param episodes_dir: folder of the episode bags; "" = ``$QG_RUNS_DIR/episodes``, else
        ``runs/episodes`` in the current directory.
    :param close_timeout: [s] wait this long for late transitions after the episode ended.
    :param recording: what the bags hold and the folder's disk budget (``RecordingPolicy``).
    """
    record: bool = True
    episodes_dir: str = ""
    close_timeout: float = 2.0
    recording: RecordingPolicy = field(default_factory=RecordingPolicy)

    def __post_init__(self) -> None:
        if not self.close_timeout >= 0.0:
            raise ValueError(f"close_timeout must be >= 0 s, got {self.close_timeout}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> RecorderConfig:
        return config_from_dict(cls, params)


RECORDER_SECTION = ParameterSection(
    "", RecorderConfig, ranges={
        "close_timeout": (0.0, 600.0), "recording.every_k": (1, 1_000_000),
        "recording.keep_last": (0, 1_000_000), "recording.budget_mb": (0.0, 1e9),
        "recording.min_free_mb": (0.0, 1e9)},
    runtime=frozenset({"record", "close_timeout"}))


class RecorderNode(Node):
    """Per-episode recording; ``record_samples`` takes the loop's ticks.

    Parameters: ``RecorderConfig``; ``record`` and ``close_timeout`` may be changed while it
    runs (``ros2 param set``).
    """

    def __init__(self) -> None:
        super().__init__("recorder")
        self.config = RecorderConfig.from_dict(declare_parameters(
            self, [RECORDER_SECTION], (("robot_bridge_node", "recorder.yaml"),)))
        on_parameter_change(self, self._reconfigure)
        self.recorder = EpisodeRecorder(Path(self.config.episodes_dir or runs_dir() / "episodes"),
                                        policy=self.config.recording,
                                        log=self.get_logger().info)
        self.lock = threading.Lock()
        self._opened = threading.Condition(self.lock)    # a bag opened
        self.episode_id = ""
        self.refused_id, self.refused_reason = "", ""   # the episode refused last, and why
        self.opened_ns = 0                  # the loop's clock when the open bag began
        self.transitions = 0
        self.final_steps: int | None = None
        self.ended_at = 0.0
        self.ended_ns = 0                   # the loop's clock when the episode ended
        self.recorded_ns = 0                # the newest tick the recorder has been handed
        self._ticks_in = threading.Condition()  # ... which the reader thread announces
        self._latched: dict[str, bytes] = {}     # latched topic -> its latest message
        group = MutuallyExclusiveCallbackGroup()
        self._subscribe(EpisodeStatus, topics.EPISODE_STATUS, self._on_status, _STATUS_QOS, group)
        self._subscribe(Transition, topics.TRANSITIONS, self._on_transition, topics.RELIABLE_DEEP, group)
        self._subscribe(WrenchSetpoint, topics.WRENCH_SETPOINT, self._on_setpoint, topics.COMMAND_QOS, group)
        self._subscribe(AtRest, topics.EE_AT_REST, self._on_at_rest, topics.COMMAND_QOS, group)
        # Runs only while an ended episode's bag waits to close: a 20 Hz timer in every idle
        # robot process was half of its idle CPU.
        self._closer = self.create_timer(0.05, self._close_if_complete, callback_group=group)
        self._closer.cancel()
        #: The clock RL-rate messages are logged on; the robot process sets the loop's.
        self.clock_ns: Callable[[], int] = lambda: self.get_clock().now().nanoseconds
        self.last_setpoint_seq = -1

    def _reconfigure(self, params: dict[str, Any]) -> None:
        """``ros2 param set``: the new values (validated) apply from now on."""
        self.config = RecorderConfig.from_dict(params)

    # --- the 1 kHz data ---------------------------------------------------------------------
    def record_samples(self, records: np.ndarray, names: TickNames,
                       extra: Sequence[TopicRows] = ()) -> None:
        """Record the loop's ticks (``sample_ring`` records; nothing between episodes) and the
        ``extra`` rows made of them (``/tf``)."""
        if not len(records):
            return
        if self.episode_id:
            # The ticks come in blocks, up to a few ms after their stamps: those stamped before
            # the bag opened (its first message) belong to no episode.
            opened = self.opened_ns
            taken = records[records["t_ns"] >= opened]
            if len(taken):
                record_ticks(self.recorder, taken, names, [rows.since(opened) for rows in extra])
        with self._ticks_in:               # announced once in the bag, not before
            self.recorded_ns = int(records["t_ns"][-1])
            self._ticks_in.notify_all()

    # --- latched topics ---------------------------------------------------------------------
    def latch(self, topic: str, data: bytes) -> None:
        """A serialized message of a latched topic (``/robot_description``, ``/tf_static``,
        ``/scene_markers``): every bag starts with the latest one of each, as a late subscriber
        of a transient-local topic gets it, and an open bag records a new one at once."""
        with self.lock:
            self._latched[topic] = data
            if self.episode_id:
                self.recorder.record_raw(topic, self.clock_ns(), data)

    def wait_for_episode(self, episode_id: str, timeout: float) -> bool:
        """Wait until the bag of ``episode_id`` is open; False after ``timeout`` s.

        The robot process calls it before a reset, whose settled start is the bag's first
        tick. The executor publishes the episode's ``resetting`` status before it asks for the
        reset, but the two arrive on different threads, and under load the status came after
        the settled tick, which no bag then took. Without recording, an episode id or an
        executor (nothing publishes ``/episode_status``) there is nothing to wait for.

        :raises RuntimeError: with the reason, if the recording policy refused the episode.
        """
        if not (self.config.record and episode_id
                and self.count_publishers(topics.EPISODE_STATUS)):
            return True
        with self._opened:
            opened = self._opened.wait_for(
                lambda: episode_id in (self.episode_id, self.refused_id), timeout)
            if opened and self.refused_id == episode_id:
                raise RuntimeError(self.refused_reason)
            return opened

    # --- RL-rate topics -------------------------------------------------------------------
    def _subscribe(self, msg_type: type, topic: str, handler: Callable[[int, bytes, Any], None],
                   qos: Any, group: MutuallyExclusiveCallbackGroup) -> None:
        """Subscribe serialized, as rosbag2 does: the bag gets the bytes as published (padding
        included), ``handler`` the arrival time on the loop's clock, the bytes and the message."""
        def on_message(data: bytes) -> None:
            t_ns = self.clock_ns()  # one time base per bag: the loop's
            handler(t_ns, data, deserialize_message(data, msg_type))
        self.create_subscription(msg_type, topic, on_message, qos, callback_group=group, raw=True)

    def _on_status(self, t_ns: int, data: bytes, msg: EpisodeStatus) -> None:
        if not self.config.record or not msg.episode_id or msg.episode_id == self.refused_id:
            return
        if msg.episode_id != self.episode_id and msg.state not in _FINAL:
            if self.final_steps is not None:     # the last episode ended: its ticks first
                with self._ticks_in:
                    self._ticks_in.wait_for(self._all_ticks_in, _TICKS_WAIT)
            self._close()
            with self.lock:
                try:
                    self.recorder.start(msg.episode_id, {"mode": msg.mode,
                                                         "initial_pose": int(msg.initial_pose),
                                                         "reward": msg.reward_type})
                except RecordingRefused as exc:
                    self.get_logger().error(str(exc))
                    self.refused_id, self.refused_reason = msg.episode_id, str(exc)
                    self._opened.notify_all()
                    return
                self.opened_ns = t_ns
                self.episode_id, self.transitions, self.final_steps = msg.episode_id, 0, None
                for topic, latched in self._latched.items():
                    self.recorder.record_raw(topic, t_ns, latched)
                self._opened.notify_all()
        if msg.episode_id == self.episode_id:
            self.recorder.record_raw("/episode_status", t_ns, data)
            if msg.state in _FINAL and self.final_steps is None:
                self.final_steps, self.ended_at = int(msg.step), time.monotonic()
                self.ended_ns = t_ns
                self._closer.reset()

    def _on_transition(self, t_ns: int, data: bytes, msg: Transition) -> None:
        if msg.episode_id == self.episode_id:
            self.recorder.record_raw("/transitions", t_ns, data)
            self.transitions += 1

    def _on_setpoint(self, t_ns: int, data: bytes, msg: WrenchSetpoint) -> None:
        # The executor re-sends the running setpoint every few ms as a watchdog keep-alive;
        # the bag keeps the first message of each seq, the command itself.
        if self.episode_id and msg.seq != self.last_setpoint_seq:
            self.last_setpoint_seq = msg.seq
            self.recorder.record_raw("/wrench_setpoint", t_ns, data)

    def _on_at_rest(self, t_ns: int, data: bytes, msg: AtRest) -> None:
        if self.episode_id:
            self.recorder.record_raw("/ee_at_rest", t_ns, data)

    def _close_if_complete(self) -> None:
        """Close the bag once the episode has ended and all its transitions and ticks are in.

        Called by the timer only, never from a message callback: messages published just
        before the final status (the last ``/ee_at_rest``) may sit in the same batch of ready
        callbacks as that status, behind it. Waiting at least one timer period after the end
        lets every message that was already on its way be recorded first.
        """
        if self.final_steps is None:
            return
        waited = time.monotonic() - self.ended_at
        if waited < _SETTLE:
            return
        late = waited > self.config.close_timeout
        ticks_in = self._all_ticks_in()
        if (self.transitions >= self.final_steps and ticks_in) or late:
            if late and self.transitions < self.final_steps:
                self.get_logger().warning(
                    f"closing bag of {self.episode_id} with {self.transitions} of "
                    f"{self.final_steps} transitions")
            if late and not ticks_in:
                self.get_logger().warning(
                    f"closing bag of {self.episode_id} without the ticks after "
                    f"{self.recorded_ns} ns (it ended at {self.ended_ns} ns)")
            self._close()

    def _all_ticks_in(self) -> bool:
        """Whether the ticks up to the ended episode's last have been recorded."""
        return self.recorded_ns >= self.ended_ns

    def _close(self) -> None:
        with self.lock:
            if self.episode_id:
                path = self.recorder.stop()
                rec = self.recorder
                self.get_logger().info(
                    f"recorded {self.episode_id} -> {path}: {rec.last_bytes} bytes "
                    f"({rec.last_bytes / MB:.2f} MiB, "
                    f"{'with' if rec.last_high_rate else 'without'} its 1 kHz topics)")
            self.episode_id, self.final_steps = "", None
            self._closer.cancel()

    def destroy_node(self) -> None:
        self._close()
        super().destroy_node()
