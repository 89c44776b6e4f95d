"""The recorder in realtime mode: one time base per bag, the wall clock the live messages carry.

Episodes are driven by hand here (a status, a reset, one step, the final status), so only the
robot process runs. Where a bag begins and ends against the loop's ticks is tested on the
recorder node alone, its callbacks called directly with made-up ticks.
"""
from __future__ import annotations

import time
from pathlib import Path

import pytest
from conftest import SHORT_STEP
from live_capture import LiveCapture, stamp_ns
from robot_client import RobotClient

pytestmark = pytest.mark.ros   # a realtime robot process

EPISODE = "rt_0001"


def status(state: str, episode: str = EPISODE):
    from qg_common.conversions import time_msg
    from qg_interfaces.msg import EpisodeStatus
    return EpisodeStatus(stamp=time_msg(time.time_ns()), episode_id=episode, state=state, mode="test",
                         reward_type="sparse", initial_pose=2, step=0, max_steps=1)


@pytest.mark.alone   # a 1 kHz best-effort stream to this test's own subscriber
def test_realtime_bag_is_stamped_like_the_live_messages(stack, machine_to_itself) -> None:
    from qg_common.topics import LATCHED
    from qg_interfaces.msg import EpisodeStatus
    from qg_recording.bag_reader import bag_info
    from qg_recording.episode_recorder import TOPICS
    from qg_recording.player import message_class
    from rclpy.serialization import deserialize_message
    from rosbags.highlevel import AnyReader

    bag = Path(stack.env["QG_RUNS_DIR"]) / "episodes" / EPISODE
    # With the machine to itself: beside the other workers this test's subscriber, starved,
    # stopped receiving for good (3 of 6 suite runs: 318 states, 0.33 s of them, then none
    # while the robot published on and the bag recorded; Fast DDS giving up a shared-memory
    # reader that falls behind would do that, unproven).
    with machine_to_itself(), stack.client() as cli:
        stack.start(("robot", "robot_bridge_node", "robot",
                     ("--ros-args", "-p", "sim.clock_mode:=realtime", *SHORT_STEP)))
        live = LiveCapture(cli, ("/joint_states", "/ee_pose", "/ee_at_rest"))
        statuses = cli.node.create_publisher(EpisodeStatus, "/episode_status", LATCHED)
        robot = RobotClient(cli)
        assert robot.reset(2).success  # the robot is up
        statuses.publish(status("resetting"))
        assert cli.spin_until(bag.exists, 30.0), stack.logs()
        assert robot.reset(2).success
        assert robot.step(1, (0.0, 0.0, -8.0, 0.2, 0.0, 0.0), timeout=10.0) is not None
        statuses.publish(status("done"))
        assert cli.spin_until(lambda: bag_info(bag).complete, 30.0), stack.logs()
    with AnyReader([bag]) as reader:
        recorded: dict[str, list[tuple[int, bytes]]] = {}
        for connection, t_ns, data in reader.messages():
            recorded.setdefault(connection.topic, []).append((t_ns, bytes(data)))
        start, end = reader.start_time, reader.end_time
    assert start == recorded["/episode_status"][0][0]  # the bag starts with its first message
    assert abs(start - time.time_ns()) < 120 * 10**9  # the wall clock, not loop time
    assert all(start <= t < end for messages in recorded.values() for t, _ in messages)
    for topic in ("/joint_states", "/ee_pose"):  # the live stamps, byte for byte
        cls = message_class(TOPICS[topic].type_name)
        by_stamp = {stamp_ns(deserialize_message(data, cls)): data for _, data in recorded[topic]}
        assert all(t == stamp_ns(deserialize_message(data, cls)) for t, data in recorded[topic])
        in_span = [(stamp_ns(m), data) for m, data in zip(live.decoded(topic), live.received[topic])
                   if min(by_stamp) <= stamp_ns(m) <= max(by_stamp)]
        live_stamps = [stamp_ns(m) for m in live.decoded(topic)]
        assert len(in_span) >= 20, (topic, len(in_span), len(live_stamps),
                                    live_stamps[:1], live_stamps[-1:], min(by_stamp),
                                    max(by_stamp), len(by_stamp))
        assert all(by_stamp.get(t) == data for t, data in in_span), topic
    events = [deserialize_message(data, message_class(TOPICS["/ee_at_rest"].type_name))
              for _, data in recorded["/ee_at_rest"]]
    assert [e.seq for e in events][-1] == 1
    for (t_ns, _), event in zip(recorded["/ee_at_rest"], events):
        assert 0 <= t_ns - stamp_ns(event) < 10**9, (t_ns, stamp_ns(event))


def _ticks(stamps):
    """Loop records (``sample_ring.record_dtype``, 7 joints) stamped ``stamps``."""
    import numpy as np
    from robot_bridge_node.core.sample_ring import record_dtype
    ticks = np.zeros(len(stamps), dtype=record_dtype(7))
    ticks["t_ns"] = stamps
    return ticks


