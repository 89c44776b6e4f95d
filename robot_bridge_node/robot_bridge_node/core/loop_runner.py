"""Drives one loop: setpoints and resets in, ticks, samples and at-rest events out.

The same driver runs the loop in its own process (``loop_process``: the composed robot) and on
a thread of the separate bridge (``bridge_node``); what differs is where its commands come from
(a ``Mailbox``) and where its output goes (a ``LoopOutlet``). A setpoint with a new ``seq``
starts a step; one with the ``seq`` of the running step is a repeat (a commander's keep-alive)
and changes nothing. A rejected setpoint (NaN/inf) is reported and the
previous command stays.

Clock modes: ``lockstep`` ticks only while a step runs, as fast as it can, stamped with simulated
time (deterministic), looking for commands every ``LOCKSTEP_POLL_TICKS`` ticks of a step;
otherwise the loop ticks whenever ``pace`` says a tick is due, stamped with the wall clock, and
the watchdog holds the pose when no setpoint follows a step's end in time
(``safety.watchdog_timeout``; each such hold is logged).

A robot that stops by itself (``HardwareFault``: a Franka's reflex, a missed signal timeout)
ends the step under way: its at-rest event carries the reason (``StepResult.fault``), the loop
ticks no more and refuses setpoints until a reset, which first has the robot recover.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from qg_common.types import StartPose, StepResult, WrenchSetpoint

from robot_bridge_node.core.hardware_interface import HardwareFault
from robot_bridge_node.core.loop_core import LoopCore
from robot_bridge_node.core.safety import SetpointRejected

__all__ = ["SetpointCommand", "ResetCommand", "StepEvent", "LoopOutlet", "Mailbox",
           "ThreadMailbox", "LoopRunner", "LOCKSTEP_POLL_TICKS"]

#: In lockstep, a step under way looks for commands every this many ticks, not every tick: a
#: look at a process's pipe costs 3-6 us, and a lockstep commander sends the next step only
#: after this one's at-rest event (what arrives mid-step, a reset or a stop, is taken at most
#: 10 simulated ms later; its tick depended on the wall clock anyway).
LOCKSTEP_POLL_TICKS = 10


@dataclass(frozen=True)
class SetpointCommand:
    """An RL step's setpoint, numbered by its sender (the same ``seq`` again: keep-alive)."""
    seq: int
    setpoint: WrenchSetpoint


@dataclass(frozen=True)
class ResetCommand:
    """Get the robot to a start and settle (``LoopCore.reset``); ``job`` names it in the
    answer. ``start`` None: the robot has already been put somewhere (the separate sim
    teleported): only restart and settle where it is."""
    start: StartPose | None
    job: int = 0


@dataclass(frozen=True)
class StepEvent:
    """How a step ended (``seq`` 0: a reset settled), with the tool pose and the tick's stamp."""
    seq: int
    result: StepResult
    position: np.ndarray
    rotation: np.ndarray
    t_ns: int


class LoopOutlet(Protocol):
    """Where the runner's output goes."""

    def sample(self, t_ns: int, loop: LoopCore, publish: bool) -> None:
        """After every tick, and once when a reset has settled (``publish``: a tick of the
        publishing rate)."""
        ...

    def at_rest(self, event: StepEvent) -> None:
        """A step ended (at rest or at its time limit)."""
        ...

    def reset_done(self, job: int, event: StepEvent | None, error: str | None) -> None:
        """Reset ``job`` settled (``event``, also passed to ``at_rest``) or failed."""
        ...

    def log(self, level: str, message: str) -> None:
        """``level``: ``info``, ``warning`` or ``error``."""
        ...


class Mailbox(Protocol):
    """Where the runner takes its commands from."""

    def take(self, timeout: float) -> tuple[SetpointCommand | None, ResetCommand | None]:
        """The newest setpoint and the pending reset, if any; waits up to ``timeout`` seconds
        for either (0: not at all)."""
        ...


