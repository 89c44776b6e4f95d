"""A node's ROS parameters, declared from its config dataclasses: names, types, docs, ranges.

ROS only shows (``ros2 param list/describe/get``) and checks what a node declares, so every node
declares exactly the fields of its own config dataclasses, each ``ParameterSection`` one of them
under a prefix (``params.ParameterSection``; nested dataclasses give dotted names,
``scene.geometry.peg_radius``):

- the default comes from the package's YAML (``share/<pkg>/config``), else from the dataclass;
- the description from the dataclass docstring (``:param name:``) or the field's comment, with
  the shipped default and where it lives appended, generated from the value itself (a number
  written into a docstring goes stale; this cannot);
- a ``FloatingPointRange`` / ``IntegerRange`` where the section gives one;
- ``read_only`` unless the section lists the field as changeable while the node runs, and the
  description says which, and why (``ParameterSection.fixed``).

A value from the command line (``-p``, ``--params-file``) overrides the default; rclpy itself
refuses one of the wrong type or out of range, and ``declare_parameters`` turns that into a
``ConfigError`` naming the parameter. rclpy silently ignores a given parameter nobody declared;
``unknown_overrides`` finds those (misspelt names), and ``run_nodes`` refuses to start with them.
"""
from __future__ import annotations

import difflib
import inspect
import re
import typing
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from qg_common.params import (
    ConfigError,
    ParameterSection,
    config_fields,
    field_default,
    flatten,
    load_ros_params,
    package_config,
    unflatten,
)

__all__ = ["Leaf", "leaves", "declare_parameters", "describe", "package_defaults", "ros_value",
           "shipped_defaults", "unknown_overrides", "on_parameter_change"]

#: Parameters rclpy declares or reads itself: never "unknown".
_BUILTIN = ("use_sim_time",)
_BUILTIN_PREFIXES = ("qos_overrides.",)

_SCALAR_TYPES = {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER,
                 float: Parameter.Type.DOUBLE, str: Parameter.Type.STRING}
_ARRAY_TYPES = {bool: Parameter.Type.BOOL_ARRAY, int: Parameter.Type.INTEGER_ARRAY,
                float: Parameter.Type.DOUBLE_ARRAY, str: Parameter.Type.STRING_ARRAY}


@dataclass(frozen=True)
class Leaf:
    """One declared parameter: a scalar or array field of a (possibly nested) config dataclass."""
    name: str
    type: Parameter.Type
    default: Any
    description: str


def _local(section: ParameterSection, leaf: Leaf) -> str:
    return leaf.name[len(section.prefix) + 1:] if section.prefix else leaf.name


def describe(section: ParameterSection, leaf: Leaf, default: Any, home: str) -> str:
    """What ``ros2 param describe`` says of ``leaf``: its docstring, then the shipped default
    and its home (generated from the value, so it cannot contradict it), then whether it can
    be set while the node runs, or why not."""
    local = _local(section, leaf)
    settable = (f"settable with `ros2 param set`, applies {section.applies}"
                if local in section.runtime else section.fixed)
    text = leaf.description.rstrip(".")
    return f"{text}. Default {default!r} ({home}); {settable}." if text else \
        f"Default {default!r} ({home}); {settable}."


def _descriptor(section: ParameterSection, leaf: Leaf, description: str) -> ParameterDescriptor:
    """Type, description, range and read-only flag of one leaf, as ``ros2 param describe``
    shows them."""
    local = _local(section, leaf)
    descriptor = ParameterDescriptor(name=leaf.name, type=leaf.type.value,
                                     description=description,
                                     read_only=local not in section.runtime)
    if local in section.ranges:
        low, high = section.ranges[local]
        if leaf.type == Parameter.Type.DOUBLE:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(low), to_value=float(high), step=0.0)]
        elif leaf.type == Parameter.Type.INTEGER:
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high),
                                                     step=1)]
        else:
            raise TypeError(f"{leaf.name}: a range needs a number, not {leaf.type.name}")
    return descriptor


