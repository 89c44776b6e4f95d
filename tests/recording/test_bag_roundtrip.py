"""Episode bags read back with the mcap reader and mcap_ros2's decoder, with matching counts."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from qg_recording.bag_reader import bag_info, read_bag
from qg_recording.bag_writer import BagWriter
from qg_recording.cdr import encode_wrench_stamped
from qg_recording.episode_recorder import TOPICS, EpisodeRecorder

NAMES = [f"panda_joint{i}" for i in range(1, 8)]
T0 = 1_763_700_000_000_000_000
TICKS = 1200  # 1.2 s at 1 kHz: several chunks at the chunk size used below
STEPS = 12


def record_episode(recorder: EpisodeRecorder, episode_id: str) -> None:
    recorder.start(episode_id, {"mode": "train", "seed": 3})
    for i in range(TICKS):
        t = T0 + i * 1_000_000
        q = np.full(7, i * 1e-3)
        recorder.record_joint_state(t, NAMES, q, -q, 2 * q)
        recorder.record_wrench(t, [i, 0.0, -1.0], [0.0, 0.5, 0.0])
        recorder.record_pose(t, [0.5, 0.0, 0.3 - i * 1e-6], [0.0, 1.0, 0.0, 0.0])
        recorder.record_twist(t, [0.0, 0.0, -1e-3], [0.0, 0.0, 0.0])
        recorder.record_ground_truth(t, [0.0, 0.0, -5.0, 0.0, 0.0, 0.0], i * 1e-5, 2e-3, i == TICKS - 1,
                                     1e-3, [2e-3, -2e-3], 3e-4, 0.05)
        if i % (TICKS // STEPS) == 0:
            step = i // (TICKS // STEPS)
            recorder.record_transition(t, step, [step, 0.0, 0.0, 0.0], [0.1, -0.1], -1.0,
                                       [step + 1, 0.0, 0.0, 0.0], step == STEPS - 1)
    recorder.stop()


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    runs = tmp_path_factory.mktemp("runs")
    record_episode(EpisodeRecorder(runs, chunk_size=64 * 1024), "ep_0001")
    return runs / "ep_0001"


EXPECTED = {"/joint_states": TICKS, "/wrench_estimate": TICKS, "/ee_pose": TICKS, "/ee_twist": TICKS,
            "/sim/ground_truth": TICKS, "/transitions": STEPS}


def test_mcap_reader_and_ros2_decoder_read_every_message(bag: Path) -> None:
    files = list(bag.glob("*.mcap"))
    assert [f.name for f in files] == ["ep_0001_0.mcap"]
    counts: dict[str, int] = {}
    with open(files[0], "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
            assert schema.name == TOPICS[channel.topic].type_name
            i = (message.log_time - T0) // 1_000_000
            if channel.topic == "/joint_states":
                assert decoded.name == NAMES
                assert decoded.position == pytest.approx([i * 1e-3] * 7)
                assert decoded.effort == pytest.approx([2 * i * 1e-3] * 7)
                assert decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec == message.log_time
            elif channel.topic == "/wrench_estimate":
                assert (decoded.wrench.force.x, decoded.wrench.torque.y) == (i, 0.5)
                assert decoded.header.frame_id == "tool"
            elif channel.topic == "/sim/ground_truth":
                assert decoded.insertion_depth == pytest.approx(i * 1e-5)
                assert decoded.success == (i == TICKS - 1)
                assert decoded.lateral_offset == pytest.approx(3e-4)
                assert list(decoded.orientation_error) == pytest.approx([2e-3, -2e-3])
                assert (decoded.contact_wrench.force.z, decoded.tilt) == (-5.0, 0.05)
            elif channel.topic == "/transitions":
                assert decoded.episode_id == "ep_0001"
                assert decoded.next_state[0] == decoded.state[0] + 1
                assert decoded.terminal == (decoded.step == STEPS - 1)
        summary = reader.get_summary()
    assert counts == EXPECTED
    assert summary.statistics.message_count == sum(EXPECTED.values())
    assert summary.statistics.chunk_count >= 3  # the chunk size really split the episode


def test_metadata_yaml_lists_the_counts(bag: Path) -> None:
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap"
    assert meta["relative_file_paths"] == ["ep_0001_0.mcap"]
    assert meta["message_count"] == sum(EXPECTED.values())
    assert meta["duration"]["nanoseconds"] == (TICKS - 1) * 1_000_000
    assert meta["starting_time"]["nanoseconds_since_epoch"] == T0
    listed = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert set(listed) == set(TOPICS)  # all recorder topics, even those without messages
    for name, entry in listed.items():
        assert entry["message_count"] == EXPECTED.get(name, 0)
        assert entry["topic_metadata"]["type"] == TOPICS[name].type_name
        assert entry["topic_metadata"]["serialization_format"] == "cdr"
        assert entry["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == TOPICS[name].qos
    assert meta["custom_data"] == {"episode_id": "ep_0001", "mode": "train", "seed": "3"}


def test_bag_info_and_read_bag_agree(bag: Path) -> None:
    info = bag_info(bag)
    assert info.complete and info.has_metadata
    assert {t.name: t.message_count for t in info.topics if t.message_count} == EXPECTED
    assert info.duration_ns == (TICKS - 1) * 1_000_000
    times = [t for _, _, t, _ in read_bag(bag)]
    assert len(times) == sum(EXPECTED.values())
    assert times == sorted(times)  # log-time order, though the file groups each topic in blocks
    seen = [(topic, t) for topic, _, t, _ in read_bag(bag, topics=["/transitions"])]
    assert len(seen) == STEPS and all(topic == "/transitions" for topic, _ in seen)
    assert [t for _, t in seen] == sorted(t for _, t in seen)


def test_episodes_are_separate_directories(tmp_path: Path) -> None:
    recorder = EpisodeRecorder(tmp_path)
    recorder.record_wrench(T0, [1.0, 0, 0], [0, 0, 0])  # idle: ignored
    for episode in ("a", "b"):
        recorder.start(episode)
        assert recorder.active
        recorder.record_wrench(T0, [1.0, 0, 0], [0, 0, 0])
    recorder.stop()
    assert not recorder.active
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]
    assert [bag_info(tmp_path / e).count("/wrench_estimate") for e in ("a", "b")] == [1, 1]
    with pytest.raises(FileExistsError):
        recorder.start("a")
    with pytest.raises(ValueError, match="plain directory name"):
        recorder.start("../escape")


def test_metadata_exists_from_the_start_and_follows_closed_chunks(tmp_path: Path) -> None:
    writer = BagWriter(tmp_path / "bag", chunk_size=4096, flush_interval_s=0.05)
    writer.add_topic("/w", "geometry_msgs/msg/WrenchStamped")
    meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == 0
    for i in range(10):
        writer.write("/w", encode_wrench_stamped(T0 + i, "", [i, 0, 0], [0, 0, 0]), T0 + i)
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:  # the flush interval closes the chunk while still open
        meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        if meta["message_count"] == 10:
            break
        time.sleep(0.02)
    assert meta["message_count"] == 10
    writer.close()
    assert writer.messages_written == 10
    with pytest.raises(RuntimeError, match="closed"):
        writer.write("/w", b"", T0)


def test_writer_rejects_unknown_topics_and_bad_options(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag") as writer:
        with pytest.raises(ValueError, match="was not added"):
            writer.write("/nope", b"\x00", 0)
        with pytest.raises(ValueError, match="qos"):
            writer.add_topic("/x", "std_msgs/msg/String", qos="sometimes")
        writer.add_topic("/x", "std_msgs/msg/String")
        with pytest.raises(ValueError, match="recorded as std_msgs/msg/String"):
            writer.add_topic("/x", "std_msgs/msg/Bool")
    with pytest.raises(ValueError, match="compression"):
        BagWriter(tmp_path / "other", compression="gzip")
    with pytest.raises(FileExistsError):
        BagWriter(tmp_path / "bag")


def test_episodes_started_and_stopped_from_another_thread(tmp_path: Path) -> None:
    import threading

    recorder, errors, stop = EpisodeRecorder(tmp_path), [], threading.Event()

    def loop() -> None:
        i = 0
        try:
            while not stop.is_set():
                recorder.record_wrench(T0 + i, [float(i), 0.0, 0.0], [0.0, 0.0, 0.0])
                i += 1
                time.sleep(0.0002)   # about a 1 kHz loop: a busier one only starves the GIL
        except Exception as exc:  # noqa: BLE001 - the assertion below reports it
            errors.append(exc)

    thread = threading.Thread(target=loop)
    thread.start()
    for k in range(8):
        recorder.start(f"ep{k}")
        time.sleep(0.03)
        recorder.stop()
    stop.set()
    thread.join()
    assert errors == []
    for k in range(8):
        got = [int(m.wrench.force.x) for _, _, _, m in read_bag(tmp_path / f"ep{k}")]
        assert got and got == list(range(got[0], got[0] + len(got)))  # contiguous within an episode
        assert bag_info(tmp_path / f"ep{k}").complete


def test_rclpy_messages_and_other_fixed_types(tmp_path: Path) -> None:
    std_msgs = pytest.importorskip("std_msgs.msg")
    recorder = EpisodeRecorder(tmp_path)
    bag = recorder.start("ep")
    recorder.record_message("/chatter", T0, std_msgs.String(data="hello"))  # type from the class
    recorder.record_fixed("/imu", T0 + 1, np.arange(37.0), frame_id="imu", type_name="sensor_msgs/msg/Imu")
    with pytest.raises(ValueError, match="pass its type name"):
        recorder.record_raw("/unknown", T0, b"\x00\x01\x00\x00")
    recorder.stop()
    (chatter, imu) = list(read_bag(bag, topics=["/chatter", "/imu"]))
    assert chatter[:2] == ("/chatter", "std_msgs/msg/String") and chatter[3].data == "hello"
    assert imu[1] == "sensor_msgs/msg/Imu" and imu[3].header.frame_id == "imu"
    assert imu[3].orientation.w == 3.0 and list(imu[3].linear_acceleration_covariance) == list(range(28, 37))