@dataclass
class ThreadMailbox:
    """Commands left by other threads of the same process (ROS callbacks)."""
    _mail: threading.Condition = field(default_factory=threading.Condition)
    _setpoint: SetpointCommand | None = None
    _reset: ResetCommand | None = None

    def post_setpoint(self, command: SetpointCommand) -> None:
        with self._mail:
            self._setpoint = command
            self._mail.notify()

    def post_reset(self, command: ResetCommand) -> None:
        with self._mail:
            self._reset = command
            self._mail.notify()

    def take(self, timeout: float) -> tuple[SetpointCommand | None, ResetCommand | None]:
        with self._mail:
            if timeout > 0.0 and self._setpoint is None and self._reset is None:
                self._mail.wait(timeout)
            taken = self._setpoint, self._reset
            self._setpoint = self._reset = None
        return taken


class LoopRunner:
    """Runs one loop from a ``Mailbox`` into a ``LoopOutlet`` (see the module doc).

    :param loop: the loop; its ``config.realtime`` turns the watchdog on.
    :param mailbox: setpoints and resets.
    :param outlet: samples, events, answers to resets, log lines.
    :param lockstep: tick only while a step runs, stamped with simulated time.
    :param pace: not lockstep: called before every tick, returns once the tick is due; False
        skips the tick (nothing to do yet).
    :param after_reset: not lockstep: called once a reset has settled (it ran as fast as it
        could, off the wall clock): the pace starts afresh.
    :param publish_every: every this many ticks a sample is marked for publishing.
    :param take_restart: called before a reset without a start (the robot was put at its start
        by someone else: the separate sim), in the loop's thread: the hardware takes the new
        state (``RemoteRobot.take_restart``).
    """

    def __init__(self, loop: LoopCore, mailbox: Mailbox, outlet: LoopOutlet, *,
                 lockstep: bool, pace: Callable[[], bool] | None = None,
                 after_reset: Callable[[], None] | None = None,
                 publish_every: int = 1,
                 take_restart: Callable[[], None] | None = None) -> None:
        if not lockstep and pace is None:
            raise ValueError("a free-running (realtime) loop needs a pace")
        self.loop = loop
        self.mailbox = mailbox
        self.outlet = outlet
        self.lockstep = lockstep
        self.pace = pace
        self.after_reset = after_reset
        self.publish_every = max(1, publish_every)
        self.take_restart = take_restart
        self._dt_ns = round(loop.config.dt * 1e9)
        self.clock_ns = 0          # simulated time: ticks run since start, resets included
        self.ticks = 0
        self._seq: int | None = None            # the running step's setpoint
        self._holds = 0                         # the loop's watchdog holds reported
        self._step_start: float | None = None   # loop time of the running step's start
        self.fault = ""                         # why the robot stopped, until a reset

    def run(self, stop: threading.Event) -> None:
        """Hold the robot where it is (``LoopCore.begin``: no motion at start-up) once it has a
        state (the first tick due: a remote robot's first state), then tick until ``stop`` is
        set (the body of the loop's thread or process)."""
        while not (self.lockstep or stop.is_set() or self.pace()):
            pass
        if stop.is_set():
            return
        self.begin()
        while not stop.is_set():
            if self.lockstep:
                waiting = self._step_start is None
                if waiting or self.ticks % LOCKSTEP_POLL_TICKS == 0:
                    setpoint, reset = self.mailbox.take(0.05 if waiting else 0.0)
                else:
                    setpoint = reset = None
                if waiting and setpoint is None and reset is None:
                    continue
            elif not self.pace():
                continue
            else:
                setpoint, reset = self.mailbox.take(0.0)
            self._take(setpoint, reset)
            if self.fault or (self.lockstep and self._step_start is None):
                continue
            try:
                at_rest = self.loop.tick()
            except HardwareFault as exc:
                self._stopped(str(exc))
                continue
            self._after_tick(at_rest)

    def begin(self) -> None:
        """Take the robot where it is and publish that state once (a driver's first state)."""
        self.loop.begin()
        self.outlet.sample(self.now_ns(), self.loop, True)

    def _take(self, setpoint: SetpointCommand | None, reset: ResetCommand | None) -> None:
        if reset is not None:
            self._reset(reset)
        if setpoint is None:
            return
        loop = self.loop
        if self.fault:
            self.outlet.log("error", f"setpoint {setpoint.seq} refused: the robot stopped "
                                     f"({self.fault}); move_to_start recovers it")
            return
        if setpoint.seq == self._seq:
            loop.feed_watchdog()
            return
        try:
            loop.command(setpoint.setpoint)
        except SetpointRejected as exc:
            self.outlet.log("error", f"setpoint {setpoint.seq} rejected: {exc}; keeping the "
                                     f"previous command")
            return
        self._seq = setpoint.seq
        self._step_start = loop.time

    def _reset(self, command: ResetCommand) -> None:
        try:
            before = self.loop.ticks_run
            if command.start is None:
                if self.take_restart is not None:
                    self.take_restart()
                self.loop.settle_here()
            else:
                self.loop.reset(command.start)
        except (RuntimeError, ValueError, TimeoutError) as exc:
            self.outlet.log("error", f"reset failed: {exc}")
            self.outlet.reset_done(command.job, None, f"{exc}")
            return
        finally:
            if self.loop.recovered:
                self.outlet.log("warning", self.loop.recovered)
                self.loop.recovered = ""
        self.fault = ""
        self._seq = None
        self._step_start = None
        self.clock_ns += (self.loop.ticks_run - before) * self._dt_ns
        t_ns = self.now_ns()
        self.outlet.sample(t_ns, self.loop, True)  # the settled start: published and recorded
        event = self._event(0, self.loop.time - self.loop.config.settle_time, t_ns)
        self.outlet.at_rest(event)
        self.outlet.reset_done(command.job, event, None)
        if self.after_reset is not None:
            self.after_reset()

    def _stopped(self, reason: str) -> None:
        """The robot stopped by itself: the step under way ends with the reason."""
        self.fault = reason
        self.outlet.log("error", f"the robot stopped: {reason}")
        if self._step_start is not None:
            tool = self.loop.controller.tool
            self.outlet.at_rest(StepEvent(self._seq or 0,
                                          self.loop.result(self._step_start, reason),
                                          tool.position.copy(), tool.rotation.copy(),
                                          self.now_ns()))
            self._step_start = None

    def _after_tick(self, at_rest: bool) -> None:
        self.ticks += 1
        self.clock_ns += self._dt_ns
        t_ns = self.now_ns()   # the tick's one stamp: every output of this tick carries it
        self.outlet.sample(t_ns, self.loop, self.ticks % self.publish_every == 0)
        if at_rest and self._step_start is not None:
            event = self._event(self._seq or 0, self._step_start, t_ns)
            self._step_start = None
            self.outlet.at_rest(event)
        if self.loop.watchdog_holds != self._holds:
            self._holds = self.loop.watchdog_holds
            timeout = self.loop.safety.limits.watchdog_timeout
            # Expected while a learner trains between steps (the thesis's cycle): info, not a
            # warning; the count tells how often.
            self.outlet.log("info", f"no setpoint within {timeout * 1e3:.0f} ms of step "
                                       f"{self._seq}'s end: holding the pose ({self._holds} "
                                       f"holds so far)")

    def now_ns(self) -> int:
        """The loop's clock [ns]: simulated time in lockstep (it stands still between steps),
        the wall clock otherwise."""
        return self.clock_ns if self.lockstep else time.time_ns()

    def _event(self, seq: int, start: float, t_ns: int) -> StepEvent:
        """The event of the step that started at loop time ``start``."""
        tool = self.loop.controller.tool
        return StepEvent(seq, self.loop.result(start), tool.position.copy(),
                         tool.rotation.copy(), t_ns)
