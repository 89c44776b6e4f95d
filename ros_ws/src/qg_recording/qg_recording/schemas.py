"""ros2msg schema text for a message type, as rosbag2 writes it into MCAP schema records.

A bag must carry the full definition of every recorded type so that any reader (mcap_ros2,
Foxglove, `ros2 bag`) can decode it without our interface package installed. rosbag2 builds the
text from the installed `.msg` files: the root definition verbatim, then every dependency once
(depth first, in sorted order), each preceded by an 80-character `=` line and `MSG: pkg/Type`.
We reproduce that here from the same `.msg` files, found on AMENT_PREFIX_PATH (our
`qg_interfaces` once built) and in this interpreter's prefix (the venv ships the standard
interfaces).
"""

from __future__ import annotations

import functools
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Field", "MsgNotFoundError", "find_msg_file", "message_fields", "normalize_type_name", "schema_text"]

SEPARATOR = "=" * 80
_PRIMITIVES = frozenset(
    "bool byte char float32 float64 int8 uint8 int16 uint16 int32 uint32 int64 uint64 "
    "string wstring".split()
)
# The first token of a field line ("geometry_msgs/Wrench" in "geometry_msgs/Wrench[] w"), as
# rosbag2's LocalMessageDefinitionSource matches it.
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_TYPE_NAME = re.compile(r"^([a-zA-Z0-9_]+)/(?:msg/)?([a-zA-Z0-9_]+)$")
# A field type token: base type, optional string bound, optional array suffix.
_FIELD_TOKEN = re.compile(r"^([a-zA-Z0-9_/]+)(?:<=\d+)?(?:\[(<=)?(\d*)\])?$")


class MsgNotFoundError(LookupError):
    """No `.msg` file for a type name in any searched prefix."""


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


def find_msg_file(type_name: str) -> Path:
    """Path of the `.msg` file defining `type_name`.

    :raises MsgNotFoundError: if no searched directory has it.
    """
    pkg, name = normalize_type_name(type_name)
    candidates = [root / pkg / "msg" / f"{name}.msg" for root in _search_roots()]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    searched = ", ".join(str(c.parent) for c in candidates)
    raise MsgNotFoundError(f"no definition of {pkg}/msg/{name} (searched {searched})")


@functools.lru_cache(maxsize=None)
def _definition(pkg: str, name: str) -> tuple[str, tuple[str, ...]]:
    """The `.msg` text of `pkg/name` and its non-primitive field types as `pkg/Type`, sorted."""
    text = find_msg_file(f"{pkg}/{name}").read_text()
    dependencies = set()
    for match in _FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in _PRIMITIVES:
            continue
        dependencies.add(field_type if "/" in field_type else f"{pkg}/{field_type}")
    return text, tuple(sorted(dependencies))


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


@functools.lru_cache(maxsize=None)
def message_fields(type_name: str) -> tuple[Field, ...]:
    """The fields of a message type in definition order (constants skipped).

    :raises MsgNotFoundError: if the type has no `.msg` file; ValueError for a malformed line.
    """
    pkg, name = normalize_type_name(type_name)
    text, _ = _definition(pkg, name)
    fields = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or "=" in line:
            continue  # blank, comment or constant ("int32 X=1"; defaults have no "=")
        tokens = line.split()
        match = _FIELD_TOKEN.match(tokens[0]) if len(tokens) >= 2 else None
        if match is None:
            raise ValueError(f"{type_name}: cannot parse field line {line!r}")
        base, bounded, size = match.groups()
        if base not in _PRIMITIVES:
            dep_pkg, dep_name = normalize_type_name(base if "/" in base else f"{pkg}/{base}")
            base = f"{dep_pkg}/msg/{dep_name}"
        if tokens[0].endswith("]"):
            array = -1 if bounded or not size else int(size)
        else:
            array = None
        fields.append(Field(base, tokens[1], array))
    return tuple(fields)


@functools.lru_cache(maxsize=None)
def schema_text(type_name: str) -> str:
    """Full ros2msg schema of `type_name` (`pkg/msg/Type`) with all its dependencies inlined.

    :raises MsgNotFoundError: if the type or one of its dependencies has no `.msg` file.
    """
    seen: set[str] = set()

    def expand(pkg: str, name: str) -> str:
        text, dependencies = _definition(pkg, name)
        parts = [text]
        for dependency in dependencies:
            if dependency in seen:
                continue
            seen.add(dependency)
            dep_pkg, dep_name = normalize_type_name(dependency)
            parts.append(f"\n{SEPARATOR}\nMSG: {dep_pkg}/{dep_name}\n")
            parts.append(expand(dep_pkg, dep_name))
        return "".join(parts)

    return expand(*normalize_type_name(type_name))
