"""CDR encoding of the recorded messages without rclpy, fast enough for five messages per tick.

`rclpy.serialization.serialize_message` needs a filled rclpy message object: building one and
serializing it costs 30-40 µs, too much for five messages every millisecond. The high-rate
messages have a fixed layout once their frame id (and joint names) are known, so a
`FixedLayout` holds the serialized bytes of such a message with zero numbers plus the places of
the stamp and of the numbers, compiled from the `.msg` definition (`fixed_layout`), so a changed
interface changes the layout with it; the 1 kHz loop only copies its numbers into a row of floats, and
the writer thread encodes hundreds of rows with a few numpy operations (`encode_many`).
The output is plain CDR (XCDR1, little endian, alignment counted from the end of the 4-byte
encapsulation header), the bytes rmw_fastrtps produces, except that padding bytes are zero
(rmw leaves them uninitialised). `CdrBuffer` is the sequential writer the layouts are built
with; it also encodes the RL-rate `Transition`.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .schemas import message_fields

__all__ = [
    "CdrBuffer",
    "FixedLayout",
    "encode_joint_state",
    "encode_pose_stamped",
    "encode_transition",
    "encode_twist_stamped",
    "encode_wrench_stamped",
    "joint_state_layout",
    "fixed_layout",
    "split_stamp",
    "tf_layout",
]

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE, options 0
_NS_PER_S = 1_000_000_000
_F8 = np.dtype("<f8")

Vector = Sequence[float] | np.ndarray


def split_stamp(t_ns: int) -> tuple[int, int]:
    """`builtin_interfaces/Time` (sec, nanosec) of a time in nanoseconds (nanosec >= 0)."""
    return divmod(t_ns, _NS_PER_S)


class CdrBuffer:
    """Sequential CDR writer: each primitive is aligned to its size, as rmw_fastrtps does."""

    def __init__(self) -> None:
        self._parts: list[bytes] = [ENCAPSULATION]
        self._offset = 0  # payload bytes written (alignment is relative to the payload)

    def _put(self, data: bytes, alignment: int) -> int:
        """Append aligned data; returns its offset in the message (encapsulation included)."""
        pad = -self._offset % alignment
        if pad:
            self._parts.append(b"\x00" * pad)
        self._parts.append(data)
        self._offset += pad + len(data)
        return len(ENCAPSULATION) + self._offset - len(data)

    def uint32(self, value: int) -> CdrBuffer:
        self._put(struct.pack("<I", value), 4)
        return self

    def float64(self, value: float) -> CdrBuffer:
        self._put(struct.pack("<d", value), 8)
        return self

    def boolean(self, value: bool) -> CdrBuffer:
        self._put(b"\x01" if value else b"\x00", 1)
        return self

    def string(self, value: str) -> CdrBuffer:
        data = value.encode() + b"\x00"
        self.uint32(len(data))
        self._put(data, 1)
        return self

    def string_sequence(self, values: Sequence[str]) -> CdrBuffer:
        self.uint32(len(values))
        for value in values:
            self.string(value)
        return self

    def float64_sequence(self, values: Vector) -> CdrBuffer:
        data = np.asarray(values, dtype=_F8).tobytes()
        self.uint32(len(data) // 8)
        if data:  # an empty sequence is not aligned
            self._put(data, 8)
        return self

    def stamp(self, t_ns: int) -> CdrBuffer:
        sec, nanosec = split_stamp(t_ns)
        self._put(struct.pack("<iI", sec, nanosec), 4)
        return self

    def reserve(self, dtype: str, count: int) -> int:
        """Zero room for `count` values of a numpy `dtype` ("<f8" or "?"); returns the offset."""
        size = np.dtype(dtype).itemsize
        return self._put(b"\x00" * (size * count), size)

    def message(self) -> bytes:
        """The serialized message: encapsulation header plus payload."""
        return b"".join(self._parts)


@dataclass(frozen=True)
class FixedLayout:
    """A fixed-size message type: template bytes, and where its numbers go.

    The numbers of one message form one row of floats, in the order of `blocks`; each block is
    (offset in the message, numpy dtype, count). Every `builtin_interfaces/Time` at an offset of
    `stamps` is the message's time: the header's stamp at offset 4, or the stamp of each
    transform of a `tf2_msgs/TFMessage` (`tf_layout`). `columns` names the row's columns by
    top-level field.
    """

    type_name: str
    template: bytes
    blocks: tuple[tuple[int, str, int], ...]
    columns: tuple[tuple[str, int, int], ...] = ()  # top-level field name, first, end column
    stamps: tuple[int, ...] = (4,)

    @functools.cached_property
    def slices(self) -> dict[str, slice]:
        """Value columns of each top-level field (after the header), by field name."""
        return {name: slice(start, stop) for name, start, stop in self.columns}

    @property
    def size(self) -> int:
        return len(self.template)

    @functools.cached_property
    def n_values(self) -> int:
        return sum(count for _, _, count in self.blocks)

    @functools.cached_property
    def _dtype(self) -> np.dtype:
        names, formats, offsets = [], [], []
        for j, offset in enumerate(self.stamps):
            names += [f"sec{j}", f"nanosec{j}"]
            formats += ["<i4", "<u4"]
            offsets += [offset, offset + 4]
        for j, (offset, dtype, count) in enumerate(self.blocks):
            names.append(f"b{j}")
            formats.append(dtype if count == 1 else (dtype, (count,)))
            offsets.append(offset)
        return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": self.size})

    def encode_many(self, t_ns: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Messages of times `t_ns` (n,) and number rows `values` (n, n_values), as (n, size) uint8."""
        n = len(t_ns)
        data = bytearray(self.template * n)  # a structured copy would not keep the constant bytes
        rows = np.frombuffer(data, dtype=self._dtype)
        sec, nanosec = np.divmod(t_ns, _NS_PER_S)
        for j in range(len(self.stamps)):
            rows[f"sec{j}"], rows[f"nanosec{j}"] = sec, nanosec
        column = 0
        for j, (_, _, count) in enumerate(self.blocks):
            rows[f"b{j}"] = values[:, column] if count == 1 else values[:, column:column + count]
            column += count
        return np.frombuffer(data, dtype=np.uint8).reshape(n, self.size)

    def encode(self, t_ns: int, values: Vector) -> bytes:
        """One message (for tools and tests; the recorder encodes rows in bulk)."""
        row = np.asarray(values, dtype=_F8).reshape(1, self.n_values)
        return self.encode_many(np.array([t_ns], dtype=np.int64), row).tobytes()


