"""Making a bag whole again after its recorder was killed, as `ros2 bag reindex` does.

A recorder killed with SIGKILL leaves an MCAP file without summary, footer and closing magic;
our reader reads it up to its last complete chunk, but stock readers refuse it (`rosbags`: "File
end magic is invalid"). `reindex` rewrites such a file with every record that can still be read
(schemas, channels, complete chunks, metadata) followed by the `rosbag2` metadata record,
summary and footer, and then regenerates `metadata.yaml` from the files, as `ros2 bag reindex`
does. The rewrite goes to a temporary file that replaces the original only once complete, so
an interrupted reindex leaves the bag as it was. A file that was closed cleanly is not touched.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from .bag_reader import READ_ERRORS, bag_files, bag_info, top_level_records
from .mcap_stream import ChunkStats, McapStream
from .rosbag2_metadata import (
    METADATA_FILE,
    ROS_DISTRO,
    BagMetadata,
    TopicRecord,
    parse_qos_profiles,
    read_metadata,
    write_metadata,
)

__all__ = ["ReindexResult", "reindex"]

LIBRARY = "qg_recording reindex"


@dataclass(frozen=True)
class ReindexResult:
    """What `reindex` did."""

    files: tuple[Path, ...]
    repaired: tuple[Path, ...]  # files that had no summary and were rewritten
    messages: int


def _topic(name: str, type_name: str, offered_qos_yaml: str, type_hash: str) -> TopicRecord:
    """The metadata.yaml entry of a recorded topic."""
    reliability, durability, depth = parse_qos_profiles(offered_qos_yaml)
    return TopicRecord(name, type_name, reliability, depth, durability=durability, type_hash=type_hash)


def _rewrite(file: Path, metadata: BagMetadata) -> None:
    """Replace `file` by a complete copy of its readable records; fills `metadata`."""
    tmp = file.with_name(file.name + ".reindex")
    try:
        _write_repaired(file, tmp, metadata)
    except BaseException:
        tmp.unlink(missing_ok=True)  # the original stays as it was
        raise
    os.replace(tmp, file)


def _write_repaired(file: Path, tmp: Path, metadata: BagMetadata) -> None:
    """Copy every readable record of `file` to `tmp` (chunk by chunk, as they were), then the
    `rosbag2` record, summary and footer."""
    schemas: dict[int, int] = {}  # old id -> new id
    channels: dict[int, int] = {}
    topics: dict[int, TopicRecord] = {}  # new channel id -> record
    with open(tmp, "wb") as stream:
        records = list(top_level_records(file))
        compression = next((r.compression for r in records if isinstance(r, Chunk)), "zstd")
        mcap = McapStream(stream, LIBRARY, compression if compression in ("zstd", "") else "zstd")
        known: dict[int, Schema] = {}

        def add(record: object) -> None:
            if isinstance(record, Schema) and record.id not in schemas:
                known[record.id] = record
                schemas[record.id] = mcap.add_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel) and record.id not in channels:
                new_id = mcap.add_channel(record.topic, record.message_encoding, schemas.get(record.schema_id, 0),
                                          dict(record.metadata))
                channels[record.id] = new_id
                schema = known.get(record.schema_id)
                topics[new_id] = _topic(record.topic, schema.name if schema else "",
                                        record.metadata.get("offered_qos_profiles", ""),
                                        record.metadata.get("topic_type_hash", ""))
            elif isinstance(record, Message) and record.channel_id in channels:
                mcap.add_message(channels[record.channel_id], record.log_time, record.data, record.publish_time)
            elif isinstance(record, Metadata) and record.name != "rosbag2":
                mcap.add_metadata(record.name, dict(record.metadata))

        spans: list[tuple[int, int]] = []

        def count(chunk: ChunkStats | None) -> None:
            if chunk is not None:
                for channel_id, n in chunk.counts.items():
                    topics[channel_id].message_count += n
                spans.append((chunk.start_ns, chunk.end_ns))

        for record in records:
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except READ_ERRORS:
                    continue  # damaged on disk: the rest of the file is still good
                for item in inner:
                    add(item)
                count(mcap.close_chunk())  # the original chunk boundaries
            else:
                add(record)
        count(mcap.close_chunk())
        metadata.topics = sorted(topics.values(), key=lambda t: (t.name, t.type_name))  # as bag_info lists them
        if spans:
            metadata.start_ns, metadata.end_ns = min(a for a, _ in spans), max(b for _, b in spans)
        mcap.add_metadata("rosbag2", {"serialized_metadata": metadata.serialized(), "ROS_DISTRO": ROS_DISTRO})
        mcap.finish()


def reindex(path: Path) -> ReindexResult:
    """Repair the bag's MCAP files that have no summary and regenerate its metadata.yaml.

    :param path: a bag directory (metadata.yaml is rewritten) or a single `.mcap` file.
    :raises FileNotFoundError, NotABagError: see `bag_reader.bag_files`.
    """
    path = Path(path)
    files = bag_files(path)
    custom: dict[str, str] = {}
    if path.is_dir() and (path / METADATA_FILE).is_file():
        try:
            custom = {str(k): str(v) for k, v in (read_metadata(path).get("custom_data") or {}).items()}
        except ValueError:
            custom = {}  # unreadable: regenerated without the custom data
    repaired = []
    for file in files:
        if not bag_info(file).complete:
            _rewrite(file, BagMetadata(relative_path=file.name, custom_data=custom))
            repaired.append(file)
    info = bag_info(path)
    if path.is_dir():
        topics = [_topic(t.name, t.type_name, t.qos, t.type_hash) for t in info.topics]
        for record, topic in zip(topics, info.topics):
            record.message_count = topic.message_count
        write_metadata(path, BagMetadata(relative_path=files[0].name, topics=topics, start_ns=info.start_ns,
                                         end_ns=info.end_ns, custom_data=custom))
    return ReindexResult(tuple(files), tuple(repaired), info.message_count)
