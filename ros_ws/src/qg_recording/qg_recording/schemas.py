"""ros2msg schema text and type hash of a message type, as rosbag2 writes them into a bag.

A bag must carry the full definition of every recorded type so that any reader (mcap_ros2,
Foxglove, `ros2 bag`) can decode it without our interface package installed. rosbag2 builds the
text from the installed `.msg` files: the root definition verbatim, then every dependency once
(depth first, in sorted order), each preceded by an 80-character `=` line and `MSG: pkg/Type`.
We reproduce that here from the same `.msg` files, found on AMENT_PREFIX_PATH, in this
interpreter's prefix (the venv ships the standard interfaces) and in the colcon install named by
`$QG_ROS_INSTALL` (what the project's scripts set). The definitions are parsed by
`rosidl_adapter`, the parser the ROS 2 wheels ship (the one `rosidl_generate_interfaces` runs).

The type hash (RIHS01, REP 2011) is what the live graph reports for a topic and what rosbag2
records beside it. It is not computed here: it is read from the type description `.json` file
that rosidl generated and installed beside each `.msg` file.
"""

from __future__ import annotations

import functools
import json
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from rosidl_adapter.parser import (
    InvalidSpecification,
    InvalidValue,
    MessageSpecification,
    parse_message_string,
)

__all__ = [
    "Field",
    "MsgNotFoundError",
    "TypeHashNotFoundError",
    "find_msg_file",
    "message_fields",
    "normalize_type_name",
    "schema_text",
    "type_hash",
]

SEPARATOR = "=" * 80
# The type name rosbag2 accepts (LocalMessageDefinitionSource's PACKAGE_TYPENAME_REGEX).
_TYPE_NAME = re.compile(r"^([a-zA-Z0-9_]+)/(?:msg/)?([a-zA-Z0-9_]+)$")


class MsgNotFoundError(LookupError):
    """No `.msg` file for a type name in any searched prefix."""


class TypeHashNotFoundError(LookupError):
    """No installed type description (`.json`) for a type name."""


def normalize_type_name(type_name: str) -> tuple[str, str]:
    """Split `pkg/msg/Type` or `pkg/Type` into `(pkg, Type)`.

    :raises ValueError: for anything else.
    """
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise ValueError(f"not a message type name: {type_name!r} (expected pkg/msg/Type)")
    return match.group(1), match.group(2)


def _search_roots() -> list[Path]:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in prefixes]


def _candidates(pkg: str, file_name: str) -> list[Path]:
    """Where `share/<pkg>/msg/<file_name>` may be: the ament prefixes, this interpreter's prefix,
    then the workspace's colcon install (before `source install/setup.bash`)."""
    candidates = [root / pkg / "msg" / file_name for root in _search_roots()]
    install = os.environ.get("QG_ROS_INSTALL")
    if install:
        candidates.append(Path(install) / pkg / "share" / pkg / "msg" / file_name)
    return candidates


def find_msg_file(type_name: str) -> Path:
    """Path of the `.msg` file defining `type_name`.

    :raises MsgNotFoundError: if no searched directory has it.
    """
    pkg, name = normalize_type_name(type_name)
    candidates = _candidates(pkg, f"{name}.msg")
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    searched = ", ".join(str(c.parent) for c in candidates)
    raise MsgNotFoundError(f"no definition of {pkg}/msg/{name} (searched {searched})")


@functools.cache
def type_hash(type_name: str) -> str:
    """The RIHS01 type hash of `pkg/msg/Type`, as the graph reports it for a topic of that type.

    :raises TypeHashNotFoundError: if no installed type description names the type.
    """
    pkg, name = normalize_type_name(type_name)
    full_name = f"{pkg}/msg/{name}"
    candidates = _candidates(pkg, f"{name}.json")
    for candidate in candidates:
        if candidate.is_file():
            for entry in json.loads(candidate.read_text()).get("type_hashes", []):
                if entry.get("type_name") == full_name:
                    return str(entry["hash_string"])
    searched = ", ".join(str(c.parent) for c in candidates)
    raise TypeHashNotFoundError(f"no installed type description of {full_name} (searched {searched})")


@functools.cache
def _definition(pkg: str, name: str) -> tuple[str, MessageSpecification]:
    """The `.msg` text of `pkg/name` and its parsed specification.

    :raises ValueError: if rosidl's parser rejects the definition.
    """
    path = find_msg_file(f"{pkg}/{name}")
    text = path.read_text()
    try:
        return text, parse_message_string(pkg, name, text)
    except (InvalidSpecification, InvalidValue, ValueError) as exc:
        raise ValueError(f"{path}: not a valid message definition: {exc}") from None


def _dependencies(spec: MessageSpecification) -> tuple[str, ...]:
    """The message types a definition uses, as `pkg/Type`, sorted (rosbag2's order)."""
    return tuple(sorted({f"{f.type.pkg_name}/{f.type.type}" for f in spec.fields
                         if not f.type.is_primitive_type()}))


@dataclass(frozen=True)
class Field:
    """One field of a message definition.

    :param type_name: a primitive ("float64", "string", ...) or a message type `pkg/msg/Type`.
    :param array: None for a single value, N for a fixed array `[N]`, -1 for a sequence
        (`[]` or bounded `[<=N]`).
    """

    type_name: str
    name: str
    array: int | None


@functools.cache
def message_fields(type_name: str) -> tuple[Field, ...]:
    """The fields of a message type in definition order (constants skipped).

    :raises MsgNotFoundError: if the type has no `.msg` file; ValueError for a malformed one.
    """
    _, spec = _definition(*normalize_type_name(type_name))
    fields = []
    for field in spec.fields:
        t = field.type
        base = t.type if t.is_primitive_type() else f"{t.pkg_name}/msg/{t.type}"
        if not t.is_array:
            array = None
        else:
            array = -1 if t.is_upper_bound or t.array_size is None else int(t.array_size)
        fields.append(Field(base, field.name, array))
    return tuple(fields)


@functools.cache
def schema_text(type_name: str) -> str:
    """Full ros2msg schema of `type_name` (`pkg/msg/Type`) with all its dependencies inlined.

    :raises MsgNotFoundError: if the type or one of its dependencies has no `.msg` file.
    """
    seen: set[str] = set()

    def expand(pkg: str, name: str) -> str:
        text, spec = _definition(pkg, name)
        parts = [text]
        for dependency in _dependencies(spec):
            if dependency in seen:
                continue
            seen.add(dependency)
            dep_pkg, dep_name = normalize_type_name(dependency)
            parts.append(f"\n{SEPARATOR}\nMSG: {dep_pkg}/{dep_name}\n")
            parts.append(expand(dep_pkg, dep_name))
        return "".join(parts)

    return expand(*normalize_type_name(type_name))
