"""An episode bag as tools we did not write see it: rosbags (AnyReader, typestore from the bag's
own definitions, type hashes checked) and the mcap library's ROS 2 decoder, compared with what was
recorded; the MCAP `rosbag2` record as rosbag2's Jazzy MCAP plugin writes it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from qg_recording.episode_recorder import TOPICS, EpisodeRecorder
from qg_recording.schemas import schema_text, type_hash
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

NAMES = [f"panda_joint{i}" for i in range(1, 8)]
T0 = 1_763_700_000_000_000_000
TICKS = 600
STEPS = 6
STATUS_T = [T0 - 3_000_000, T0 + TICKS * 1_000_000]  # resetting (before the first tick), done


def rosbags_typestore():
    """A typestore that knows our types from their recorded schema text (not from rclpy)."""
    store = get_typestore(Stores.EMPTY)
    for spec in TOPICS.values():
        store.register(get_types_from_msg(schema_text(spec.type_name), spec.type_name))
    return store


def time_msg(store, t_ns: int):
    return store.types["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def status(store, t_ns: int, state: str):
    return store.types["qg_interfaces/msg/EpisodeStatus"](
        stamp=time_msg(store, t_ns), episode_id="ep_7", state=state, mode="train", reward_type="dense",
        initial_pose=3, step=STEPS if state == "done" else 0, max_steps=50, episode_return=-2.5,
        success=state == "done", degraded=False, actor_version=11, message="", recoveries=0)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[str, int, bytes]]]:
    """The bag and the RL-rate messages written into it (topic, log time, CDR), serialized by
    rosbags so the bytes come from an encoder we did not write."""
    store = rosbags_typestore()
    runs = tmp_path_factory.mktemp("runs")
    recorder = EpisodeRecorder(runs, chunk_size=32 * 1024)
    recorder.start("ep_7", {"mode": "train", "initial_pose": 3})
    raw: list[tuple[str, int, bytes]] = []

    def write(topic: str, t_ns: int, msg) -> None:
        data = bytes(store.serialize_cdr(msg, TOPICS[topic].type_name))
        recorder.record_raw(topic, t_ns, data)
        raw.append((topic, t_ns, data))

    write("/episode_status", STATUS_T[0], status(store, STATUS_T[0], "resetting"))
    header = store.types["std_msgs/msg/Header"]
    for i in range(TICKS):
        t = T0 + i * 1_000_000
        q = np.full(7, i * 1e-3)
        recorder.record_joint_state(t, NAMES, q, -q, 2 * q)
        recorder.record_pose(t, [0.5, 0.0, 0.3 - i * 1e-6], [1.0, 0.0, 0.0, 0.0])
        if i % (TICKS // STEPS) == 0:
            pose = store.types["geometry_msgs/msg/Pose"](
                position=store.types["geometry_msgs/msg/Point"](x=0.5, y=0.0, z=0.3),
                orientation=store.types["geometry_msgs/msg/Quaternion"](x=1.0, y=0.0, z=0.0, w=0.0))
            vec = store.types["geometry_msgs/msg/Vector3"]
            wrench = store.types["geometry_msgs/msg/Wrench"](force=vec(x=0.0, y=0.0, z=-15.0),
                                                              torque=vec(x=0.1 * i, y=0.0, z=0.0))
            write("/wrench_setpoint", t, store.types["qg_interfaces/msg/WrenchSetpoint"](
                header=header(stamp=time_msg(store, t), frame_id="tool"), seq=i + 1,
                session="ep_7", wrench=wrench,
                pose_reference=pose, reference_from_current=True))
    recorder.record_transition(T0 + TICKS * 1_000_000, 0, [0.1, 0.2, 0.3, 0.4], [0.5, -0.5], -1.0,
                               [0.2, 0.3, 0.4, 0.5], False)
    write("/episode_status", STATUS_T[1], status(store, STATUS_T[1], "done"))
    recorder.stop()
    return runs / "ep_7", raw


def test_rosbags_reads_every_message_with_the_bags_own_types(recorded) -> None:
    bag, raw = recorded
    counts: dict[str, int] = {}
    rl: list[tuple[str, int, bytes]] = []
    # No default typestore: AnyReader builds one from the bag's definitions and checks each
    # type's RIHS01 hash recorded in metadata.yaml against the hash of those definitions.
    with AnyReader([bag]) as reader:
        assert reader.readers[0].ros_distro == "jazzy"
        for connection, t_ns, data in reader.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            msg = reader.deserialize(data, connection.msgtype)
            if connection.topic in ("/joint_states", "/ee_pose"):
                assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t_ns
                i = (t_ns - T0) // 1_000_000
                if connection.topic == "/joint_states":
                    assert list(msg.name) == NAMES
                    assert msg.effort == pytest.approx([2 * i * 1e-3] * 7)
                else:
                    assert msg.pose.position.z == pytest.approx(0.3 - i * 1e-6)
                    assert msg.pose.orientation.x == 1.0
            elif connection.topic == "/transitions":
                assert (msg.episode_id, list(msg.action)) == ("ep_7", [0.5, -0.5])
            else:
                rl.append((connection.topic, t_ns, bytes(data)))
                if connection.topic == "/episode_status":
                    assert (msg.episode_id, msg.initial_pose, msg.actor_version) == ("ep_7", 3, 11)
        topics = {c.topic: c for c in reader.connections}
        assert reader.start_time == STATUS_T[0]  # the bag starts at its first message
    assert counts == {"/joint_states": TICKS, "/ee_pose": TICKS, "/transitions": 1,
                      "/wrench_setpoint": STEPS, "/episode_status": 2}
    assert sorted(rl) == sorted(raw)  # RL-rate messages: same bytes, same log times
    for name, spec in TOPICS.items():
        assert topics[name].msgtype == spec.type_name
        assert topics[name].digest == type_hash(spec.type_name)
        (qos,) = topics[name].ext.offered_qos_profiles
        assert qos.reliability.name.lower() == spec.qos
        assert qos.durability.name.lower() == spec.durability
        assert qos.depth == spec.depth
    assert topics["/episode_status"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"


def test_type_hashes_are_those_of_the_definitions(recorded) -> None:
    """The installed type description's hash equals rosbags' RIHS01 of the recorded schema."""
    store = rosbags_typestore()
    for spec in TOPICS.values():
        assert type_hash(spec.type_name).startswith("RIHS01_")
        assert type_hash(spec.type_name) == store.hash_rihs01(spec.type_name), spec.type_name


def test_mcap_ros2_decoder_and_the_rosbag2_metadata_record(recorded) -> None:
    bag, raw = recorded
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    with open(bag / "ep_7_0.mcap", "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        rl = []
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            assert channel.metadata["topic_type_hash"] == type_hash(schema.name)
            offered = yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]
            assert offered["durability"] == TOPICS[channel.topic].durability
            if channel.topic in ("/episode_status", "/wrench_setpoint"):
                rl.append((channel.topic, message.log_time, message.data))
            if channel.topic == "/wrench_setpoint":
                assert decoded.wrench.torque.x == pytest.approx(0.1 * (decoded.seq - 1))
        (record,) = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
    assert sorted(rl) == sorted(raw)
    # rosbag2's MCAP plugin reads these two keys (MCAPStorage::read_metadata).
    assert set(record.metadata) == {"serialized_metadata", "ROS_DISTRO"}
    assert record.metadata["ROS_DISTRO"] == "jazzy"
    assert yaml.safe_load(record.metadata["serialized_metadata"]) == meta
    assert meta["custom_data"] == {"episode_id": "ep_7", "mode": "train", "initial_pose": "3"}
    assert meta["starting_time"]["nanoseconds_since_epoch"] == STATUS_T[0]
    assert meta["duration"]["nanoseconds"] == STATUS_T[1] - STATUS_T[0]
