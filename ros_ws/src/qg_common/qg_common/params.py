"""Parameters from ROS 2 YAML files, readable without rclpy.

The same ``config/*.yaml`` files feed ``ros2 run`` (via ``--params-file``) and the pure cores
(tests, benchmarks), so the numbers live in one place. A file holds sections keyed by node name
(or ``/**`` for every node), each with a ``ros__parameters`` dict; nested keys appear to ROS as
dotted names, which ``unflatten`` turns back into nested dicts.
"""
from __future__ import annotations

import os
from pathlib import Path
from dataclasses import fields
from typing import Any, TypeVar

T = TypeVar("T")

import yaml

__all__ = ["ConfigError", "config_dir", "config_from_dict", "load_ros_params", "runs_dir",
           "unflatten"]


class ConfigError(ValueError):
    """A parameter file is missing or malformed."""


def config_dir() -> Path:
    """The project's ``config/`` folder (``$QG_CONFIG_DIR`` overrides it, e.g. when installed)."""
    env = os.environ.get("QG_CONFIG_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[4] / "config"


def runs_dir() -> Path:
    """Where runs are written (episode bags, checkpoints): ``$QG_RUNS_DIR``, else ``<repo>/runs``."""
    env = os.environ.get("QG_RUNS_DIR")
    return Path(env) if env else Path(__file__).resolve().parents[4] / "runs"


def _merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in extra.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def unflatten(flat: dict[str, Any]) -> dict[str, Any]:
    """``{"a.b": 1, "a.c": 2}`` -> ``{"a": {"b": 1, "c": 2}}`` (ROS reports nested keys dotted)."""
    nested: dict[str, Any] = {}
    for name, value in flat.items():
        parts = name.split(".")
        node = nested
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"parameter {name!r} clashes with a scalar at {part!r}")
        node[parts[-1]] = value
    return nested


def load_ros_params(path: Path, node_name: str | None = None) -> dict[str, Any]:
    """The ``ros__parameters`` of ``/**`` merged with those of ``node_name`` (which win).

    :param path: a ROS 2 parameter YAML file.
    :param node_name: section to merge over ``/**``; with a leading ``/`` or without.
    :raises ConfigError: if the file is missing or not in the ROS 2 params layout.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"parameter file not found: {path}")
    data = yaml.safe_load(path.read_text()) or {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: top level must be a mapping of node names")
    sections = ["/**"]
    if node_name:
        sections += [node_name.lstrip("/"), "/" + node_name.lstrip("/")]
    params: dict[str, Any] = {}
    for section in sections:
        if section not in data:
            continue
        body = data[section]
        if not isinstance(body, dict) or "ros__parameters" not in body:
            raise ConfigError(f"{path}: section {section!r} has no 'ros__parameters'")
        params = _merge(params, _normalise(body["ros__parameters"] or {}))
    return params


def _normalise(params: dict[str, Any]) -> dict[str, Any]:
    """Nested dicts whose keys may themselves be dotted, normalised to plain nesting."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, dict):
            value = _normalise(value)
        out = _merge(out, unflatten({key: value}))
    return out


def config_from_dict(cls: type[T], params: dict[str, Any]) -> T:
    """Build the frozen config dataclass ``cls`` from a parameter dict.

    Lists become tuples (ROS hands arrays over as lists; frozen configs keep tuples); unknown keys
    raise, so a typo in a YAML file fails loudly instead of silently keeping a default.
    :raises ConfigError: on keys that ``cls`` does not have.
    """
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(params) - names)
    if unknown:
        raise ConfigError(f"{cls.__name__}: unknown parameters {unknown}; known: {sorted(names)}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in params.items()})
