"""The robot's 1 kHz loop in a process of its own, with no ROS in it.

In one Python process every thread shares one interpreter lock: a 1 kHz loop beside rclpy's
executor threads, the publishers and the recorder waited for them (87 % of ticks on time
with the stack up, measured). Here the loop (robot plugin, estimator, controller, safety
filter, rest detector: a ``LoopRunner``) runs on the main thread of its process. It takes
commands from a socket (``PipeMailbox``), writes every tick into a shared-memory ring
(``SampleRing``) and queues its events (at rest, reset done, its timing once a second, log
lines) for the one other thread, which sends them back on the socket (``RingOutlet``,
``EventSender``): the loop never waits for the robot process. ``loop_link.LoopLink`` is the
other end, in the robot process.

Started by ``LoopLink`` as ``python -m robot_bridge_node.core.loop_process --socket FD --ring
FD``, or forked from the robot process before it starts ROS (``serve_forked``, the ring's
descriptor then comes on the socket); the first message on the socket is the ``LoopSpec``. It
ignores SIGINT (the robot process stops it, after its nodes' shutdown work) and ends when told
to, when the socket closes, or with the process that started it (``qg_common.process_guard``).
"""
from __future__ import annotations

import argparse
import gc
import os
import queue
import signal
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
from qg_common.realtime_pacer import DEFAULT_SPIN, FIFO_SPIN, RealtimePacer, fifo_priority

from robot_bridge_node.core.hardware_interface import Robot, robot_plugin
from robot_bridge_node.core.interface_kinds import interface_kind
from robot_bridge_node.core.loop_clock import MAX_STATE_GAP, StateClock
from robot_bridge_node.core.loop_core import LoopCore
from robot_bridge_node.core.loop_runner import LoopRunner, ResetCommand, SetpointCommand, StepEvent
from robot_bridge_node.core.sample_ring import (
    HAS_OWN_WRENCH,
    HAS_TOOL,
    HAS_TRUTH,
    HAS_WRENCH,
    PUBLISH,
    SampleRing,
    truth_to_array,
)
from robot_bridge_node.core.tick_timing import TickTiming

__all__ = ["LoopSpec", "RingOutlet", "EventSender", "PipeMailbox", "RealtimePace", "TIMING_PERIOD",
           "main"]

#: [s] how often a realtime loop sends its timing counts.
TIMING_PERIOD = 1.0
_ZEROS = np.zeros(9)


@dataclass(frozen=True)
class LoopSpec:
    """What the loop process builds: the robot plugin and the nodes' parameters.

    :param robot: the robot plugin's registered name.
    :param robot_params: the robot's own sections (the ``sim`` or ``hardware`` node's parameters).
    :param bridge_params: the bridge's (the interface kind's controller sections).
    :param estimator_params: the wrench estimator's.
    :param realtime: wall-clock 1 kHz with the watchdog; otherwise lockstep.
    :param priority: realtime: ``SCHED_FIFO`` priority of the loop (0: the normal scheduler).
    :param publish_every: a sample every this many ticks is marked for publishing.
    :param truth_every: the ground truth is computed every this many ticks (a multiple of
        ``publish_every``: on every so many published samples); 0 never (a real robot).
    """
    robot: str
    robot_params: dict[str, Any]
    bridge_params: dict[str, Any]
    estimator_params: dict[str, Any]
    realtime: bool
    priority: int
    publish_every: int
    truth_every: int


