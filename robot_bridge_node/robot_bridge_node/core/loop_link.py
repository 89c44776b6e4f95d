"""The robot process's end of its loop process (``loop_process``): start it, command it, and
hand what it produced to a ``LoopListener`` from a reader thread of its own.

The reader thread waits on the socket (an event wakes it at once) for at most ``poll`` seconds,
then takes every new record from the sample ring and passes them on in one batch, before any
event sent after them (an at-rest event follows the tick it ends). The listener's work
(publishing, recording) runs on that thread, in this process: it takes nothing from the loop but
a share of the machine's cores.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from multiprocessing.connection import Connection
from typing import Protocol

import numpy as np
from qg_common.process_guard import die_with_parent

from robot_bridge_node.core.loop_process import LoopSpec, serve_forked
from robot_bridge_node.core.loop_runner import ResetCommand, SetpointCommand, StepEvent
from robot_bridge_node.core.sample_ring import DEFAULT_CAPACITY, SampleRing
from robot_bridge_node.core.tick_timing import TimingSnapshot

__all__ = ["ForkedLoopProcess", "LoopListener", "LoopLink", "START_TIMEOUT"]

#: [s] building the robot (pybullet scene, URDF models, compiled kernels) takes 1-3 s.
START_TIMEOUT = 120.0


class LoopListener(Protocol):
    """What the robot process does with the loop's output (on the link's reader thread)."""

    def samples(self, records: np.ndarray) -> None:
        """New tick records (``sample_ring.record_dtype``), oldest first."""
        ...

    def at_rest(self, event: StepEvent) -> None: ...

    def timing(self, snapshot: TimingSnapshot) -> None:
        """A realtime loop's timing counts since start (once a second)."""
        ...

    def log(self, level: str, message: str) -> None: ...

    def failed(self, message: str) -> None:
        """The loop process died or reported a fatal error: the robot process must end."""
        ...


class _Reset:
    """A reset waiting for its answer."""

    def __init__(self) -> None:
        self.done = threading.Event()
        self.event: StepEvent | None = None
        self.error: str | None = None


