"""A rosbag2-layout bag (metadata.yaml + one MCAP file) written on a background thread.

The 1 kHz loop must never wait for the disk or for compression, and no message may be dropped:
`write()` (one serialized message) and `write_rows()` (a block of fixed-layout messages, still
as numbers) only append to an unbounded deque and set an event (about a microsecond, thread
safe). A writer thread, asleep otherwise, encodes the blocks and drains everything into the
MCAP file, closes a zstd chunk every `chunk_size` bytes and then rewrites metadata.yaml. Every
`flush_interval_s` it also collects what the producer still buffers (the `collect` hook: the
recorder's row buffers), writes everything produced until then and closes the chunk. A chunk
is flushed to the kernel as soon as it is complete, so a SIGKILL loses at most the chunk in
progress: at most about `flush_interval_s` seconds of every topic. `close()` (also run at interpreter exit, e.g. after Ctrl-C)
drains the queue and writes, as rosbag2's MCAP storage plugin does when it closes, the `rosbag2`
metadata record (`serialized_metadata`, `ROS_DISTRO`) and the MCAP summary. With a long backlog
the writer thread gives up the interpreter lock between batches, so the loop thread never waits
long for it.

Each channel carries what rosbag2 records for a topic: the publisher's offered QoS and the
type's RIHS01 hash (`topic_type_hash`), read from the installed type description.
"""

from __future__ import annotations

import atexit
import threading
import time
import warnings
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from .cdr import FixedLayout
from .mcap_stream import ChunkStats, McapStream
from .rosbag2_metadata import (
    ROS_DISTRO,
    BagMetadata,
    TopicRecord,
    check_qos,
    qos_profiles_yaml,
    write_metadata,
)
from .schemas import TypeHashNotFoundError, normalize_type_name, schema_text, type_hash

__all__ = ["BagWriter", "bag_file_name"]

LIBRARY = "qg_recording"
_COMPRESSIONS = {"zstd": "zstd", "none": ""}
_BATCH = 64  # queue items between two voluntary releases of the interpreter lock
#: [bytes] an MCAP message record's fields besides its data, and its message index entry
_PER_MESSAGE = 31 + 16


def bag_file_name(directory: Path) -> str:
    """rosbag2's name for the first (only) storage file of a bag directory."""
    return f"{directory.name}_0.mcap"


