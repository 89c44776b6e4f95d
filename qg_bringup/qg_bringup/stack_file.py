"""The stack file: which processes ``qgl up`` starts, with what arguments, and how they respawn.

A stack file (``config/stack.yaml``) is our launch file: each process is a ``ros2 run <package>
<executable> <args>`` with its respawn settings, under a policy for the whole stack. This module
reads and checks it (one-line errors, fit for a user) and writes the variants a run uses (the
recording settings of ``qgl run --recording``); ``launcher`` runs what it describes.
"""
from __future__ import annotations

import argparse
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml
from ament_index_python.packages import (
    PackageNotFoundError,
    get_package_prefix,
    get_package_share_directory,
)

__all__ = ["ProcessSpec", "load_stack_config", "load_stack", "StackConfigError",
           "RespawnPolicy", "CONFIG_ERROR_EXIT", "recording_setting", "recording_argument",
           "with_recording", "stack_with_recording"]


#: The exit code of a node whose parameters are refused (``run_nodes``): never respawned.
CONFIG_ERROR_EXIT = 2


class StackConfigError(ValueError):
    """The launch configuration is missing or malformed (one line, fit for a user)."""


@dataclass(frozen=True)
class RespawnPolicy:
    """How often respawning processes may die before the stack is stopped (stack file's
    ``respawn:`` section).

    :param max_restarts: a process that exits more often than this within ``window`` seconds
        is not restarted again (the stack stops with the reason).
    :param window: [s] the window those exits are counted in.
    :param backoff: each further exit within the window multiplies the delay by this.
    :param max_delay: [s] the longest delay before a restart.
    """
    max_restarts: int = 5
    window: float = 60.0
    backoff: float = 2.0
    max_delay: float = 30.0

    def __post_init__(self) -> None:
        if self.max_restarts < 0 or self.window <= 0 or self.backoff < 1 or self.max_delay < 0:
            raise StackConfigError(f"respawn: max_restarts >= 0, window > 0, backoff >= 1 and "
                                   f"max_delay >= 0 needed, got {self}")

    def delay(self, base: float, exits_in_window: int) -> float:
        """[s] before the restart after the ``exits_in_window``-th exit (1 = the first)."""
        return min(base * self.backoff ** max(0, exits_in_window - 1), self.max_delay)


@dataclass(frozen=True)
class ProcessSpec:
    """One node process: ``ros2 run <package> <executable> <args>``.

    ``package`` "" runs ``executable`` as a program (a path or a name on ``PATH``) with
    ``args``: tools and tests (a process that always fails).
    :param respawn: start it again when it exits on its own (ros2 launch's ``respawn``).
    :param respawn_delay: [s] before the first restart (ros2 launch's ``respawn_delay``).
    :param respawn_args: ROS arguments added when it is restarted (``-p resume:=true``).
    """
    name: str
    package: str
    executable: str
    args: tuple[str, ...] = ()
    respawn: bool = False
    respawn_delay: float = 1.0
    respawn_args: tuple[str, ...] = ()

    def command(self, respawned: bool = False) -> list[str]:
        """What ``ros2 run`` runs: ``lib/<package>/<executable>`` under the package's prefix in
        the ament index (the launcher's environment is the stack's, ``ros_env.stack_env``);
        ``respawned``: with ``respawn_args`` among its ROS arguments."""
        args = list(self.args)
        if respawned and self.respawn_args:
            args += ([] if "--ros-args" in args else ["--ros-args"]) + list(self.respawn_args)
        if not self.package:
            return [self.executable, *args]
        try:
            prefix = Path(get_package_prefix(self.package))
        except (OSError, PackageNotFoundError, LookupError):
            raise StackConfigError(f"package {self.package!r} is not installed: run "
                                   "scripts/setup.sh") from None
        exe = prefix / "lib" / self.package / self.executable
        if not exe.is_file():
            raise StackConfigError(f"{self.package}/{self.executable} is not built ({exe} missing): "
                                   "run scripts/setup.sh")
        return [str(exe), *args]


#: ``$(find-pkg-share <package>)`` in an argument, as in a ROS 2 launch file.
_FIND_PKG_SHARE = re.compile(r"\$\(find-pkg-share ([A-Za-z0-9_]+)\)")


def _substitute(arg: str) -> str:
    """``arg`` with every ``$(find-pkg-share pkg)`` replaced by the package's share folder."""
    def share(match: re.Match) -> str:
        try:
            return get_package_share_directory(match.group(1))
        except (OSError, PackageNotFoundError, LookupError):
            raise StackConfigError(f"$(find-pkg-share {match.group(1)}): no such package "
                                   "installed") from None
    return _FIND_PKG_SHARE.sub(share, arg)


def load_stack_config(path: Path) -> list[ProcessSpec]:
    """The ``processes:`` list of a stack file such as ``config/stack.yaml``; arguments may
    name installed files as ``$(find-pkg-share <package>)/config/<file>``."""
    return load_stack(path)[0]


#: The keys of the ``respawn:`` section: the defaults of every process, then the policy.
_RESPAWN_KEYS = {"enabled", "delay", "args", "max_restarts", "window", "backoff", "max_delay"}


def _number(path: Path, where: str, value: Any, kind: type) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (kind is int and not isinstance(value, int)):
        raise StackConfigError(f"{path}: {where} must be a{'n integer' if kind is int else ' number'}"
                               f", got {value!r}")
    return kind(value)


def _str_list(path: Path, where: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list):
        raise StackConfigError(f"{path}: {where} must be a list")
    return tuple(_substitute(str(a)) for a in value)


