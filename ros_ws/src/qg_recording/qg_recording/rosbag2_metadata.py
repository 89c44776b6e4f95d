"""rosbag2's `metadata.yaml` (Jazzy, format version 9): written by us, read by `ros2 bag` and us.

`ros2 bag info/play` refuse a bag directory without this file, so the writer creates it when the
bag opens and rewrites it after every chunk and at close; a killed recorder therefore leaves a
file that describes everything up to its last complete chunk. The text is rendered by hand
(not through a YAML emitter): it is rewritten on the writer thread while the 1 kHz loop runs, and
a pure-Python YAML dump would hold the interpreter lock for milliseconds.
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
    "QOS_RELIABILITIES",
    "BagMetadata",
    "TopicRecord",
    "qos_profiles_yaml",
    "read_metadata",
    "write_metadata",
]

METADATA_FILE = "metadata.yaml"
VERSION = 9
QOS_RELIABILITIES = ("reliable", "best_effort")
_INFINITE = "{sec: 9223372036, nsec: 854775807}"


def _q(text: str) -> str:
    """A YAML double-quoted scalar (JSON string syntax is valid YAML)."""
    return json.dumps(text)


def qos_profiles_yaml(reliability: str, depth: int, indent: str = "") -> str:
    """The one offered QoS profile of a recorded publisher as a rosbag2 YAML list."""
    if reliability not in QOS_RELIABILITIES:
        raise ValueError(f"qos must be one of {QOS_RELIABILITIES}, got {reliability!r}")
    lines = [
        "- history: keep_last",
        f"  depth: {depth}",
        f"  reliability: {reliability}",
        "  durability: volatile",
        f"  deadline: {_INFINITE}",
        f"  lifespan: {_INFINITE}",
        "  liveliness: automatic",
        f"  liveliness_lease_duration: {_INFINITE}",
        "  avoid_ros_namespace_conventions: false",
    ]
    return "\n".join(indent + line for line in lines)


@dataclass
class TopicRecord:
    """One recorded topic and how many of its messages are in complete chunks."""

    name: str
    type_name: str
    reliability: str = "reliable"
    depth: int = 10
    message_count: int = 0


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

    def render(self) -> str:
        """The metadata.yaml text."""
        start, duration, count = self.start_ns, self.duration_ns, self.message_count
        out = [
            "rosbag2_bagfile_information:",
            f"  version: {VERSION}",
            "  storage_identifier: mcap",
            "  duration:",
            f"    nanoseconds: {duration}",
            "  starting_time:",
            f"    nanoseconds_since_epoch: {start}",
            f"  message_count: {count}",
            "  topics_with_message_count:" + ("" if self.topics else " []"),
        ]
        for topic in self.topics:
            out += [
                "    - topic_metadata:",
                f"        name: {_q(topic.name)}",
                f"        type: {_q(topic.type_name)}",
                "        serialization_format: cdr",
                "        offered_qos_profiles:",
                qos_profiles_yaml(topic.reliability, topic.depth, indent="          "),
                '        type_description_hash: ""',
                f"      message_count: {topic.message_count}",
            ]
        out += [
            '  compression_format: ""',
            '  compression_mode: ""',
            "  relative_file_paths:",
            f"    - {_q(self.relative_path)}",
            "  files:",
            f"    - path: {_q(self.relative_path)}",
            "      starting_time:",
            f"        nanoseconds_since_epoch: {start}",
            "      duration:",
            f"        nanoseconds: {duration}",
            f"      message_count: {count}",
            "  custom_data:" + ("" if self.custom_data else " {}"),
        ]
        out += [f"    {_q(k)}: {_q(v)}" for k, v in self.custom_data.items()]
        out.append("  ros_distro: jazzy")
        return "\n".join(out) + "\n"


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
