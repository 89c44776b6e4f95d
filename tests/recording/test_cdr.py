"""Our CDR encoding produces the bytes rmw_fastrtps (rclpy) produces.

rmw leaves alignment padding uninitialised, so the only bytes allowed to differ are zeros on our
side, and our bytes must deserialize (rclpy) to the very message rclpy serialized.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

pytest.importorskip("rclpy")
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped  # noqa: E402
from qg_recording import cdr  # noqa: E402
from qg_recording.schemas import message_fields  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

T_NS = 1_763_700_000_123_456_789
FRAMES = ["", "a", "ab", "abc", "abcd", "base_link"]  # every padding length after the frame id
NAMES = [f"panda_joint{i}" for i in range(1, 8)]


def assert_same_cdr(ours: bytes, theirs: bytes) -> None:
    """Same length, and every differing byte is a zero of ours (callers also check that ours
    deserializes to the same message, so those bytes carry no data: they are padding)."""
    assert len(ours) == len(theirs)
    differing = [i for i in range(len(ours)) if ours[i] != theirs[i]]
    assert all(ours[i] == 0 for i in differing), f"data bytes differ at {differing}"


def stamp(msg, t_ns: int = T_NS) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = cdr.split_stamp(t_ns)


@pytest.mark.parametrize("frame_id", FRAMES)
@pytest.mark.parametrize("n", [1, 2, 7])
def test_joint_state_matches_rclpy(frame_id: str, n: int) -> None:
    rng = np.random.default_rng(n)
    names, q, dq, tau = NAMES[:n], rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    msg = JointState(name=names, position=q.tolist(), velocity=dq.tolist(), effort=tau.tolist())
    msg.header.frame_id = frame_id
    stamp(msg)
    ours = cdr.encode_joint_state(T_NS, frame_id, names, q, dq, tau)
    assert_same_cdr(ours, serialize_message(msg))
    assert deserialize_message(ours, JointState) == msg


@pytest.mark.parametrize("frame_id", FRAMES)
def test_stamped_geometry_matches_rclpy(frame_id: str) -> None:
    rng = np.random.default_rng(len(frame_id))
    a, b, quat = rng.normal(size=3), rng.normal(size=3), rng.normal(size=4)
    wrench = WrenchStamped()
    wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z = a.tolist()
    wrench.wrench.torque.x, wrench.wrench.torque.y, wrench.wrench.torque.z = b.tolist()
    twist = TwistStamped()
    twist.twist.linear.x, twist.twist.linear.y, twist.twist.linear.z = a.tolist()
    twist.twist.angular.x, twist.twist.angular.y, twist.twist.angular.z = b.tolist()
    pose = PoseStamped()
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = a.tolist()
    o = pose.pose.orientation
    o.x, o.y, o.z, o.w = quat.tolist()
    cases = [
        (wrench, cdr.encode_wrench_stamped(T_NS, frame_id, a, b)),
        (twist, cdr.encode_twist_stamped(T_NS, frame_id, a, b)),
        (pose, cdr.encode_pose_stamped(T_NS, frame_id, a, quat)),
    ]
    for msg, ours in cases:
        msg.header.frame_id = frame_id
        stamp(msg)
        assert_same_cdr(ours, serialize_message(msg))
        assert deserialize_message(ours, type(msg)) == msg


def test_lists_and_strided_arrays_encode_like_contiguous_float64() -> None:
    v = np.arange(6.0)
    reference = cdr.encode_wrench_stamped(5, "tool", v[:3], v[3:])
    assert cdr.encode_wrench_stamped(5, "tool", [0, 1, 2], (3.0, 4.0, 5.0)) == reference
    assert cdr.encode_wrench_stamped(5, "tool", v[0:6:2] * 0 + [0, 1, 2], v[3:].astype(np.float32)) == reference


def test_negative_and_large_stamps_split_like_builtin_time() -> None:
    assert cdr.split_stamp(1_500_000_000) == (1, 500_000_000)
    assert cdr.split_stamp(-1_700_000_000) == (-2, 300_000_000)  # ROS convention: nanosec >= 0


def test_joint_state_rejects_ragged_arrays() -> None:
    with pytest.raises(ValueError, match="2 > 0 values"):
        cdr.encode_joint_state(0, "", ["a", "b"], [1.0, 2.0], [1.0], [1.0, 2.0])


def fill(msg: object, type_name: str, row: np.ndarray, k: int = 0) -> int:
    """Set the fields of an rclpy message from value columns in definition order (as the
    layouts lay them out); returns the next column."""
    for field in message_fields(type_name):
        if field.type_name == cdr.HEADER:
            continue
        count = field.array or 1
        dtype = cdr._DTYPES.get(field.type_name)
        if dtype is None:
            items = getattr(msg, field.name) if field.array else [getattr(msg, field.name)]
            for item in items:
                k = fill(item, field.type_name, row, k)
            continue
        cast = bool if dtype == "?" else float if "f" in dtype else int
        values = [cast(x) for x in row[k:k + count]]
        setattr(msg, field.name, values if field.array else values[0])
        k += count
    return k


def random_row(layout: cdr.FixedLayout, rng: np.random.Generator) -> np.ndarray:
    parts = []
    for _, dtype, count in layout.blocks:
        if dtype == "?":
            parts.append(rng.integers(0, 2, count))
        elif "f" in dtype:
            parts.append(rng.normal(size=count).astype(dtype))
        else:
            parts.append(rng.integers(0, 100, count))
    return np.concatenate(parts).astype(np.float64)


def check_fixed_type(type_name: str, message_class: type) -> None:
    rng = np.random.default_rng(7)
    for frame_id in FRAMES:
        layout = cdr.fixed_layout(type_name, frame_id)
        row = random_row(layout, rng)
        msg = message_class()
        assert fill(msg, type_name, row) == layout.n_values
        msg.header.frame_id = frame_id
        stamp(msg)
        ours = layout.encode(T_NS, row)
        assert_same_cdr(ours, serialize_message(msg))
        assert deserialize_message(ours, message_class) == msg


@pytest.mark.parametrize("type_name", [
    "geometry_msgs/msg/AccelStamped",  # nested vectors
    "geometry_msgs/msg/PointStamped",
    "sensor_msgs/msg/Imu",  # fixed float64[9] arrays between messages
    "sensor_msgs/msg/NavSatFix",  # int8, uint16 and uint8 after doubles
    "sensor_msgs/msg/Temperature",
])
def test_layouts_compiled_from_msg_files_match_rclpy(type_name: str) -> None:
    pkg, _, name = type_name.split("/")
    check_fixed_type(type_name, getattr(importlib.import_module(f"{pkg}.msg"), name))


def test_layout_columns_name_the_fields() -> None:
    layout = cdr.fixed_layout("geometry_msgs/msg/PoseStamped", "base")
    assert layout.columns == (("pose", 0, 7),) and layout.n_values == 7
    assert layout.blocks == ((28, "<f8", 7),)  # one block after encapsulation (4) + padded header (24)
    with pytest.raises(ValueError, match="sequence"):
        cdr.fixed_layout("sensor_msgs/msg/JointState")
    with pytest.raises(ValueError, match="std_msgs/Header"):
        cdr.fixed_layout("geometry_msgs/msg/Wrench")


@pytest.mark.ros
def test_interface_messages_match_rclpy() -> None:
    from qg_interfaces.msg import GroundTruth, Transition

    check_fixed_type("qg_interfaces/msg/GroundTruth", GroundTruth)
    for episode_id, dims in [("ep", (4, 2)), ("episode_0001", (3, 1)), ("", (0, 0))]:
        s, a = np.linspace(-1, 1, dims[0]), np.linspace(0.5, -0.5, dims[1])
        tr = Transition(episode_id=episode_id, step=17, state=s.tolist(), action=a.tolist(), reward=-1.0,
                        next_state=(s * 0.5).tolist(), terminal=False, timeout=True, zero_action=False)
        ours = cdr.encode_transition(episode_id, 17, s, a, -1.0, s * 0.5, False, True, False)
        assert deserialize_message(ours, Transition) == tr
        if dims[0]:  # rmw pads empty double sequences in its length estimate; compare non-empty ones
            assert_same_cdr(ours, serialize_message(tr))