def load_stack(path: Path) -> tuple[list[ProcessSpec], RespawnPolicy]:
    """The processes of a stack file and its respawn policy.

    The optional ``respawn:`` section gives every process's defaults (``enabled``, ``delay``,
    ``args``) and the policy (``max_restarts``, ``window``, ``backoff``, ``max_delay``); a
    process overrides the defaults with its own ``respawn``, ``respawn_delay`` and
    ``respawn_args``. Without the section nothing respawns.
    """
    if not path.is_file():
        raise StackConfigError(f"config file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise StackConfigError(f"malformed YAML in {path}{where}: "
                               f"{getattr(exc, 'problem', exc)}") from None
    if not isinstance(data, dict) or not isinstance(data.get("processes"), list) \
            or not data["processes"]:
        raise StackConfigError(f"{path}: expected a non-empty 'processes:' list")
    section = data.get("respawn") or {}
    if not isinstance(section, dict) or not set(section) <= _RESPAWN_KEYS:
        raise StackConfigError(f"{path}: 'respawn:' takes {sorted(_RESPAWN_KEYS)}, got "
                               f"{sorted(section) if isinstance(section, dict) else section!r}")
    enabled = section.get("enabled", False)
    if not isinstance(enabled, bool):
        raise StackConfigError(f"{path}: respawn.enabled must be true or false, got {enabled!r}")
    delay = _number(path, "respawn.delay", section.get("delay", 1.0), float)
    default_args = _str_list(path, "respawn.args", section.get("args", []))
    policy = RespawnPolicy(**{key: _number(path, f"respawn.{key}", section[key],
                                           int if key == "max_restarts" else float)
                              for key in ("max_restarts", "window", "backoff", "max_delay")
                              if key in section})
    specs = []
    for i, entry in enumerate(data["processes"]):
        if not isinstance(entry, dict) or not {"name", "package", "executable"} <= entry.keys():
            raise StackConfigError(f"{path}: processes[{i}] needs name, package and executable")
        args = _str_list(path, f"processes[{i}].args", entry.get("args", []))
        respawn = entry.get("respawn", enabled)
        if not isinstance(respawn, bool):
            raise StackConfigError(f"{path}: processes[{i}].respawn must be true or false")
        own_delay = _number(path, f"processes[{i}].respawn_delay",
                            entry.get("respawn_delay", delay), float)
        if own_delay < 0:
            raise StackConfigError(f"{path}: processes[{i}].respawn_delay must be >= 0")
        respawn_args = (_str_list(path, f"processes[{i}].respawn_args", entry["respawn_args"])
                        if "respawn_args" in entry else default_args)
        specs.append(ProcessSpec(str(entry["name"]), str(entry["package"]),
                                 str(entry["executable"]), args, respawn, own_delay,
                                 respawn_args))
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise StackConfigError(f"{path}: process names must be unique, got {names}")
    return specs, policy


#: The processes whose ``recorder`` node records the episodes (and takes ``recording.*``).
RECORDING_PROCESSES = frozenset({("robot_bridge_node", "robot")})


def recording_setting(text: str) -> tuple[str, str]:
    """``--recording NAME=VALUE``: one ``recording.*`` parameter of the recorder
    (``qg_recording.disk_keeper.RecordingPolicy``), checked; ``("recording.NAME", VALUE)``.

    :raises ValueError: naming the setting, for an unknown name or a bad value.
    """
    from dataclasses import fields

    from qg_recording.disk_keeper import RecordingPolicy
    name, sep, value = text.partition("=")
    kinds = {f.name: f.type for f in fields(RecordingPolicy)}
    name = name.strip().removeprefix("recording.")
    if not sep or name not in kinds:
        raise ValueError(f"--recording takes NAME=VALUE with NAME one of {sorted(kinds)}, "
                         f"got {text!r}")
    kind = {"str": str, "int": int, "float": float}[str(kinds[name])]
    try:
        RecordingPolicy(**{name: kind(value.strip())})
    except ValueError as exc:
        raise ValueError(f"--recording {text}: {exc}") from None
    return f"recording.{name}", value.strip()


def recording_argument(text: str) -> tuple[str, str]:
    """``recording_setting`` as an argparse type (a bad one refused with the reason)."""
    try:
        return recording_setting(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def with_recording(specs: list[ProcessSpec], settings: list[tuple[str, str]]) -> list[ProcessSpec]:
    """``specs`` with ``-p recording.NAME:=VALUE`` on the processes that record episodes."""
    if not settings:
        return specs
    out = []
    for spec in specs:
        if (spec.package, spec.executable) in RECORDING_PROCESSES:
            ros_args = () if "--ros-args" in spec.args else ("--ros-args",)
            extra = tuple(x for key, value in settings for x in ("-p", f"{key}:={value}"))
            spec = replace(spec, args=spec.args + ros_args + extra)
        out.append(spec)
    return out


def stack_with_recording(config: Path, settings: list[tuple[str, str]], out: Path) -> Path:
    """Write ``out``: the stack file ``config`` with ``settings`` added to the arguments of
    the processes that record (a run keeps its stack file, so a continued run records alike)."""
    load_stack(config)    # a stack file, or the reason why not
    data = yaml.safe_load(config.read_text())
    for entry in data.get("processes") or []:
        if (entry.get("package"), entry.get("executable")) in RECORDING_PROCESSES:
            args = [str(a) for a in entry.get("args") or []]
            args += [] if "--ros-args" in args else ["--ros-args"]
            entry["args"] = args + [x for key, value in settings for x in ("-p", f"{key}:={value}")]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"# {config} with the recording settings of `qgl run --recording`\n"
                   + yaml.safe_dump(data, sort_keys=False))
    load_stack(out)       # what it wrote is a stack file
    return out