class ForkedLoopProcess:
    """A loop process forked from this one, waiting for its sample ring and ``LoopSpec``.

    It starts with what this process has imported (numpy, Pinocchio, the loop's code): ready in
    0.07 s of CPU against 0.37 s for a new interpreter (``python -m ...loop_process``), which
    every robot start paid. Fork it while this process has no threads yet, before
    ``rclpy.init``: a lock held by another thread at the fork would stay taken in the child.
    ``LoopLink(..., forked=...)`` hands it the ring and the spec. Its ``poll``, ``wait``,
    ``kill`` and ``pid`` are ``subprocess.Popen``'s, which the link uses.
    """

    def __init__(self) -> None:
        parent = os.getpid()
        self.socket, theirs = socket.socketpair()
        sys.stdout.flush()
        sys.stderr.flush()
        self.pid = os.fork()
        if self.pid == 0:                     # the child: never returns
            code = 1
            try:
                self.socket.close()
                die_with_parent(parent)()
                code = serve_forked(theirs)
            except BaseException:             # noqa: BLE001 - the robot process hears of it
                traceback.print_exc()
            finally:
                os._exit(code)
        theirs.close()
        self.returncode: int | None = None
        self._reaping = threading.Lock()     # the link's reader thread and stop() may both wait

    def poll(self) -> int | None:
        """The exit code if it has ended, else None."""
        with self._reaping:
            if self.returncode is None:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
                if pid:
                    self.returncode = os.waitstatus_to_exitcode(status)
            return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        """The exit code, once it has ended.

        :raises subprocess.TimeoutExpired: if it is still running after ``timeout`` s.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if deadline is not None and time.monotonic() >= deadline:
                raise subprocess.TimeoutExpired(f"loop process {self.pid}", timeout)
            time.sleep(0.01)
        return self.returncode

    def kill(self) -> None:
        if self.poll() is None:
            os.kill(self.pid, signal.SIGKILL)


class LoopLink:
    """Starts the loop process for ``spec`` and relays between it and ``listener``.

    :param spec: what the loop process builds.
    :param n_joints: the robot's joint count (the records' size).
    :param poll: [s] the longest the reader thread leaves new records in the ring.
    :param idle_poll: [s] how often it looks once none come (a lockstep loop between steps,
        whose events arrive on the connection and wake it anyway): it backs off from ``poll``
        by doubling, and is back to ``poll`` at the first records. Every 5 ms, an idle robot
        process spent 2 % of a core on looking.
    :param capacity: [records] of the sample ring.
    :param forked: a loop process forked beforehand, to use instead of starting one.
    """

    def __init__(self, spec: LoopSpec, n_joints: int, listener: LoopListener, *,
                 poll: float = 0.005, idle_poll: float = 0.05, capacity: int = DEFAULT_CAPACITY,
                 forked: ForkedLoopProcess | None = None) -> None:
        self.spec = spec
        self.listener = listener
        self.poll, self.idle_poll = poll, idle_poll
        self.ring = SampleRing.create(n_joints, capacity)
        self._forked = forked
        if forked is None:
            self._socket, self._theirs = socket.socketpair()
        else:
            self._socket, self._theirs = forked.socket, None
        self.conn = Connection(os.dup(self._socket.fileno()))
        self._send_lock = threading.Lock()
        self._resets: dict[int, _Reset] = {}
        self._next_job = 0
        self._stopping = False
        #: Why the loop process failed (``stop`` raises it), or None.
        self.error: str | None = None
        self.process: subprocess.Popen | ForkedLoopProcess | None = None
        self._reader = threading.Thread(target=self._read, name="loop link", daemon=True)

    def start(self) -> None:
        """Start the loop process, send it the spec, wait until the loop is built, relay.

        :raises RuntimeError: if the loop process reports an error or exits.
        :raises TimeoutError: if it is not ready within ``START_TIMEOUT`` seconds.
        """
        if self._forked is not None:
            socket.send_fds(self._socket, [b"r"], [self.ring.fd])
            self.process = self._forked
        else:
            theirs = self._theirs
            self.process = subprocess.Popen(
                [sys.executable, "-m", "robot_bridge_node.core.loop_process",
                 "--socket", str(theirs.fileno()), "--ring", str(self.ring.fd)],
                pass_fds=(theirs.fileno(), self.ring.fd),
                preexec_fn=die_with_parent(os.getpid()))
            theirs.close()
        try:
            self.conn.send(self.spec)
            deadline = time.monotonic() + START_TIMEOUT
            while True:
                if not self.conn.poll(max(0.0, deadline - time.monotonic())):
                    raise TimeoutError(f"the loop process was not ready within "
                                       f"{START_TIMEOUT:.0f} s")
                try:
                    message = self.conn.recv()
                except EOFError:
                    raise RuntimeError(f"the loop process exited ({self.process.wait()}) "
                                       f"before it was ready") from None
                if message[0] == "ready":
                    break
                if message[0] == "error":
                    raise RuntimeError(message[1])
                self._dispatch(message)
        except BaseException:
            self._stopping = True
            self.process.kill()
            self.process.wait()
            raise
        self._reader.start()

    # --- commands ------------------------------------------------------------------------------
    def _send(self, message: object) -> None:
        with self._send_lock:
            self.conn.send(message)

    def send_setpoint(self, command: SetpointCommand) -> None:
        """Hand a setpoint to the loop (the newest one waiting wins)."""
        self._send(command)

    def reset(self, initial_pose: int, housing_yaw: float = 0.0,
              timeout: float = 30.0) -> StepEvent:
        """Reset and settle; the settled event (the listener gets it too).

        :raises TimeoutError: if the loop does not answer within ``timeout`` seconds.
        :raises RuntimeError: what the reset failed with (e.g. a pose out of reach).
        """
        pending = _Reset()
        with self._send_lock:
            self._next_job += 1
            job = self._next_job
            self._resets[job] = pending
            self.conn.send(ResetCommand(initial_pose, housing_yaw, job))
        try:
            if not pending.done.wait(timeout):
                raise TimeoutError(f"the loop did not reset within {timeout:.0f} s")
        finally:
            self._resets.pop(job, None)
        if pending.error is not None:
            raise RuntimeError(pending.error)
        assert pending.event is not None
        return pending.event

    def now_ns(self) -> int:
        """The loop's clock: the newest tick's stamp in lockstep, the wall clock in realtime."""
        if self.spec.realtime:
            return time.time_ns()
        return self.ring.latest_t_ns() or 0

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the loop process (its last records and events are relayed first).

        :raises RuntimeError: if the loop process had failed (``error``).
        """
        self._stopping = True
        assert self.process is not None, "stop() before start()"
        try:
            self._send(("stop",))
        except OSError:
            pass
        try:
            self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        if self._reader.is_alive():
            self._reader.join(timeout)
        self._socket.close()
        self.conn.close()
        if self.error is not None:
            raise RuntimeError(self.error)

    # --- the reader thread ---------------------------------------------------------------------
    def _read(self) -> None:
        try:
            wait = self.poll
            while True:
                ready = self.conn.poll(wait)
                relayed = self._relay_samples()
                while ready:
                    self._dispatch(self.conn.recv())
                    ready = self.conn.poll(0.0)
                wait = self.poll if relayed else min(2.0 * wait, self.idle_poll)
        except (EOFError, OSError):
            self._relay_samples()
            if not self._stopping:
                self._fail(f"the loop process exited ({self.process.wait()})")
        except Exception:  # noqa: BLE001 - the listener failed: nothing would relay any more
            if not self._stopping:
                self._fail(f"relaying the loop's output failed:\n{traceback.format_exc()}")

    def _relay_samples(self) -> int:
        """Hand the records in the ring to the listener; how many there were."""
        records = self.ring.take()
        if len(records):
            self.listener.samples(records)
        return len(records)

    def _dispatch(self, message: tuple) -> None:
        kind = message[0]
        if kind == "at_rest":
            self._relay_samples()        # the records up to the event's tick go first
            self.listener.at_rest(message[1])
        elif kind == "reset_done":
            _, job, event, error = message
            pending = self._resets.get(job)
            if pending is not None:
                pending.event, pending.error = event, error
                pending.done.set()
        elif kind == "timing":
            self.listener.timing(message[1])
        elif kind == "log":
            self.listener.log(message[1], message[2])
        elif kind == "error":
            self._fail(message[1])

    def _fail(self, message: str) -> None:
        self._stopping = True
        self.error = message
        self.listener.failed(message)
