"""Reading our (and rosbag2's) MCAP bags without ROS: raw records, decoded messages, bag info.

Reading goes through the MCAP stream reader and stops quietly at the first record that cannot
be read: a recorder killed with SIGKILL leaves a file without summary whose last chunk may be
cut, and everything before it is still good data. Messages come out in log-time order. Decoding uses mcap_ros2's
dynamic decoder on the ros2msg schemas stored in the file, so no message package is needed.
`bag_info` prefers the MCAP summary (instant) and scans the file when the summary is missing.
"""

from __future__ import annotations

import heapq
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import zstandard
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import MCAP0_MAGIC
from mcap_ros2.decoder import DecoderFactory

from .rosbag2_metadata import METADATA_FILE, read_metadata

__all__ = [
    "READ_ERRORS",
    "BagInfo",
    "NotABagError",
    "RawMessage",
    "TopicInfo",
    "bag_files",
    "bag_info",
    "read_bag",
    "read_raw",
    "top_level_records",
]

#: What reading a cut or damaged MCAP file raises.
READ_ERRORS = (McapError, struct.error, zstandard.ZstdError, ValueError, EOFError, OSError)


class NotABagError(ValueError):
    """The path is neither a bag directory nor an MCAP file."""


class RawMessage(NamedTuple):
    topic: str
    type_name: str
    t_ns: int
    data: bytes


@dataclass(frozen=True)
class TopicInfo:
    name: str
    type_name: str
    message_count: int
    qos: str  # the channel's offered_qos_profiles YAML, as recorded
    type_hash: str = ""  # the channel's topic_type_hash (RIHS01)


@dataclass(frozen=True)
class BagInfo:
    """What `qgl info` prints."""

    path: Path
    files: tuple[Path, ...]
    topics: tuple[TopicInfo, ...]
    start_ns: int
    end_ns: int
    complete: bool  # every file has its MCAP summary (closed cleanly)
    has_metadata: bool  # the directory has a metadata.yaml
    size_bytes: int

    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics)

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    def count(self, topic: str) -> int:
        return sum(t.message_count for t in self.topics if t.name == topic)