def leaves(section: ParameterSection) -> list[Leaf]:
    """Every scalar/array field of the section, nested dataclasses flattened to dotted names."""
    return list(_leaves(section.config, section.prefix))


def _parameter_type(hint: Any) -> Parameter.Type:
    """The ROS type of a field annotation (``X | None`` is X; tuples become arrays)."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if typing.get_origin(hint) in (typing.Union, type(int | None)) and len(args) == 1:
        hint = args[0]
        args = list(typing.get_args(hint))
    if hint in _SCALAR_TYPES:
        return _SCALAR_TYPES[hint]
    if typing.get_origin(hint) in (tuple, list) and args and args[0] in _ARRAY_TYPES:
        return _ARRAY_TYPES[args[0]]
    raise TypeError(f"no ROS parameter type for the annotation {hint!r}")


def _docs(cls: type) -> dict[str, str]:
    """Field descriptions: ``:param name: text`` of the docstring, else the field's comment."""
    docs: dict[str, str] = {}
    for line in inspect.getsource(cls).splitlines():
        match = re.match(r"\s+(\w+):[^=#]+=[^#]*#\s*(.+)$", line)
        if match:
            docs[match.group(1)] = match.group(2).strip()
    text = inspect.getdoc(cls) or ""
    for match in re.finditer(r":param (\w+):(.*?)(?=:param |\n\s*\n|\Z)", text, re.S):
        docs[match.group(1)] = " ".join(match.group(2).split())
    return docs


def ros_value(value: Any, kind: Parameter.Type) -> Any:
    """A config value as rclpy takes it: tuples as lists, ints as floats where floats are due,
    and ``None`` as the zero of the type (ROS parameters cannot be null: 0 / "" mean none)."""
    if value is None:
        return {Parameter.Type.BOOL: False, Parameter.Type.INTEGER: 0,
                Parameter.Type.DOUBLE: 0.0, Parameter.Type.STRING: ""}.get(kind, [])
    if kind == Parameter.Type.DOUBLE and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind == Parameter.Type.DOUBLE_ARRAY and isinstance(value, (list, tuple)):
        return [float(v) for v in value]
    if isinstance(value, tuple):
        return list(value)
    return value


def _leaves(cls: type, prefix: str) -> Iterator[Leaf]:
    docs: dict[type, dict[str, str]] = {}
    for name, f, hint, owner in config_fields(cls, prefix):
        kind = _parameter_type(hint)
        if owner not in docs:
            docs[owner] = _docs(owner)
        yield Leaf(name, kind, ros_value(field_default(f), kind), docs[owner].get(f.name, ""))


def _coerce_override(node: Node, leaf: Leaf) -> None:
    """Let ``-p x:=10`` give a float parameter 10.0 (rclpy would refuse the integer)."""
    given = node._parameter_overrides.get(leaf.name)     # rclpy has no public accessor
    if given is None:
        return
    value = ros_value(given.value, leaf.type)
    if value != given.value or type(value) is not type(given.value):
        node._parameter_overrides[leaf.name] = Parameter(leaf.name, value=value)


def shipped_defaults(node_name: str, files: Sequence[tuple[str, str]]
                     ) -> dict[str, tuple[Any, str]]:
    """Dotted name -> (value, ``config/<file>``) of the ``ros__parameters`` for ``node_name``
    (its own section over ``/**``) of the files ``(package, file name)`` installed in
    ``share/<package>/config``, later files winning: each value with its home."""
    defaults: dict[str, tuple[Any, str]] = {}
    for package, name in files:
        for key, value in flatten(load_ros_params(package_config(package, name),
                                                  node_name)).items():
            defaults[key] = (value, f"config/{name}")
    return defaults


def package_defaults(node_name: str, files: Sequence[tuple[str, str]]) -> dict[str, Any]:
    """The ``ros__parameters`` for ``node_name`` of ``files`` (``shipped_defaults``), nested."""
    return unflatten({key: value for key, (value, _) in
                      shipped_defaults(node_name, files).items()})