_DTYPES = {"bool": "?", "byte": "u1", "char": "u1", "uint8": "u1", "int8": "i1", "uint16": "<u2",
           "int16": "<i2", "uint32": "<u4", "int32": "<i4", "uint64": "<u8", "int64": "<i8",
           "float32": "<f4", "float64": "<f8"}
HEADER = "std_msgs/msg/Header"


@functools.lru_cache(maxsize=64)
def fixed_layout(type_name: str, frame_id: str = "") -> FixedLayout:
    """Layout of a fixed-size message type with a std_msgs/Header first, compiled from its `.msg`
    definition: numbers, bools, fixed arrays and nested messages become value columns in
    definition order; the header's frame id is constant, its stamp the message time.

    :raises ValueError: for a type without leading header or with strings or sequences.
    """
    fields = message_fields(type_name)
    if not fields or fields[0].type_name != HEADER or fields[0].array is not None:
        raise ValueError(f"{type_name} does not start with a std_msgs/Header")
    buffer = CdrBuffer().stamp(0).string(frame_id)
    blocks: list[tuple[int, str, int]] = []

    def add(type_name: str, count: int) -> int:
        """Lay out `count` values of `type_name`; returns the number of value columns."""
        dtype = _DTYPES.get(type_name)
        if dtype is not None:
            offset = buffer.reserve(dtype, count)
            last = blocks[-1] if blocks else None
            if last and last[1] == dtype and last[0] + last[2] * np.dtype(dtype).itemsize == offset:
                blocks[-1] = (last[0], dtype, last[2] + count)  # contiguous: one block
            else:
                blocks.append((offset, dtype, count))
            return count
        if type_name in ("string", "wstring") or type_name == HEADER:
            raise ValueError(f"{type_name} is not fixed-size: it contains a {type_name}")
        total = 0
        for _ in range(count):
            for field in message_fields(type_name):
                if field.array == -1:
                    raise ValueError(f"{type_name} is not fixed-size: {field.name} is a sequence")
                total += add(field.type_name, field.array or 1)
        return total

    columns, start = [], 0
    for field in fields[1:]:
        if field.array == -1:
            raise ValueError(f"{type_name} is not fixed-size: {field.name} is a sequence")
        n = add(field.type_name, field.array or 1)
        columns.append((field.name, start, start + n))
        start += n
    return FixedLayout(type_name, buffer.message(), tuple(blocks), tuple(columns))


