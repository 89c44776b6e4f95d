"""Parameters from ROS 2 YAML files, readable without rclpy, and where those files are.

The same YAML files feed the nodes (their parameter defaults) and the pure cores (tests,
benchmarks, the fast runner), so the numbers live in one place: the repository's ``config/``,
installed by each package's ``setup.py`` to ``share/<package>/config`` and found through the
ament index, like any ROS package's config. A file holds sections keyed by node name (or ``/**``
for every node), each with a ``ros__parameters`` dict; nested keys appear to ROS as dotted names,
which ``unflatten`` turns back into nested dicts (``flatten`` the other way).
"""
from __future__ import annotations

import math
import os
import typing
from collections.abc import Iterator, Mapping
from dataclasses import MISSING, Field, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any, TypeVar

import yaml
from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

T = TypeVar("T")

__all__ = ["ConfigError", "ParameterSection", "POSITIVE", "CONFIG_PACKAGES", "FIXED_AT_START",
           "check_section", "config_fields", "config_file", "config_from_dict", "field_default",
           "flatten", "load_ros_params", "load_yaml", "merge_params", "package_config",
           "runs_dir", "section_values", "unflatten"]

#: The packages that install config files (``share/<package>/config``), searched in this order.
CONFIG_PACKAGES = ("qg_common", "robot_bridge_node", "sim_robot_node", "qg_learning_node",
                   "qg_experiments")


class ConfigError(ValueError):
    """A parameter file is missing or malformed."""


#: libyaml's parser under PyYAML's safe resolver and constructor: the values of
#: ``yaml.safe_load``, parsed five times as fast (3.2 ms against 0.6 ms for panda_scene.yaml).
#: Every node start and every experiment run reads several of these files.
_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_yaml(text: str) -> Any:
    """``yaml.safe_load(text)``, with libyaml's parser where PyYAML has it."""
    return yaml.load(text, Loader=_SAFE_LOADER)  # noqa: S506 - a safe loader


#: The range of a quantity that only has to be positive (``__post_init__`` checks the rest).
POSITIVE = (0.0, math.inf)

#: Why a parameter is read-only, unless its section says better (``ParameterSection.fixed``).
FIXED_AT_START = "read-only: read once at start; restart the node to change it"


@dataclass(frozen=True)
class ParameterSection:
    """One config dataclass as a block of a node's ROS parameters (``node_parameters``).

    :param prefix: the parameters' common prefix (``impedance``), "" for top-level names.
    :param config: the frozen config dataclass; its ``__post_init__`` stays the validator.
    :param ranges: field name (dotted below the prefix) -> ``(lowest, highest)`` allowed.
    :param runtime: field names whose change the node applies while it runs; all others are
        read-only.
    :param applies: when a run-time change takes effect (``from the next episode``).
    :param fixed: why the others are read-only; ``ros2 param describe`` shows both.
    """
    prefix: str
    config: type
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    runtime: frozenset[str] = frozenset()
    applies: str = "at once"
    fixed: str = FIXED_AT_START


def field_default(f: Field) -> Any:
    """The default of a dataclass field (``None`` if it has none)."""
    if f.default is not MISSING:
        return f.default
    return f.default_factory() if f.default_factory is not MISSING else None


def config_fields(cls: type, prefix: str = "") -> Iterator[tuple[str, Field, Any, type]]:
    """Every scalar or array field of the config dataclass ``cls`` as ``(dotted name, field,
    type hint, owning dataclass)``, nested dataclasses flattened (``ddpg.gamma``)."""
    hints = typing.get_type_hints(cls)
    for f in fields(cls):
        name = f"{prefix}.{f.name}" if prefix else f.name
        if is_dataclass(hints[f.name]):
            yield from config_fields(hints[f.name], name)
        else:
            yield name, f, hints[f.name], cls


def section_values(section: ParameterSection, params: Mapping[str, Any]) -> dict[str, Any]:
    """The section's own values out of a node's nested parameters: ``params[prefix]``, or for
    prefix "" the top-level keys that are fields of the section's config."""
    if section.prefix:
        return dict(params.get(section.prefix) or {})
    own = {f.name for f in fields(section.config)}
    return {key: value for key, value in params.items() if key in own}


def check_section(section: ParameterSection, values: Mapping[str, Any],
                  source: str = "") -> dict[str, Any]:
    """``values`` (the section's own, nested as in the YAML) checked as a node checks them when
    it declares the section: every key a field of the config, every number in its range.

    What reads a config file without a node (the experiments, tests) calls this, so a value the
    node would refuse is refused there too.
    :param source: where the values come from, for the message (``config/learner.yaml``).
    :returns: ``values`` as a plain dict.
    :raises ConfigError: naming the parameter, on an unknown key or a value out of range.
    """
    where = f" ({source})" if source else ""
    flat = flatten(dict(values))
    known = {name for name, *_ in config_fields(section.config)}
    dotted = (lambda name: f"{section.prefix}.{name}") if section.prefix else (lambda name: name)
    unknown = sorted(set(flat) - known)
    if unknown:
        raise ConfigError(f"unknown parameters {[dotted(n) for n in unknown]}{where}")
    for name, (low, high) in section.ranges.items():
        value = flat.get(name)
        if value is None or isinstance(value, bool):
            continue
        if not low <= value <= high:
            raise ConfigError(f"parameter {dotted(name)!r} = {value} is out of range "
                              f"[{low}, {high}]{where}")
    return dict(values)


