"""What an episode bag may hold, and the run's bag folder kept within its disk budget.

A training run of thousands of episodes cannot keep every tick of every 1 kHz topic (a 36-step
training episode is about 12-28 MB), so the recording setting (``RecordingPolicy``) chooses:

- ``all``: every tick of every topic in every bag (the default);
- ``rl_rate``: only the RL-rate topics (``RL_RATE_TOPICS``: transitions, episode status,
  setpoints, at-rest events and the latched description, frames and scene), no 1 kHz topic;
- ``every_k``: every bag starts with every topic; once an episode is no longer one of the
  ``keep_last`` most recent ones, its bag keeps its 1 kHz topics only if its ordinal (its
  place among the folder's bags, 0 first) is a multiple of ``every_k``, else it is rewritten
  to its RL-rate copy.

With a budget (``budget_mb`` > 0) the folder's bytes on disk never exceed it: before an episode
starts, and again after it ends, the oldest bags that still hold 1 kHz data are rewritten to
their RL-rate copies until the expected size of the next episode (1.25 times the largest such
bag so far) fits; if nothing is left to drop, the episode records its RL-rate topics only. An
episode larger than expected loses its 1 kHz topics from the moment its bag would reach the
budget (``size_limit``). Transitions and episode summaries are never dropped: when the RL-rate
data alone fills the budget, the next episode is refused. So is one that would leave less than
``min_free_mb`` free on the folder's filesystem. A refusal (``RecordingRefused``) comes before
anything of the episode is written.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import yaml
from mcap.reader import make_reader

from .bag_reader import READ_ERRORS, RawMessage, bag_files, read_raw
from .bag_writer import BagWriter
from .rosbag2_metadata import METADATA_FILE, parse_qos_profiles, read_metadata

__all__ = ["MODES", "RL_RATE_TOPICS", "DiskKeeper", "RecordingPolicy", "RecordingRefused",
           "compact_bag", "disk_bytes", "free_bytes", "holds_high_rate"]

MODES = ("all", "rl_rate", "every_k")
MB = 1024 * 1024
#: Topics published at the RL rate or once per bag: what every mode records.
RL_RATE_TOPICS = frozenset({"/transitions", "/episode_status", "/wrench_setpoint", "/ee_at_rest",
                            "/robot_description", "/tf_static", "/scene_markers"})
#: [bytes] an RL-rate bag is expected to stay below this until one has been measured.
_RL_GUESS = 256 * 1024
#: Where a bag's RL-rate copy is written before it replaces the bag.
_WORK_DIR = ".compacting"


class RecordingRefused(RuntimeError):
    """An episode that must not be recorded (disk nearly full, budget full of RL-rate data)."""


@dataclass(frozen=True)
class RecordingPolicy:
    """The ``recording`` parameters of the recorder (``config/recorder.yaml``).

    :param mode: ``all``, ``rl_rate`` or ``every_k`` (see the module).
    :param every_k: with ``every_k``, bags whose ordinal is a multiple of it keep their 1 kHz data.
    :param keep_last: with ``every_k``, the most recent episodes that keep their 1 kHz data.
    :param budget_mb: [MiB] the most the bag folder may hold on disk; 0 = no budget.
    :param min_free_mb: [MiB] an episode is refused when less would be left free on the disk.
    """
    mode: str = "all"
    every_k: int = 10
    keep_last: int = 3
    budget_mb: float = 0.0
    min_free_mb: float = 0.0

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"recording.mode must be one of {list(MODES)}, got {self.mode!r}")
        if self.every_k < 1:
            raise ValueError(f"recording.every_k must be >= 1, got {self.every_k}")
        if self.keep_last < 0:
            raise ValueError(f"recording.keep_last must be >= 0, got {self.keep_last}")
        if not self.budget_mb >= 0.0:
            raise ValueError(f"recording.budget_mb must be >= 0 (0 = none), got {self.budget_mb}")
        if not self.min_free_mb >= 0.0:
            raise ValueError(f"recording.min_free_mb must be >= 0, got {self.min_free_mb}")

    @property
    def budget_bytes(self) -> int:
        return int(self.budget_mb * MB)


def _entry_bytes(st: os.stat_result) -> int:
    """Bytes a file or directory takes: its allocated blocks or its length, the larger."""
    return max(st.st_size, st.st_blocks * 512)


def disk_bytes(path: Path) -> int:
    """Bytes under ``path`` on disk (files and directories, as ``du`` counts them, or their
    lengths where larger); 0 if it does not exist."""
    total = 0
    stack = [Path(path)]
    while stack:
        try:
            with os.scandir(stack.pop()) as entries:
                for entry in entries:
                    try:
                        total += _entry_bytes(entry.stat(follow_symlinks=False))
                        if entry.is_dir(follow_symlinks=False):
                            stack.append(Path(entry.path))
                    except FileNotFoundError:
                        continue
        except (FileNotFoundError, NotADirectoryError):
            continue
    return total


def free_bytes(path: Path) -> int:
    """Bytes free for an unprivileged writer on the filesystem of ``path`` (or of its nearest
    existing parent: the folder may not exist yet)."""
    path = Path(path).absolute()
    while not path.exists():
        path = path.parent
    st = os.statvfs(path)
    return st.f_bavail * st.f_frsize


_TOPIC_NAME = re.compile(r'\bname:\s*"?([^"\n]+?)"?\s*\n')
_TOPIC_COUNT = re.compile(r"\n\s*message_count:\s*(\d+)")


def holds_high_rate(bag: Path) -> bool:
    """Whether a bag directory holds messages of a topic that is not RL-rate (from its
    metadata.yaml; a bag without one is assumed to).

    Each topic entry's name and count are read by pattern (a resumed run's keeper reads every
    bag's: a YAML parse took 23 ms a bag), the whole file parsed only if that fails.
    """
    try:
        text = (bag / METADATA_FILE).read_text()
    except OSError:
        return True
    entries = text.split("- topic_metadata:")[1:]
    found = [(_TOPIC_NAME.search(e), _TOPIC_COUNT.search(e)) for e in entries]
    if all(name and count for name, count in found):
        return any(name.group(1) not in RL_RATE_TOPICS and int(count.group(1))
                   for name, count in found)
    try:
        topics = read_metadata(bag).get("topics_with_message_count") or []
    except (FileNotFoundError, ValueError):
        return True
    return any(t["topic_metadata"]["name"] not in RL_RATE_TOPICS and t.get("message_count", 0)
               for t in topics)


def _rl_messages(bag: Path) -> list[RawMessage]:
    """The RL-rate messages of a bag in log-time order; through the MCAP summary's chunk
    index where the bag has one (chunks without an RL-rate message stay unread)."""
    files = bag_files(bag)
    try:
        out = []
        for file in files:
            with open(file, "rb") as stream:
                for schema, channel, message in make_reader(stream).iter_messages(
                        topics=sorted(RL_RATE_TOPICS), log_time_order=True):
                    out.append(RawMessage(channel.topic, schema.name if schema else "",
                                          message.log_time, message.data))
        return out
    except READ_ERRORS:  # no summary (a killed recorder): scan the file
        return list(read_raw(bag, RL_RATE_TOPICS))


def compact_bag(bag: Path, reason: str) -> int:
    """Replace a closed bag by its RL-rate copy (same directory and file names, same topics'
    QoS and custom data, plus ``high_rate_dropped: reason``); returns its bytes on disk.

    The copy is written beside the folder's bags (``.compacting/``) and swapped in by renames,
    so at every moment the episode has one complete bag; its files keep the original's
    modification time.
    """
    bag = Path(bag)
    meta = read_metadata(bag)
    custom = {str(k): str(v) for k, v in (meta.get("custom_data") or {}).items()}
    custom["high_rate_dropped"] = reason
    qos = {}
    for t in meta.get("topics_with_message_count") or []:
        topic = t["topic_metadata"]
        if topic["name"] in RL_RATE_TOPICS:
            offered = topic.get("offered_qos_profiles") or ""
            if not isinstance(offered, str):        # metadata.yaml holds it as YAML text
                offered = yaml.safe_dump(offered)
            reliability, durability, depth = parse_qos_profiles(offered)
            qos[topic["name"]] = (topic["type"], reliability, depth, durability)
    messages = _rl_messages(bag)
    work = bag.parent / _WORK_DIR
    copy = work / bag.name
    if copy.exists():
        shutil.rmtree(copy)
    with BagWriter(copy, custom_data=custom) as writer:
        for name, (type_name, reliability, depth, durability) in qos.items():
            writer.add_topic(name, type_name, reliability, depth, durability)
        for m in messages:
            if not writer.has_topic(m.topic):
                writer.add_topic(m.topic, m.type_name)
            writer.write(m.topic, m.data, m.t_ns)
    # the copy keeps the time it was recorded at: a resumed run's keeper orders bags by it
    recorded = (bag / METADATA_FILE).stat().st_mtime_ns
    for file in copy.iterdir():
        os.utime(file, ns=(recorded, recorded))
    old = work / f"{bag.name}.old"
    os.replace(bag, old)
    os.replace(copy, bag)
    shutil.rmtree(old)
    try:
        work.rmdir()
    except OSError:
        pass
    return disk_bytes(bag)


@dataclass
class _Bag:
    """A closed bag of the folder, oldest first."""
    path: Path
    ordinal: int
    bytes: int
    high_rate: bool


class DiskKeeper:
    """Applies a ``RecordingPolicy`` to one bag folder: decides whether an episode records its
    1 kHz topics, refuses one that must not start, and drops old 1 kHz data after each episode.

    :param folder: the bag folder (its existing bags count: a resumed run goes on with them).
    :param free_space: bytes free on the folder's filesystem (``free_bytes``; a test passes a
        full disk).
    :param log: where the keeper says what it dropped.
    """

    #: [bytes] what a bag may still grow by beyond its file, queue and open chunk (the block
    #: of ticks after its size was checked, the summary, metadata.yaml's atomic rewrite).
    margin: int = 256 * 1024

    def __init__(self, folder: Path, policy: RecordingPolicy,
                 free_space: Callable[[Path], int] = free_bytes,
                 log: Callable[[str], None] = lambda _: None) -> None:
        self.folder = Path(folder)
        self.policy = policy
        self.free_space = free_space
        self.log = log
        self.bags: list[_Bag] = []
        self.largest = {True: 0, False: 0}   # the largest bag so far, with and without 1 kHz
        # Only a policy that drops data needs the bags already there (a resumed run's).
        if (policy.mode != "all" or policy.budget_bytes) and self.folder.is_dir():
            found = [p for p in self.folder.iterdir()
                     if p.is_dir() and (p / METADATA_FILE).is_file()]
            found.sort(key=lambda p: ((p / METADATA_FILE).stat().st_mtime, p.name))
            for ordinal, path in enumerate(found):
                self._add(path, ordinal, holds_high_rate(path))

    def _add(self, path: Path, ordinal: int, high_rate: bool) -> _Bag:
        bag = _Bag(path, ordinal, disk_bytes(path), high_rate)
        self.bags.append(bag)
        self.largest[high_rate] = max(self.largest[high_rate], bag.bytes)
        return bag

    @property
    def next_ordinal(self) -> int:
        return self.bags[-1].ordinal + 1 if self.bags else 0

    def expected_bytes(self, high_rate: bool) -> int:
        """What the next episode is expected to take: twice the largest RL-rate bag so far (at
        least a first guess); with its 1 kHz topics, 1.25 times the largest such bag besides,
        and the ``margin`` (``plan``'s size limit leaves room for both)."""
        rl = max(2 * self.largest[False], _RL_GUESS)
        if not high_rate:
            return rl
        return self.largest[True] * 5 // 4 + rl + self.margin

    def plan(self, episode_id: str) -> tuple[bool, int | None]:
        """Whether the next episode records its 1 kHz topics, and the bytes its bag may reach
        while it does (None: no budget). Drops old 1 kHz data to make room.

        :raises RecordingRefused: with the reason, when the disk is nearly full or the budget
            is full of RL-rate data; nothing is written then.
        """
        policy = self.policy
        high_rate = policy.mode == "all" or (policy.mode == "every_k" and (
            policy.keep_last > 0 or self.next_ordinal % policy.every_k == 0))
        budget = policy.budget_bytes
        if budget:
            high_rate = self.make_room(self.expected_bytes(high_rate)) and high_rate
            used = disk_bytes(self.folder)
            if used + self.expected_bytes(False) > budget:
                raise RecordingRefused(
                    f"recording refused for {episode_id}: the bag folder {self.folder} holds "
                    f"{used / MB:.1f} MiB with no 1 kHz data left to drop, and the next episode's "
                    f"{self.expected_bytes(False) / MB:.2f} MiB would exceed recording.budget_mb "
                    f"= {policy.budget_mb:g} (transitions are never dropped: raise the budget "
                    "or use another folder)")
        need = self.expected_bytes(high_rate)
        free = self.free_space(self.folder) if policy.min_free_mb else 0
        if policy.min_free_mb and free - need < policy.min_free_mb * MB:
            raise RecordingRefused(
                f"recording refused for {episode_id}: the disk of {self.folder} has "
                f"{free / MB:.1f} MiB free, and the episode's expected {need / MB:.1f} MiB would "
                f"leave less than recording.min_free_mb = {policy.min_free_mb:g} MiB")
        if not budget:
            return high_rate, None
        # The 1 kHz topics stop where the rest of the episode (queued rows, its RL-rate
        # messages) could no longer fit.
        limit = budget - disk_bytes(self.folder) - self.margin - self.expected_bytes(False)
        return high_rate and limit > 0, limit

    def make_room(self, need: int) -> bool:
        """Rewrite the oldest bags with 1 kHz data to their RL-rate copies until the folder
        plus ``need`` fits the budget; False if it still does not."""
        budget = self.policy.budget_bytes
        if not budget:
            return True
        used = disk_bytes(self.folder)
        for bag in self.bags:
            if used + need <= budget:
                break
            if bag.high_rate:
                used -= self._compact(bag, f"recording.budget_mb = {self.policy.budget_mb:g}")
        return used + need <= budget

    def _compact(self, bag: _Bag, reason: str) -> int:
        """Drop a bag's 1 kHz data; returns the bytes freed."""
        before = disk_bytes(bag.path)
        bag.bytes, bag.high_rate = compact_bag(bag.path, reason), False
        self.largest[False] = max(self.largest[False], bag.bytes)
        self.log(f"dropped the 1 kHz data of {bag.path.name} ({reason}): "
                 f"{before / MB:.2f} -> {bag.bytes / MB:.3f} MiB")
        return before - bag.bytes

    def closed(self, path: Path, high_rate: bool) -> int:
        """A bag closed (``high_rate``: it may hold 1 kHz data): drop the 1 kHz data the policy
        no longer keeps and make room for the next episode; returns the bag's bytes on disk."""
        bag = self._add(Path(path), self.next_ordinal, high_rate and holds_high_rate(Path(path)))
        written, policy = bag.bytes, self.policy
        if policy.mode == "every_k":
            recent = {b.ordinal for b in self.bags[-policy.keep_last:]} if policy.keep_last else set()
            for old in self.bags:
                if old.high_rate and old.ordinal not in recent and old.ordinal % policy.every_k:
                    self._compact(old, f"recording.mode every_k = {policy.every_k}, "
                                       f"keep_last = {policy.keep_last}")
        if policy.budget_bytes:
            self.make_room(self.expected_bytes(policy.mode != "rl_rate"))
        return written