def bag_files(path: Path) -> list[Path]:
    """The MCAP files of a bag directory (in metadata.yaml order) or of a single `.mcap` path.

    :raises FileNotFoundError: if the path does not exist.
    :raises NotABagError: if it holds no MCAP file.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such bag: {path}")
    files: list[Path] = [path] if path.is_file() else []
    if path.is_dir() and (path / METADATA_FILE).is_file():
        try:
            files = [path / p for p in read_metadata(path).get("relative_file_paths") or []]
        except ValueError:
            files = []
        files = [f for f in files if f.is_file()]
    if not files and path.is_dir():
        files = sorted(path.glob("*.mcap"))
    if not files:
        raise NotABagError(f"not a bag (no .mcap file): {path}")
    for file in files:
        with open(file, "rb") as stream:
            if stream.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
                raise NotABagError(f"not an MCAP file (bad magic): {file}")
    return files


def top_level_records(file: Path) -> Iterator[object]:
    """Records of one file (chunks unopened), up to the first unreadable one."""
    with open(file, "rb") as stream:
        records = StreamReader(stream, emit_chunks=True).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except READ_ERRORS:
                return  # truncated tail (killed recorder): keep what was complete
            yield record


def _iter_file(file: Path, topics: set[str] | None) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """Messages of one file in log-time order (ties: file order).

    Chunks may overlap in time (our writer groups the 1 kHz topics in blocks), so, as mcap's
    indexed reader does, a chunk is opened when the merge reaches its start time and its
    messages join one heap ordered by (time, chunk position, index in chunk). The compressed
    chunks are held in memory (an episode bag is small); this works without the summary a
    killed recorder never wrote.
    """
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    chunks: dict[int, Chunk] = {}  # by position in the file
    heap: list[tuple[int, int, int, Any]] = []  # index -1 marks a chunk still to open

    def accept(record: object, position: int, index: int) -> None:
        if isinstance(record, Message):
            channel = channels.get(record.channel_id)
            if channel is None:
                raise McapError(f"{file}: message on channel {record.channel_id} before its channel record")
            if topics is None or channel.topic in topics:
                entry = (schemas.get(channel.schema_id), channel, record)
                heapq.heappush(heap, (record.log_time, position, index, entry))
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Schema):
            schemas[record.id] = record

    for position, record in enumerate(top_level_records(file)):
        if isinstance(record, Chunk):
            chunks[position] = record
            heapq.heappush(heap, (record.message_start_time, position, -1, None))
        else:
            accept(record, position, 0)
    while heap:
        _, position, index, entry = heapq.heappop(heap)
        if index >= 0:
            yield entry
            continue
        try:
            inner = breakup_chunk(chunks.pop(position))
        except READ_ERRORS:
            continue  # a chunk damaged on disk: skip it
        for i, record in enumerate(inner):
            accept(record, position, i)


def read_raw(path: Path, topics: Iterable[str] | None = None) -> Iterator[RawMessage]:
    """Serialized messages in log-time order.

    :param topics: only these topics (all if None).
    """
    wanted = None if topics is None else set(topics)
    for file in bag_files(path):
        for schema, channel, message in _iter_file(file, wanted):
            yield RawMessage(channel.topic, schema.name if schema else "", message.log_time, message.data)


def read_bag(path: Path, topics: Iterable[str] | None = None,
             select: Callable[[str, int], bool] | None = None) -> Iterator[tuple[str, str, int, Any]]:
    """(topic, type_name, t_ns, decoded message) in log-time order; fields are attributes.

    :param select: decode and yield only the messages for which ``select(topic, t_ns)`` is true,
        asked in log-time order (decoding is most of the reading: a video's frames need one
        joint state in forty).
    """
    wanted = None if topics is None else set(topics)
    factory = DecoderFactory()
    for file in bag_files(path):
        for schema, channel, message in _iter_file(file, wanted):
            if select is not None and not select(channel.topic, message.log_time):
                continue
            decode = factory.decoder_for(channel.message_encoding, schema)
            if decode is None:
                raise McapError(f"cannot decode {channel.topic}: no ros2msg schema with cdr encoding")
            yield channel.topic, schema.name, message.log_time, decode(message.data)


_TopicKey = tuple[str, str, str, str]  # topic, type, offered QoS YAML, type hash


def _key(schema: Schema | None, channel: Channel) -> _TopicKey:
    metadata = channel.metadata
    return (channel.topic, schema.name if schema else "", metadata.get("offered_qos_profiles", ""),
            metadata.get("topic_type_hash", ""))


def _summary_info(file: Path) -> tuple[dict[_TopicKey, int], int, int] | None:
    try:
        with open(file, "rb") as stream:
            summary = make_reader(stream).get_summary()
    except READ_ERRORS:
        return None
    if summary is None or summary.statistics is None:
        return None
    stats = summary.statistics
    counts: dict[_TopicKey, int] = {}
    for channel_id, channel in summary.channels.items():
        key = _key(summary.schemas.get(channel.schema_id), channel)
        counts[key] = counts.get(key, 0) + stats.channel_message_counts.get(channel_id, 0)
    return counts, stats.message_start_time, stats.message_end_time


def _scanned_info(file: Path) -> tuple[dict[_TopicKey, int], int, int]:
    counts: dict[_TopicKey, int] = {}
    start, end = None, 0
    for schema, channel, message in _iter_file(file, None):
        key = _key(schema, channel)
        counts[key] = counts.get(key, 0) + 1
        start = message.log_time if start is None else min(start, message.log_time)
        end = max(end, message.log_time)
    return counts, start or 0, end


def bag_info(path: Path) -> BagInfo:
    """Topics with types and counts, time range, completeness of a bag.

    :raises FileNotFoundError, NotABagError: see `bag_files`.
    """
    path = Path(path)
    files = bag_files(path)
    counts: dict[_TopicKey, int] = {}
    starts, ends, complete = [], [], True
    for file in files:
        found = _summary_info(file)
        if found is None:
            complete = False
            found = _scanned_info(file)
        file_counts, start, end = found
        for key, n in file_counts.items():
            counts[key] = counts.get(key, 0) + n
        if any(file_counts.values()):
            starts.append(start)
            ends.append(end)
    topics = tuple(TopicInfo(name, type_name, n, qos, hash_string)
                   for (name, type_name, qos, hash_string), n in sorted(counts.items()))
    return BagInfo(
        path=path,
        files=tuple(files),
        topics=topics,
        start_ns=min(starts, default=0),
        end_ns=max(ends, default=0),
        complete=complete,
        has_metadata=path.is_dir() and (path / METADATA_FILE).is_file(),
        size_bytes=sum(f.stat().st_size for f in files),
    )