def declare_parameters(node: Node, sections: Sequence[ParameterSection],
                       files: Sequence[tuple[str, str]] = ()) -> dict[str, Any]:
    """Declare the sections' fields on ``node``; the values in effect, as a nested dict.

    :param files: ``(package, file name)`` of the YAML files with this node's defaults
        (``package_defaults``); a field they do not name keeps the dataclass default.
    :raises ConfigError: a given value of the wrong type or out of range, naming the parameter;
        or a key of the files under a section's prefix that the section does not have.
    """
    shipped = shipped_defaults(node.get_name(), files)
    values: dict[str, Any] = {}
    for section in sections:
        section_leaves = leaves(section)
        if section.prefix:
            known = {leaf.name for leaf in section_leaves}
            stray = sorted(k for k in shipped
                           if k.startswith(section.prefix + ".") and k not in known)
            if stray:
                raise ConfigError(f"node {node.get_name()}: the package config names unknown "
                                  f"parameters {stray}")
        for leaf in section_leaves:
            value, home = shipped.get(leaf.name, (leaf.default, "code default"))
            default = ros_value(value, leaf.type)
            if isinstance(default, list) and not default:
                raise ConfigError(f"{leaf.name}: an empty array has no ROS type; give a default")
            _coerce_override(node, leaf)
            descriptor = _descriptor(section, leaf, describe(section, leaf, default, home))
            try:
                values[leaf.name] = node.declare_parameter(leaf.name, default, descriptor).value
            except InvalidParameterTypeException as exc:
                raise ConfigError(f"node {node.get_name()}: parameter {leaf.name!r}: {exc}") \
                    from None
            except InvalidParameterValueException as exc:
                raise ConfigError(f"node {node.get_name()}: parameter {leaf.name!r} refused: "
                                  f"{exc.args[0]}") from None
    return unflatten(values)


def _builtin(name: str) -> bool:
    return name in _BUILTIN or name.startswith(_BUILTIN_PREFIXES)


def _given(node: Node) -> set[str]:
    return {name for name in node._parameter_overrides if not _builtin(name)}


def unknown_overrides(nodes: Sequence[Node]) -> list[str]:
    """Messages for the given parameters that no node of ``nodes`` (one process) declares.

    Nodes composed in one process share a ``/**`` params file, so a name is only unknown if
    none of them declares it.
    """
    declared = {name for node in nodes for name in node.get_parameters_by_prefix("")}
    problems = []
    for name in sorted(set().union(*(_given(node) for node in nodes)) - declared):
        close = difflib.get_close_matches(name, declared, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        owners = ", ".join(sorted(n.get_name() for n in nodes))
        problems.append(f"unknown parameter {name!r}: no node of this process ({owners}) "
                        f"declares it{hint}")
    return problems


def on_parameter_change(node: Node, apply: Callable[[dict[str, Any]], None],
                        when: str = "at once") -> None:
    """Call ``apply`` with all parameter values (nested) whenever ``ros2 param set`` changes one.

    rclpy has already refused read-only and out-of-range values by then. ``apply`` validates
    and applies; a ``ValueError`` refuses the change with its message as the reason. An applied
    change is logged, old and new value and ``when`` it takes effect.
    """
    def callback(changed: list[Parameter]) -> SetParametersResult:
        before = {name: p.value for name, p in node.get_parameters_by_prefix("").items()}
        current = {**before, **{p.name: p.value for p in changed}}
        current = {name: value for name, value in current.items() if not _builtin(name)}
        try:
            apply(unflatten(current))
        except (ValueError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        for p in changed:
            if not _builtin(p.name) and p.value != before.get(p.name):
                node.get_logger().info(f"parameter {p.name}: {before.get(p.name)!r} -> "
                                       f"{p.value!r}, applies {when}")
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(callback)