@functools.lru_cache(maxsize=64)
def joint_state_layout(frame_id: str, names: tuple[str, ...]) -> FixedLayout:
    """Layout of a sensor_msgs/JointState with position, velocity, effort of len(names) each."""
    if not names:
        raise ValueError("a joint state layout needs at least one joint name")
    buffer = CdrBuffer().stamp(0).string(frame_id).string_sequence(names)
    n, blocks, columns = len(names), [], []
    for k, field in enumerate(("position", "velocity", "effort")):
        buffer.uint32(n)
        blocks.append((buffer.reserve("<f8", n), "<f8", n))
        columns.append((field, k * n, (k + 1) * n))
    return FixedLayout("sensor_msgs/msg/JointState", buffer.message(), tuple(blocks), tuple(columns))


@functools.lru_cache(maxsize=64)
def tf_layout(frames: tuple[tuple[str, str], ...]) -> FixedLayout:
    """Layout of a `tf2_msgs/msg/TFMessage` of one transform per `(parent, child)` frame pair,
    all stamped with the message's time: its row is each transform's translation (x, y, z) and
    rotation (x, y, z, w), transform after transform."""
    if not frames:
        raise ValueError("a tf layout needs at least one transform")
    buffer = CdrBuffer().uint32(len(frames))
    blocks, columns, stamps = [], [], []
    for k, (parent, child) in enumerate(frames):
        stamps.append(buffer.reserve("<i4", 2))            # header.stamp: sec, nanosec
        buffer.string(parent).string(child)
        blocks.append((buffer.reserve("<f8", 7), "<f8", 7))
        columns.append((child, 7 * k, 7 * (k + 1)))
    return FixedLayout("tf2_msgs/msg/TFMessage", buffer.message(), tuple(blocks),
                       tuple(columns), tuple(stamps))


def _row(*parts: Vector | float) -> np.ndarray:
    return np.concatenate([np.atleast_1d(np.asarray(p, dtype=_F8)) for p in parts])


def encode_joint_state(
    t_ns: int, frame_id: str, names: Sequence[str], position: Vector, velocity: Vector, effort: Vector
) -> bytes:
    """sensor_msgs/msg/JointState with position, velocity and effort all of len(names) values.

    :raises ValueError: if an array has another length (use `CdrBuffer` for ragged messages).
    """
    n = len(names)
    if not (len(position) == len(velocity) == len(effort) == n) or n == 0:
        raise ValueError(f"joint state arrays need {n} > 0 values each, got "
                         f"{len(position)}, {len(velocity)}, {len(effort)}")
    return joint_state_layout(frame_id, tuple(names)).encode(t_ns, _row(position, velocity, effort))


def encode_wrench_stamped(t_ns: int, frame_id: str, force: Vector, torque: Vector) -> bytes:
    """geometry_msgs/msg/WrenchStamped."""
    return fixed_layout("geometry_msgs/msg/WrenchStamped", frame_id).encode(t_ns, _row(force, torque))


def encode_twist_stamped(t_ns: int, frame_id: str, linear: Vector, angular: Vector) -> bytes:
    """geometry_msgs/msg/TwistStamped."""
    return fixed_layout("geometry_msgs/msg/TwistStamped", frame_id).encode(t_ns, _row(linear, angular))


def encode_pose_stamped(t_ns: int, frame_id: str, position: Vector, quaternion_xyzw: Vector) -> bytes:
    """geometry_msgs/msg/PoseStamped; the quaternion in ROS order (x, y, z, w)."""
    return fixed_layout("geometry_msgs/msg/PoseStamped", frame_id).encode(t_ns, _row(position, quaternion_xyzw))


def encode_transition(
    episode_id: str, step: int, state: Vector, action: Vector, reward: float, next_state: Vector,
    terminal: bool, timeout: bool, zero_action: bool,
) -> bytes:
    """qg_interfaces/msg/Transition (RL rate: the sequential writer is fast enough)."""
    return (
        CdrBuffer()
        .string(episode_id)
        .uint32(step)
        .float64_sequence(state)
        .float64_sequence(action)
        .float64(reward)
        .float64_sequence(next_state)
        .boolean(terminal)
        .boolean(timeout)
        .boolean(zero_action)
        .message()
    )
