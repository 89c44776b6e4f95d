"""Start the stack's node processes, prefix their output, respawn them, and stop them all together.

``ros2 launch`` has no wheels here, so this is our launcher: each process is started the way
``ros2 run`` would (``install/<pkg>/lib/<pkg>/<exe>``), its output lines are prefixed with its
name, and stopping sends SIGINT, then SIGTERM, then SIGKILL, each after a grace period.

Each child runs in a session of its own (a Ctrl-C in the terminal reaches the launcher, which
stops the children in order) but asks the kernel for SIGTERM when the launcher dies
(``qg_common.process_guard``), so a killed launcher leaves no node behind.

Respawn, as ros2 launch's ``respawn``/``respawn_delay``: a process whose spec says ``respawn``
is started again when it exits on its own, after ``respawn_delay`` seconds, doubled for each
further exit within the policy's window (:class:`RespawnPolicy`); with ``respawn_args`` added
(the learner's ``-p resume:=true``: it comes back from its checkpoint). One that exits more
than ``max_restarts`` times within ``window`` seconds, or with code 2 (the nodes' "bad
parameters": a restart would fail alike), is given up on: ``poll()`` reports it as dead, with
the reason in ``reasons``, and the caller stops the stack. Each restart is announced in
``respawns`` (``take_respawns()``), so a supervisor can end the episode the process was in.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from qg_common.process_guard import die_with_parent

from qg_bringup.stack_file import CONFIG_ERROR_EXIT, ProcessSpec, RespawnPolicy

__all__ = ["Launcher", "Respawn"]

@dataclass(frozen=True)
class Respawn:
    """A process exited on its own and will be started again (``Launcher.take_respawns``)."""
    name: str
    code: int
    restart: int        # its how-many-th restart within the policy's window (1 = the first)
    delay: float        # [s] until it starts again

    @property
    def reason(self) -> str:
        return f"process '{self.name}' exited with code {self.code}; restarting"


@dataclass
class _Running:
    spec: ProcessSpec
    popen: subprocess.Popen
    pump: threading.Thread
    reported: bool = False
    exits: deque = field(default_factory=deque)   # monotonic times of exits within the window
    restart_at: float | None = None               # when a respawn is due
    restarts: int = 0                             # restarts so far


@dataclass
class Launcher:
    """Runs a set of processes; ``poll()`` tells whether one died on its own.

    :param env: environment of the children (see :func:`ros_env.stack_env`).
    :param out: where prefixed lines go (default stdout); ``None`` silences them.
    :param log_dir: if set, each process's output is also written to ``<log_dir>/<name>.log``
        (a restarted process's is appended).
    :param append_logs: append to the logs already in ``log_dir``, each start marked: a run
        that continues keeps what its earlier sessions said (the crash it continues after).
    :param policy: how often a respawning process may die (:class:`RespawnPolicy`).
    """
    env: dict[str, str]
    out: IO[str] | None = field(default_factory=lambda: sys.stdout)
    log_dir: Path | None = None
    append_logs: bool = False
    policy: RespawnPolicy = field(default_factory=RespawnPolicy)
    running: list[_Running] = field(default_factory=list)
    #: name -> why a process that died is not restarted (its last words for the user).
    reasons: dict[str, str] = field(default_factory=dict)
    respawns: list[Respawn] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _width: int = 0
    _stopping: bool = False

    def start(self, specs: list[ProcessSpec]) -> None:
        self._width = max([self._width, *(len(s.name) for s in specs)])
        for spec in specs:
            popen, pump = self._spawn(spec, respawned=False)
            self.running.append(_Running(spec, popen, pump))

    def _spawn(self, spec: ProcessSpec, respawned: bool
               ) -> tuple[subprocess.Popen, threading.Thread]:
        popen = subprocess.Popen(spec.command(respawned), env=self.env, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True, bufsize=1,
                                 start_new_session=True,
                                 preexec_fn=die_with_parent(os.getpid()))
        pump = threading.Thread(target=self._pump, args=(spec, popen, self._width, respawned),
                                daemon=True)
        pump.start()
        return popen, pump

    def _say(self, line: str) -> None:
        """A launcher line among the processes' (``[qgl] ...``)."""
        if self.out is not None:
            with self._lock:
                self.out.write(f"[qgl] {line}\n")
                self.out.flush()

    def _pump(self, spec: ProcessSpec, popen: subprocess.Popen, width: int,
              append: bool = False) -> None:
        log = None
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            log = open(self.log_dir / f"{spec.name}.log", "a" if append or self.append_logs
                       else "w")
            if append:
                log.write(f"--- restarted by the launcher (pid {popen.pid})\n")
            elif self.append_logs:
                log.write(f"--- started by the launcher (pid {popen.pid}) at "
                          f"{time.strftime('%Y-%m-%d %H:%M:%S')}\n")
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
        """Processes that exited since the last call and stay dead, as (name, exit code).

        A respawning process is restarted instead (when its delay is over: call this often),
        unless it has exited too often (``reasons`` says why it is not).
        """
        died = []
        now = time.monotonic()
        for r in self.running:
            if r.reported:
                continue
            if r.restart_at is not None:
                if now >= r.restart_at and not self._stopping:
                    r.pump.join(timeout=1.0)
                    r.popen, r.pump = self._spawn(r.spec, respawned=True)
                    r.restart_at, r.restarts = None, r.restarts + 1
                    self._say(f"restarted '{r.spec.name}' (pid {r.popen.pid})")
                continue
            code = r.popen.poll()
            if code is None:
                continue
            reason = self._why_not_respawned(r, code, now)
            if reason is not None:
                r.reported = True
                self.reasons[r.spec.name] = reason
                died.append((r.spec.name, code))
                continue
            delay = self.policy.delay(r.spec.respawn_delay, len(r.exits))
            r.restart_at = now + delay
            self.respawns.append(Respawn(r.spec.name, code, len(r.exits), delay))
            self._say(f"process '{r.spec.name}' exited with code {code}; restarting it in "
                      f"{delay:.1f} s (exit {len(r.exits)} of at most "
                      f"{self.policy.max_restarts + 1} within {self.policy.window:.0f} s)")
        return died

    def _why_not_respawned(self, r: _Running, code: int, now: float) -> str | None:
        """None if ``r`` is to be restarted after this exit (counted), else the reason."""
        if not r.spec.respawn or self._stopping:
            return f"process '{r.spec.name}' exited with code {code}"
        if code == CONFIG_ERROR_EXIT:
            return (f"process '{r.spec.name}' exited with code {code} (refused its "
                    "parameters): not restarted")
        r.exits.append(now)
        while r.exits and now - r.exits[0] > self.policy.window:
            r.exits.popleft()
        if len(r.exits) > self.policy.max_restarts:
            return (f"process '{r.spec.name}' keeps dying: it exited {len(r.exits)} times "
                    f"within {self.policy.window:.0f} s (last code {code}); respawn gives up "
                    f"after {self.policy.max_restarts} restarts")
        return None

    def take_respawns(self) -> list[Respawn]:
        """The restarts announced since the last call (a process exited, and will be back)."""
        taken, self.respawns = self.respawns, []
        return taken

    def restarting(self) -> list[str]:
        """The processes waiting for their restart (their delay is not over)."""
        return [r.spec.name for r in self.running if r.restart_at is not None and not r.reported]

    def restarts(self) -> dict[str, int]:
        """How many times each process has been restarted."""
        return {r.spec.name: r.restarts for r in self.running}

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
        Nothing is restarted from now on.
        """
        self._stopping = True
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
        """Each process's current pid (a restarted one's new pid)."""
        return {r.spec.name: r.popen.pid for r in self.running}