def package_config(package: str, name: str) -> Path:
    """``share/<package>/config/<name>`` of an installed package: found through the ament index
    (a sourced shell), else in the colcon workspace ``$QG_ROS_INSTALL`` names (which the venv's
    interpreter sets: a plain Python, a Gymnasium user's, sources nothing).

    :raises ConfigError: if neither knows the package, or it lacks the file.
    """
    try:
        path = Path(get_package_share_directory(package)) / "config" / name
    except (OSError, PackageNotFoundError, LookupError) as exc:
        share = Path(os.environ.get("QG_ROS_INSTALL", "")) / package / "share" / package
        if not os.environ.get("QG_ROS_INSTALL") or not share.is_dir():
            raise ConfigError(f"package {package!r} is not installed where the ament index "
                              f"looks ({exc}) nor in $QG_ROS_INSTALL; run scripts/setup.sh and "
                              "source ros_ws/install/setup.bash (qgl and scripts/*.sh do that "
                              "themselves)") from None
        path = share / "config" / name
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    return path


def config_file(name: str, directory: str | Path | None = None) -> Path:
    """The stack's config file ``name``: ``<directory>/<name>`` if a folder of edited copies is
    given (or ``$QG_CONFIG_DIR`` names one), else the one an installed package ships
    (``CONFIG_PACKAGES``).

    :raises ConfigError: if no package ships it.
    """
    directory = directory or os.environ.get("QG_CONFIG_DIR")
    if directory:
        return Path(directory) / name
    problems = []
    for package in CONFIG_PACKAGES:
        try:
            return package_config(package, name)
        except ConfigError as exc:
            problems.append(str(exc))
    raise ConfigError(f"no package of {CONFIG_PACKAGES} ships config/{name}: "
                      + "; ".join(problems))


def runs_dir() -> Path:
    """Where runs are written (episode bags, checkpoints, ROS logs): ``$QG_RUNS_DIR``, else
    ``runs/`` in the current directory."""
    env = os.environ.get("QG_RUNS_DIR")
    return Path(env) if env else Path.cwd() / "runs"


def merge_params(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``extra`` laid over it, nested dicts merged key by key (as a second
    ``--params-file`` overrides only what it names)."""
    out = dict(base)
    for key, value in extra.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_params(out[key], value)
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


def flatten(nested: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}``: the names ROS gives nested keys."""
    flat: dict[str, Any] = {}
    for key, value in nested.items():
        name = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict):
            flat.update(flatten(value, name))
        else:
            flat[name] = value
    return flat


def load_ros_params(path: Path, node_name: str | None = None) -> dict[str, Any]:
    """The ``ros__parameters`` of ``/**`` merged with those of ``node_name`` (which win).

    :param path: a ROS 2 parameter YAML file.
    :param node_name: section to merge over ``/**``; with a leading ``/`` or without.
    :raises ConfigError: if the file is missing or not in the ROS 2 params layout.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"parameter file not found: {path}")
    data = load_yaml(path.read_text()) or {}
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
        params = merge_params(params, _normalise(body["ros__parameters"] or {}))
    return params


def _normalise(params: dict[str, Any]) -> dict[str, Any]:
    """Nested dicts whose keys may themselves be dotted, normalised to plain nesting."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, dict):
            value = _normalise(value)
        out = merge_params(out, unflatten({key: value}))
    return out


def config_from_dict(cls: type[T], params: dict[str, Any]) -> T:
    """Build the frozen config dataclass ``cls`` from a parameter dict.

    Lists become tuples (ROS hands arrays over as lists; frozen configs keep tuples), a dict
    given for a field that is itself a config dataclass becomes that dataclass (nested sections,
    ``imperfections.*``); unknown keys raise, so a typo in a YAML file fails loudly instead of
    silently keeping a default.
    :raises ConfigError: on keys that ``cls`` does not have.
    """
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(params) - names)
    if unknown:
        raise ConfigError(f"{cls.__name__}: unknown parameters {unknown}; known: {sorted(names)}")
    hints = typing.get_type_hints(cls)
    return cls(**{k: config_from_dict(hints[k], v) if isinstance(v, dict) and is_dataclass(hints[k])
                  else tuple(v) if isinstance(v, list) else v for k, v in params.items()})