def _names():
    from robot_bridge_node.core.tick_messages import TickNames
    return TickNames(tuple(f"j{i}" for i in range(7)), "base")


@pytest.fixture
def recorder_node(tmp_path: Path):
    """A recorder node writing into ``tmp_path``, its messages handed to it by the test."""
    import rclpy
    from qg_recording.episode_recorder import EpisodeRecorder
    from robot_bridge_node.recorder_node import RecorderNode

    rclpy.init(domain_id=232)          # no test's processes use it; nothing is published
    try:
        node = RecorderNode()
        node.recorder = EpisodeRecorder(tmp_path)
        yield node
        node.destroy_node()
    finally:
        rclpy.shutdown()


def _on_status(node, t_ns: int, state: str, episode: str = EPISODE) -> None:
    from rclpy.serialization import serialize_message
    msg = status(state, episode)
    node._on_status(t_ns, serialize_message(msg), msg)


def test_ticks_stamped_before_the_bag_opened_are_not_recorded(recorder_node, tmp_path: Path) -> None:
    """The loop's ticks reach the recorder in blocks, a few ms after their stamps: a block that
    arrives just after an episode's first status holds ticks from before it (a suite run found a
    bag whose first message was a tick 4.6 ms older than its opening status)."""
    import numpy as np
    from qg_recording.bag_reader import read_raw

    node, opened = recorder_node, 1_000_000_000
    _on_status(node, opened, "resetting")
    node.record_samples(_ticks(opened + np.arange(-5, 5) * 1_000_000), _names())  # 5 before
    node._close()
    bag = tmp_path / EPISODE
    stamps = [m.t_ns for m in read_raw(bag, ["/joint_states"])]
    assert stamps == [opened + k * 1_000_000 for k in range(5)]
    first = next(iter(read_raw(bag)))
    assert (first.topic, first.t_ns) == ("/episode_status", opened)


def test_a_bag_waits_for_the_ticks_of_its_last_step(recorder_node, tmp_path: Path) -> None:
    """The final status overtakes the last step's ticks (they come in blocks, behind the RL-rate
    messages): the bag stays open until the ticks up to the episode's end are in, and a loop
    that sends no more closes it after ``close_timeout`` without them. A CI run under load
    closed a bag first, and it held no tick at all."""
    import numpy as np
    from qg_recording.bag_reader import read_raw
    from robot_bridge_node.recorder_node import _SETTLE

    node, names = recorder_node, _names()
    opened, ended = 1_000_000_000, 1_500_000_000
    _on_status(node, opened, "resetting")
    _on_status(node, ended, "done")             # the episode's 500 ticks not handed over yet
    node.ended_at -= 2 * _SETTLE                # the settling time has passed
    node._close_if_complete()
    assert node.recorder.active, "closed before the episode's ticks were in"
    node.record_samples(_ticks(opened + np.arange(250) * 1_000_000), names)
    node._close_if_complete()
    assert node.recorder.active, "closed with half of the episode's ticks"
    node.record_samples(_ticks(opened + np.arange(250, 501) * 1_000_000), names)
    node._close_if_complete()
    assert not node.recorder.active
    stamps = [m.t_ns for m in read_raw(tmp_path / EPISODE, ["/joint_states"])]
    assert stamps == [opened + k * 1_000_000 for k in range(501)]

    node.recorder.runs_dir = tmp_path / "next"       # the next episode (same id: another folder)
    _on_status(node, 2_000_000_000, "resetting")
    _on_status(node, 2_100_000_000, "done")          # ... and no tick comes any more
    node.ended_at -= node.config.close_timeout + _SETTLE
    node._close_if_complete()
    assert not node.recorder.active


def test_the_next_episodes_first_status_waits_for_the_last_ones_ticks(recorder_node,
                                                                       tmp_path: Path) -> None:
    """Episodes back to back: the next episode's ``resetting`` may come before the last step's
    ticks of the episode before. Its bag takes them first (the reader thread hands them over
    40 ms later here), then the next bag opens."""
    import threading

    import numpy as np
    from qg_recording.bag_reader import read_raw

    node, names = recorder_node, _names()
    opened, ended = 1_000_000_000, 1_100_000_000
    _on_status(node, opened, "resetting")
    _on_status(node, ended, "done")
    late = threading.Timer(0.04, node.record_samples,
                           (_ticks(opened + np.arange(101) * 1_000_000), names))
    late.start()
    start = time.monotonic()
    _on_status(node, ended, "resetting", "rt_0002")
    waited = time.monotonic() - start
    late.join()
    assert waited < 0.4, waited          # (not the whole _TICKS_WAIT)
    assert node.recorder.episode_id == "rt_0002" and node.opened_ns == ended
    stamps = [m.t_ns for m in read_raw(tmp_path / EPISODE, ["/joint_states"])]
    assert stamps == [opened + k * 1_000_000 for k in range(101)]
