"""rosbag2's `metadata.yaml` (Jazzy, format version 9): written by us, read by `ros2 bag` and us.

`ros2 bag info/play` refuse a bag directory without this file, so the writer creates it when the
bag opens and rewrites it after every chunk and at close; a killed recorder therefore leaves a
file that describes everything up to its last complete chunk. The text is rendered by hand
(not through a YAML emitter): it is rewritten on the writer thread while the 1 kHz loop runs, and
a pure-Python YAML dump would hold the interpreter lock for milliseconds.

The same mapping, without the `rosbag2_bagfile_information` key, is what rosbag2's MCAP storage
plugin stores as `serialized_metadata` in the file's `rosbag2` metadata record when it closes
(`MCAPStorage::update_metadata`), so a lone `.mcap` file keeps its distro and custom data.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "METADATA_FILE",
    "QOS_DURABILITIES",
    "QOS_RELIABILITIES",
    "ROS_DISTRO",
    "BagMetadata",
    "TopicRecord",
    "parse_qos_profiles",
    "qos_profiles_yaml",
    "read_metadata",
    "write_metadata",
]

METADATA_FILE = "metadata.yaml"
VERSION = 9
ROS_DISTRO = "jazzy"
QOS_RELIABILITIES = ("reliable", "best_effort")
QOS_DURABILITIES = ("volatile", "transient_local")
_INFINITE = "{sec: 9223372036, nsec: 854775807}"


def _q(text: str) -> str:
    """A YAML double-quoted scalar (JSON string syntax is valid YAML)."""
    return json.dumps(text)


def check_qos(reliability: str, durability: str) -> None:
    """:raises ValueError: for a reliability or durability rosbag2 would not write."""
    if reliability not in QOS_RELIABILITIES:
        raise ValueError(f"qos must be one of {QOS_RELIABILITIES}, got {reliability!r}")
    if durability not in QOS_DURABILITIES:
        raise ValueError(f"durability must be one of {QOS_DURABILITIES}, got {durability!r}")


def qos_profiles_yaml(reliability: str, depth: int, indent: str = "", durability: str = "volatile") -> str:
    """The one offered QoS profile of a recorded publisher as a rosbag2 YAML list."""
    check_qos(reliability, durability)
    lines = [
        "- history: keep_last",
        f"  depth: {depth}",
        f"  reliability: {reliability}",
        f"  durability: {durability}",
        f"  deadline: {_INFINITE}",
        f"  lifespan: {_INFINITE}",
        "  liveliness: automatic",
        f"  liveliness_lease_duration: {_INFINITE}",
        "  avoid_ros_namespace_conventions: false",
    ]
    return "\n".join(indent + line for line in lines)


def parse_qos_profiles(offered_yaml: str) -> tuple[str, str, int]:
    """(reliability, durability, depth) of the first profile of a recorded offered-QoS YAML list,
    by name (version 9) or rmw enum value (older bags); reliable, volatile, 10 where missing,
    unreadable or 0 (rosbag2 records the graph's depth, which is 0)."""
    try:
        profiles = yaml.safe_load(offered_yaml) or [{}]
        profile = profiles[0] if isinstance(profiles, list) and isinstance(profiles[0], dict) else {}
    except yaml.YAMLError:
        profile = {}
    best_effort = profile.get("reliability") in ("best_effort", 2)
    latched = profile.get("durability") in ("transient_local", 1)
    try:
        depth = int(profile.get("depth") or 10)
    except (TypeError, ValueError):
        depth = 10
    return ("best_effort" if best_effort else "reliable", "transient_local" if latched else "volatile",
            depth if depth > 0 else 10)


@dataclass
class TopicRecord:
    """One recorded topic and how many of its messages are in complete chunks."""

    name: str
    type_name: str
    reliability: str = "reliable"
    depth: int = 10
    message_count: int = 0
    durability: str = "volatile"
    type_hash: str = ""  # RIHS01 of the type ("" if no type description is installed)


@dataclass
class BagMetadata:
    """What `metadata.yaml` states about a one-file bag."""

    relative_path: str
    topics: list[TopicRecord] = field(default_factory=list)
    start_ns: int = 0
    end_ns: int = 0
    custom_data: dict[str, str] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        return sum(topic.message_count for topic in self.topics)

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    def serialized(self) -> str:
        """The mapping alone (rosbag2's `serialized_metadata` in the MCAP `rosbag2` record)."""
        start, duration, count = self.start_ns, self.duration_ns, self.message_count
        out = [
            f"version: {VERSION}",
            "storage_identifier: mcap",
            "duration:",
            f"  nanoseconds: {duration}",
            "starting_time:",
            f"  nanoseconds_since_epoch: {start}",
            f"message_count: {count}",
            "topics_with_message_count:" + ("" if self.topics else " []"),
        ]
        for topic in self.topics:
            out += [
                "  - topic_metadata:",
                f"      name: {_q(topic.name)}",
                f"      type: {_q(topic.type_name)}",
                "      serialization_format: cdr",
                "      offered_qos_profiles:",
                qos_profiles_yaml(topic.reliability, topic.depth, "        ", topic.durability),
                f"      type_description_hash: {_q(topic.type_hash)}",
                f"    message_count: {topic.message_count}",
            ]
        out += [
            'compression_format: ""',
            'compression_mode: ""',
            "relative_file_paths:",
            f"  - {_q(self.relative_path)}",
            "files:",
            f"  - path: {_q(self.relative_path)}",
            "    starting_time:",
            f"      nanoseconds_since_epoch: {start}",
            "    duration:",
            f"      nanoseconds: {duration}",
            f"    message_count: {count}",
            "custom_data:" + ("" if self.custom_data else " {}"),
        ]
        out += [f"  {_q(k)}: {_q(v)}" for k, v in self.custom_data.items()]
        out.append(f"ros_distro: {ROS_DISTRO}")
        return "\n".join(out) + "\n"

    def render(self) -> str:
        """The metadata.yaml text."""
        return "rosbag2_bagfile_information:\n" + "".join(f"  {line}\n" for line in self.serialized().splitlines())


def write_metadata(directory: Path, metadata: BagMetadata) -> None:
    """Replace `directory/metadata.yaml` atomically (a kill mid-write leaves the old file)."""
    target = directory / METADATA_FILE
    tmp = target.with_suffix(".yaml.tmp")
    tmp.write_text(metadata.render())
    os.replace(tmp, target)


def read_metadata(directory: Path) -> dict[str, Any]:
    """The `rosbag2_bagfile_information` mapping of a bag directory.

    :raises FileNotFoundError: if there is no metadata.yaml.
    :raises ValueError: if it is not a rosbag2 metadata file.
    """
    try:
        data = yaml.safe_load((directory / METADATA_FILE).read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f"{directory / METADATA_FILE} is not valid YAML: {exc}") from None
    if not isinstance(data, dict) or "rosbag2_bagfile_information" not in data:
        raise ValueError(f"{directory / METADATA_FILE} is not a rosbag2 metadata file")
    return data["rosbag2_bagfile_information"]