class RingOutlet:
    """The runner's output: every tick into the ring, events onto the socket.

    :param truth_every: compute the ground truth on every this many published samples (0:
        never).
    :param own_wrench: the robot's own wrench estimate (``Robot.own_wrench``), if it has one.
    """

    def __init__(self, ring: SampleRing, events: EventSender, truth_every: int,
                 own_wrench: Callable[[], np.ndarray] | None = None) -> None:
        self.ring = ring
        self.events = events
        self.truth_every = truth_every
        self.own_wrench = own_wrench
        self.ticks = 0
        self.published = 0

    def sample(self, t_ns: int, loop: LoopCore, publish: bool) -> None:
        state = loop.hardware.read()
        flags = PUBLISH if publish else 0
        wrench = loop.wrench_estimate
        if wrench is None:
            wrench = _ZEROS[:6]
        else:
            flags |= HAS_WRENCH
        tool = loop.controller.tool
        if tool is None:
            position, rotation, twist = _ZEROS[:3], _ZEROS[:9], _ZEROS[:6]
        else:
            position, rotation, twist = tool.position, tool.rotation, tool.twist
            flags |= HAS_TOOL
        if self.own_wrench is None:
            own = _ZEROS[:6]
        else:
            own = self.own_wrench()
            flags |= HAS_OWN_WRENCH
        truth = publish and self.truth_every > 0 and self.published % self.truth_every == 0
        self.published += publish
        values = self.ring.write(t_ns, self.ticks, flags | HAS_TRUTH if truth else flags,
                                 state.q, state.dq, state.tau, loop.commanded, wrench, own,
                                 position, rotation, twist)
        if truth:
            truth_to_array(loop.ground_truth(), values)
        self.ring.commit()
        self.ticks += 1

    def at_rest(self, event: StepEvent) -> None:
        self.events.send(("at_rest", event))

    def reset_done(self, job: int, event: StepEvent | None, error: str | None) -> None:
        self.events.send(("reset_done", job, event, error))

    def log(self, level: str, message: str) -> None:
        self.events.send(("log", level, message))


class EventSender:
    """The loop's messages to the robot process, sent by a thread of their own: the loop only
    queues them.

    A send waits while the socket is full, and it fills when the robot process reads behind:
    two robots on an overloaded 2-core machine (each publishing 1 kHz) left 230 kB in the
    socket and the loop process blocked in its send, with ticks 3-7 s apart. The loop must never
    wait for its reader; what it has to say waits in the queue instead.

    :param stop: set when the robot process is gone (a send failed).
    """

    def __init__(self, conn: Connection, stop: threading.Event) -> None:
        self.conn = conn
        self.stop = stop
        self._queue: queue.SimpleQueue[tuple | None] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="loop events", daemon=True)
        self._thread.start()

    def send(self, message: tuple) -> None:
        """Queue ``message``; it is sent after every message queued before it."""
        self._queue.put(message)

    def close(self, timeout: float = 5.0) -> None:
        """Send what is queued (for at most ``timeout`` seconds) and end the thread."""
        self._queue.put(None)
        self._thread.join(timeout)

    def _run(self) -> None:
        while (message := self._queue.get()) is not None:
            try:
                self.conn.send(message)
            except OSError:            # the robot process is gone
                self.stop.set()
                return


class PipeMailbox:
    """The runner's commands from the socket: the newest setpoint, a reset; ``stop`` is set by
    a ``("stop",)`` message or when the socket closes."""

    def __init__(self, conn: Connection, stop: threading.Event) -> None:
        self.conn = conn
        self.stop = stop

    def take(self, timeout: float) -> tuple[SetpointCommand | None, ResetCommand | None]:
        setpoint: SetpointCommand | None = None
        reset: ResetCommand | None = None
        try:
            wait = timeout
            while self.conn.poll(wait):
                message = self.conn.recv()
                wait = 0.0
                if isinstance(message, SetpointCommand):
                    setpoint = message
                elif isinstance(message, ResetCommand):
                    reset, setpoint = message, None   # a setpoint from before the reset is stale
                elif message == ("stop",):
                    self.stop.set()
        except (EOFError, OSError):        # the robot process is gone
            self.stop.set()
        return setpoint, reset


def _build(spec: LoopSpec) -> tuple[LoopCore, Robot]:
    """The robot's loop, and the robot (``paced_by_hardware``: its loop ticks on its states'
    clock; ``own_wrench``)."""
    plugin = robot_plugin(spec.robot)
    robot = plugin.create(spec.robot_params)
    bridge_params = {**spec.bridge_params,
                     "loop": {**spec.bridge_params.get("loop", {}), "realtime": spec.realtime}}
    clock = StateClock(robot.hardware, MAX_STATE_GAP) if robot.paced_by_hardware else None
    loop = interface_kind(plugin.interface).build_loop(robot, bridge_params,
                                                       spec.estimator_params, clock=clock)
    return loop, robot