class BagWriter:
    """Writes serialized (CDR) messages of registered topics into `directory`.

    :param directory: the bag directory; created, must not already contain a bag.
    :param chunk_size: uncompressed bytes per MCAP chunk (the most a SIGKILL can lose).
    :param compression: chunk compression, "zstd" or "none".
    :param flush_interval_s: also close a chunk this long after its first message, so slow
        topics reach the disk too.
    :param custom_data: strings stored in rosbag2's `custom_data` (metadata.yaml and the MCAP
        `rosbag2` record).
    :param collect: called on the writer thread every `flush_interval_s`, to queue the messages
        the producer still buffers; it must only call `write`/`write_rows`.
    """

    def __init__(
        self,
        directory: Path,
        chunk_size: int = 512 * 1024,
        compression: str = "zstd",
        flush_interval_s: float = 1.0,
        custom_data: Mapping[str, str] | None = None,
        collect: Callable[[], None] | None = None,
    ) -> None:
        if chunk_size < 1024:
            raise ValueError(f"chunk_size must be at least 1024 bytes, got {chunk_size}")
        if compression not in _COMPRESSIONS:
            raise ValueError(f"compression must be one of {sorted(_COMPRESSIONS)}, got {compression!r}")
        if flush_interval_s <= 0.0:
            raise ValueError(f"flush_interval_s must be positive, got {flush_interval_s}")
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        file_name = bag_file_name(self.directory)
        if (self.directory / file_name).exists():
            raise FileExistsError(f"{self.directory} already holds a bag")
        self.path = self.directory / file_name
        self._chunk_size = chunk_size
        self._flush_interval_s = flush_interval_s
        custom = {str(k): str(v) for k, v in (custom_data or {}).items()}

        self._stream = open(self.path, "wb")
        self._mcap = McapStream(self._stream, LIBRARY, _COMPRESSIONS[compression])
        self._stream.flush()  # a bag killed before its first chunk still starts with MCAP magic
        self._metadata = BagMetadata(relative_path=file_name, custom_data=custom)
        write_metadata(self.directory, self._metadata)

        self._lock = threading.Lock()  # the file and the metadata: add_topic vs. writer thread
        # (channel, t_ns, bytes) or (channel, t_ns array, (layout, value rows))
        self._queue: deque[tuple[int, Any, Any]] = deque()
        self._channels: dict[str, int] = {}
        self._topics: dict[int, TopicRecord] = {}
        self._schemas: dict[str, int] = {}
        self._collect = collect
        self._flushed_at = time.monotonic()  # the last `_flush`
        self.messages_written = 0  # handed to the MCAP file so far (by the writer thread)
        # Uncompressed bytes queued (producer) and taken off the queue (writer thread): one
        # writer each, so neither needs a lock.
        self._enqueued = 0
        self._dequeued = 0
        self._accepting = True
        self._error: BaseException | None = None
        self._closing = threading.Event()
        self._wake = threading.Event()  # set by every write: the writer thread sleeps otherwise
        self._thread = threading.Thread(target=self._run, name=f"bag-writer:{self.directory.name}", daemon=True)
        self._thread.start()
        atexit.register(self.close)

    # -- producer side -------------------------------------------------------------------------

    def add_topic(
        self, name: str, type_name: str, qos: str = "reliable", depth: int = 10, durability: str = "volatile",
    ) -> None:
        """Register a topic before writing to it; repeating a registration is a no-op.

        :param type_name: `pkg/msg/Type`; its `.msg` definition must be findable.
        :param qos, depth, durability: the publisher's offered QoS ("reliable" or "best_effort",
            history depth, "volatile" or "transient_local"), which replay offers again.
        :raises ValueError: on an invalid qos or a topic re-registered with another type.
        """
        check_qos(qos, durability)
        pkg, msg = normalize_type_name(type_name)
        type_name = f"{pkg}/msg/{msg}"
        if name in self._channels:
            known = self._topics[self._channels[name]].type_name
            if known != type_name:
                raise ValueError(f"topic {name} is recorded as {known}, not {type_name}")
            return
        schema = schema_text(type_name).encode()
        try:
            hash_string = type_hash(type_name)
        except TypeHashNotFoundError as exc:  # recordable all the same: rosbag2 then writes ""
            warnings.warn(f"{exc}; recording {name} without a type hash", stacklevel=2)
            hash_string = ""
        with self._lock:
            schema_id = self._schemas.get(type_name)
            if schema_id is None:
                schema_id = self._mcap.add_schema(type_name, "ros2msg", schema)
                self._schemas[type_name] = schema_id
            metadata = {"offered_qos_profiles": qos_profiles_yaml(qos, depth, durability=durability) + "\n",
                        "topic_type_hash": hash_string}
            channel_id = self._mcap.add_channel(name, "cdr", schema_id, metadata)
            record = TopicRecord(name, type_name, qos, depth, durability=durability, type_hash=hash_string)
            self._metadata.topics.append(record)
            self._topics[channel_id] = record
            self._channels[name] = channel_id

    def has_topic(self, name: str) -> bool:
        return name in self._channels

    def topic_type(self, name: str) -> str | None:
        """The `pkg/msg/Type` a topic was added with, None if it was not."""
        channel = self._channels.get(name)
        return None if channel is None else self._topics[channel].type_name

    def set_custom(self, key: str, value: str) -> None:
        """Add or change one `custom_data` entry (metadata.yaml from its next rewrite on)."""
        with self._lock:
            self._metadata.custom_data[str(key)] = str(value)

    def write(self, topic: str, data: bytes, t_ns: int) -> None:
        """Queue one serialized message (log and publish time `t_ns`); never blocks.

        :raises ValueError: if the topic was not added.
        :raises RuntimeError: after close() or if the writer thread failed.
        """
        if not self._accepting:
            self._raise_not_accepting()
        try:
            self._queue.append((self._channels[topic], t_ns, data))
        except KeyError:
            raise ValueError(f"topic {topic} was not added to the bag") from None
        self._enqueued += len(data) + _PER_MESSAGE
        self._wake.set()

    def write_rows(self, topic: str, layout: FixedLayout, t_ns: np.ndarray, values: np.ndarray) -> None:
        """Queue len(t_ns) messages of a fixed layout from their numbers; never blocks.

        :param values: (len(t_ns), layout.n_values) rows; the writer thread encodes them, so the
            caller must not modify the arrays afterwards.
        :raises ValueError: if the topic was not added or has another type.
        """
        if not self._accepting:
            self._raise_not_accepting()
        if self.topic_type(topic) != layout.type_name:
            raise ValueError(f"topic {topic} was not added to the bag as {layout.type_name}")
        self._queue.append((self._channels[topic], t_ns, (layout, values)))
        self._enqueued += len(t_ns) * (layout.size + _PER_MESSAGE)
        self._wake.set()

    @property
    def unwritten_bytes(self) -> int:
        """Uncompressed bytes queued or in the open chunk: at most what the file grows by
        before the next write (give or take the summary and zstd's few bytes per chunk)."""
        return self._enqueued - self._dequeued + self._mcap.chunk_bytes

    def close(self) -> None:
        """Write every queued message, the MCAP summary and the final metadata.yaml."""
        if self._closing.is_set():
            self._thread.join()
            return
        self._accepting = False
        self._closing.set()
        self._wake.set()
        self._thread.join()
        atexit.unregister(self.close)
        if self._error is not None:
            raise RuntimeError(f"bag writer for {self.directory} failed") from self._error

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _raise_not_accepting(self) -> None:
        if self._error is not None:
            raise RuntimeError(f"bag writer for {self.directory} failed") from self._error
        raise RuntimeError(f"bag {self.directory} is closed")

    # -- writer thread -------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while True:
                self._wake.wait(max(1e-3, self._flush_interval_s - (time.monotonic() - self._flushed_at)))
                self._wake.clear()
                self._drain()
                if self._closing.is_set() and not self._queue:
                    break
                if time.monotonic() - self._flushed_at >= self._flush_interval_s:
                    self._flush()
            with self._lock:
                self._count(self._mcap.close_chunk())
                self._mcap.add_metadata("rosbag2", {"serialized_metadata": self._metadata.serialized(),
                                                    "ROS_DISTRO": ROS_DISTRO})
                self._mcap.finish()
                self._stream.close()
                write_metadata(self.directory, self._metadata)
        except BaseException as exc:  # noqa: BLE001 - reported to the producer by write()/close()
            self._error = exc
            self._accepting = False

    def _drain(self) -> None:
        queue, mcap = self._queue, self._mcap
        while queue:
            for _ in range(min(_BATCH, len(queue))):
                channel, t_ns, payload = queue.popleft()
                if payload.__class__ is bytes:
                    mcap.add_message(channel, t_ns, payload)
                    self.messages_written += 1
                    self._dequeued += len(payload) + _PER_MESSAGE
                else:
                    layout, values = payload
                    mcap.add_rows(channel, t_ns, layout.encode_many(t_ns, values))
                    self.messages_written += len(t_ns)
                    self._dequeued += len(t_ns) * (layout.size + _PER_MESSAGE)
                if mcap.chunk_bytes >= self._chunk_size:
                    self._close_chunk()
            if queue:
                time.sleep(0)  # a long backlog: let the loop thread take the interpreter lock

    def _flush(self) -> None:
        """Every `flush_interval_s`: write everything produced until now, the producer's
        buffers included, and close the chunk (so a SIGKILL loses at most what came since)."""
        if self._collect is not None:
            self._collect()
        self._drain()
        self._close_chunk()
        self._flushed_at = time.monotonic()

    def _close_chunk(self) -> None:
        with self._lock:
            if self._count(self._mcap.close_chunk()):
                write_metadata(self.directory, self._metadata)

    def _count(self, chunk: ChunkStats | None) -> bool:
        """Add a written chunk to the metadata (lock held); False if there was none."""
        if chunk is None:
            return False
        meta = self._metadata
        if meta.message_count == 0:
            meta.start_ns, meta.end_ns = chunk.start_ns, chunk.end_ns
        else:
            meta.start_ns = min(meta.start_ns, chunk.start_ns)
            meta.end_ns = max(meta.end_ns, chunk.end_ns)
        for channel_id, n in chunk.counts.items():
            self._topics[channel_id].message_count += n
        return True
