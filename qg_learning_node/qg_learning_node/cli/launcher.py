"""Start the stack's node processes, prefix their output, and stop them all together.

``ros2 launch`` has no wheels here, so this is our launcher: each process is started the way
``ros2 run`` would (``install/<pkg>/lib/<pkg>/<exe>``), its output lines are prefixed with its
name, and stopping sends SIGINT, then SIGTERM, then SIGKILL, each after a grace period.

Each child runs in a session of its own (a Ctrl-C in the terminal reaches the launcher, which
stops the children in order) but asks the kernel for SIGTERM when the launcher dies
(``qg_common.process_guard``), so a killed launcher leaves no node behind.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import yaml

from ament_index_python.packages import (PackageNotFoundError, get_package_prefix,
                                         get_package_share_directory)
from qg_common.process_guard import die_with_parent

__all__ = ["ProcessSpec", "Launcher", "load_stack_config", "StackConfigError"]


class StackConfigError(ValueError):
    """The launch configuration is missing or malformed (one line, fit for a user)."""


@dataclass(frozen=True)
class ProcessSpec:
    """One node process: ``ros2 run <package> <executable> <args>``."""
    name: str
    package: str
    executable: str
    args: tuple[str, ...] = ()

    def command(self) -> list[str]:
        """What ``ros2 run`` runs: ``lib/<package>/<executable>`` under the package's prefix in
        the ament index (the launcher's environment is the stack's, ``ros_env.stack_env``)."""
        try:
            prefix = Path(get_package_prefix(self.package))
        except (PackageNotFoundError, LookupError, EnvironmentError):
            raise StackConfigError(f"package {self.package!r} is not installed: run "
                                   "scripts/setup.sh") from None
        exe = prefix / "lib" / self.package / self.executable
        if not exe.is_file():
            raise StackConfigError(f"{self.package}/{self.executable} is not built ({exe} missing): "
                                   "run scripts/setup.sh")
        return [str(exe), *self.args]


#: ``$(find-pkg-share <package>)`` in an argument, as in a ROS 2 launch file.
_FIND_PKG_SHARE = re.compile(r"\$\(find-pkg-share ([A-Za-z0-9_]+)\)")


def _substitute(arg: str) -> str:
    """``arg`` with every ``$(find-pkg-share pkg)`` replaced by the package's share folder."""
    def share(match: re.Match) -> str:
        try:
            return get_package_share_directory(match.group(1))
        except (PackageNotFoundError, LookupError, EnvironmentError):
            raise StackConfigError(f"$(find-pkg-share {match.group(1)}): no such package "
                                   "installed") from None
    return _FIND_PKG_SHARE.sub(share, arg)


def load_stack_config(path: Path) -> list[ProcessSpec]:
    """The ``processes:`` list of a stack file such as ``config/stack.yaml``; arguments may
    name installed files as ``$(find-pkg-share <package>)/config/<file>``."""
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
    specs = []
    for i, entry in enumerate(data["processes"]):
        if not isinstance(entry, dict) or not {"name", "package", "executable"} <= entry.keys():
            raise StackConfigError(f"{path}: processes[{i}] needs name, package and executable")
        args = entry.get("args", [])
        if not isinstance(args, list):
            raise StackConfigError(f"{path}: processes[{i}].args must be a list")
        specs.append(ProcessSpec(str(entry["name"]), str(entry["package"]),
                                 str(entry["executable"]),
                                 tuple(_substitute(str(a)) for a in args)))
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise StackConfigError(f"{path}: process names must be unique, got {names}")
    return specs


@dataclass
class _Running:
    spec: ProcessSpec
    popen: subprocess.Popen
    pump: threading.Thread
    reported: bool = False


@dataclass
class Launcher:
    """Runs a set of processes; ``poll()`` tells whether one died on its own.

    :param env: environment of the children (see :func:`ros_env.stack_env`).
    :param out: where prefixed lines go (default stdout); ``None`` silences them.
    :param log_dir: if set, each process's output is also written to ``<log_dir>/<name>.log``.
    """
    env: dict[str, str]
    out: IO[str] | None = field(default_factory=lambda: sys.stdout)
    log_dir: Path | None = None
    running: list[_Running] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def start(self, specs: list[ProcessSpec]) -> None:
        width = max(len(s.name) for s in specs)
        for spec in specs:
            popen = subprocess.Popen(spec.command(), env=self.env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, bufsize=1,
                                     start_new_session=True,
                                     preexec_fn=die_with_parent(os.getpid()))
            pump = threading.Thread(target=self._pump, args=(spec, popen, width), daemon=True)
            pump.start()
            self.running.append(_Running(spec, popen, pump))

    def _pump(self, spec: ProcessSpec, popen: subprocess.Popen, width: int) -> None:
        log = None
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            log = open(self.log_dir / f"{spec.name}.log", "w")
        assert popen.stdout is not None
        for line in popen.stdout:
            if log is not None:
                log.write(line)
                log.flush()
            if self.out is not None:
                with self._lock:
                    self.out.write(f"[{spec.name:<{width}}] {line}")
                    self.out.flush()
        if log is not None:
            log.close()

    def poll(self) -> list[tuple[str, int]]:
        """Processes that exited since the last call, as (name, exit code)."""
        died = []
        for r in self.running:
            code = r.popen.poll()
            if code is not None and not r.reported:
                r.reported = True
                died.append((r.spec.name, code))
        return died

    def wait_any(self, period: float = 0.2) -> tuple[str, int]:
        """Block until some process exits; return its name and exit code."""
        while True:
            died = self.poll()
            if died:
                return died[0]
            time.sleep(period)

    def stop(self, grace: float = 5.0) -> dict[str, int]:
        """SIGINT all, then SIGTERM and SIGKILL stragglers; return each exit code.

        SIGINT goes in reverse start order, each process given until the wave's deadline to end
        before the next is signalled: what a later process says at its end (the executor's
        final ``aborted`` status) still reaches the earlier ones (the robot process's recorder).
        """
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            alive = [r for r in reversed(self.running) if r.popen.poll() is None]
            if not alive:
                break
            deadline = time.monotonic() + grace
            for r in alive:
                try:
                    r.popen.send_signal(sig)
                except ProcessLookupError:
                    pass
                if sig == signal.SIGINT:
                    self._wait([r], deadline)
            self._wait(alive, deadline)
        for r in self.running:
            r.pump.join(timeout=2.0)
        return {r.spec.name: r.popen.returncode for r in self.running}

    @staticmethod
    def _wait(processes: list[_Running], deadline: float) -> None:
        """Until all of ``processes`` have ended or ``deadline`` (monotonic) has passed."""
        while time.monotonic() < deadline and any(r.popen.poll() is None for r in processes):
            time.sleep(0.05)

    def pids(self) -> dict[str, Any]:
        return {r.spec.name: r.popen.pid for r in self.running}