class RealtimePace:
    """The realtime loop's pace: the pacer's deadline, each tick's timing, and the counts sent
    once a second.

    A reset pauses the wall clock on purpose: the simulation is reset and settled as fast as it
    can (``settle_time`` of ticks in a burst, ~25 ms), as a real arm would be driven to its start
    pose before control resumes. ``restart`` then starts the clock afresh, so those ticks are
    neither dropped nor a late period (they were 200-260 dropped ticks a minute in training,
    ~25 at every episode's reset).
    """

    def __init__(self, dt: float, events: EventSender, spin: float = DEFAULT_SPIN,
                 wait: bool = True) -> None:
        self.pacer = RealtimePacer(dt, spin) if wait else None
        self.timing = TickTiming(dt)
        self.events = events
        self._next_report = time.monotonic() + TIMING_PERIOD

    def __call__(self) -> bool:
        if self.pacer is not None:
            self.timing.drop(self.pacer.wait())
        self.timing.tick(time.perf_counter_ns())
        if time.monotonic() >= self._next_report:
            self._next_report += TIMING_PERIOD
            self.events.send(("timing", self.timing.snapshot()))
        return True

    def restart(self) -> None:
        """The loop paused on purpose: the next tick is due at once and has no predecessor."""
        if self.pacer is not None:
            self.pacer.restart()
        self.timing.restart()


def run(conn: Connection, ring: SampleRing) -> int:
    """Receive the spec, build the loop, say ``ready`` (or why not), run until stopped."""
    spec: LoopSpec = conn.recv()
    try:
        loop, robot = _build(spec)
    except ConnectionError as exc:     # an unreachable robot: its message says where and why
        conn.send(("error", f"the robot loop could not be built: {exc}"))
        return 1
    except Exception:  # noqa: BLE001 - whatever fails, the robot process must hear why
        conn.send(("error", f"the robot loop could not be built:\n{traceback.format_exc()}"))
        return 1
    # The built loop's ~63 000 objects out of the collector's reach: a full collection walked
    # them in 19 ms (on a machine that ticks in 240 us), a stall of 20-40 ticks every minute or
    # so; after the freeze it takes no measurable time.
    gc.collect()
    gc.freeze()
    spin = DEFAULT_SPIN
    if spec.realtime and spec.priority > 0:
        refused = fifo_priority(spec.priority)
        if refused is None:
            spin = FIFO_SPIN
        else:
            conn.send(("log", "warning", f"no realtime priority {spec.priority} ({refused}); "
                                         f"running unprioritised"))
    stop = threading.Event()
    events = EventSender(conn, stop)      # after the priority: its thread has the loop's
    outlet = RingOutlet(ring, events, spec.truth_every // spec.publish_every, robot.own_wrench)
    # A robot that paces its loop (its read waits for its next state) needs no wall-clock
    # pacer: the loop's timing is then the robot's periods as the loop saw them.
    pace = RealtimePace(loop.config.dt, events, spin, wait=not robot.paced_by_hardware) \
        if spec.realtime else None
    runner = LoopRunner(loop, PipeMailbox(conn, stop), outlet, lockstep=not spec.realtime,
                        pace=pace, after_reset=pace.restart if pace is not None else None,
                        publish_every=spec.publish_every)
    events.send(("ready", runner.clock_ns))
    try:
        runner.run(stop)
    except Exception:  # noqa: BLE001
        events.send(("error", f"the robot loop failed:\n{traceback.format_exc()}"))
        return 1
    finally:
        events.close()
    return 0


def serve_forked(sock: socket.socket) -> int:
    """The loop process forked from the robot process (``loop_link.ForkedLoopProcess``): wait
    for the sample ring's descriptor on ``sock``, then ``run`` as ``main`` does. An end of
    ``sock`` first (the robot process stopped before it started its loop) ends it at once."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _, fds, _, _ = socket.recv_fds(sock, 1, 1)
    if not fds:
        return 0
    conn = Connection(os.dup(sock.fileno()))
    try:
        return run(conn, SampleRing.attach(fds[0]))
    finally:
        conn.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--socket", type=int, required=True, help="file descriptor")
    parser.add_argument("--ring", type=int, required=True, help="file descriptor")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    conn = Connection(args.socket)
    ring = SampleRing.attach(args.ring)
    try:
        return run(conn, ring)
    finally:
        conn.close()


if __name__ == "__main__":
    sys.exit(main())
