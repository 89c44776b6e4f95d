"""The realtime loop's ticks leave the robot process evenly spaced, as they were measured.

The loop process writes a record every millisecond; the robot process's reader thread takes
them in blocks (it wakes every few milliseconds) and used to publish a block at once: a
subscriber saw bursts of 5-13 messages and then nothing, and one with the sensor-data QoS of
``ros2 topic hz`` (best effort, depth 5) lost what a burst overflowed: it counted 852 Hz while
the loop kept 1 kHz. A ros2_control broadcaster publishes from the control loop,
once a tick. Here a thread of its own publishes each tick's messages at the tick's stamp plus a
fixed ``delay`` (longer than the reader's period), so they go out one tick apart, late by the
same amount each. A tick whose time has passed when it is handed over (the process fell behind)
goes out at once; one more than ``max_lag`` late is dropped and counted, as ros2_control's
realtime publisher drops what its thread cannot send, so the live topics never trail the robot
by more than that (the bag records every tick apart from this).

On a busy machine the thread must wake on time: it runs at ``SCHED_FIFO`` ``priority`` (the
robot process gives it the loop's priority less 10; it takes ~1 % of a core). The delay covers
the reader thread's lateness: at load average 8 from other jobs it handed blocks over up to
17 ms after their stamps (p99). Measured with ``benchmarks/topic_hz_bench.py`` (a subscriber as
``ros2 topic hz`` subscribes) on the 2-core machine: publishing gaps p50 1.00 ms, p99 1.3 ms.
Tried and left out: the reader thread at ``SCHED_FIFO`` too, with the GIL handed over every
0.1 ms (986-993 Hz counted instead of 980, but a starved test subscriber then stopped receiving
altogether more often: ``test_recorder_time_base``'s realtime test, four copies at once on the
loaded machine, failed 6 times in 29 runs, against 1 in 12 now and 3 in 12 before this
module), and the GIL hand-over alone (``node_runtime.favour_loop_thread``: 455-905 Hz, stalls
of 190-310 ms).
"""
from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable, Sequence

from qg_common.realtime_pacer import fifo_priority

__all__ = ["PacedPublisher", "Tick"]

#: One tick's messages: its stamp [ns, wall clock] and (topic, serialized message) pairs.
Tick = tuple[int, Sequence[tuple[str, bytes]]]


class PacedPublisher:
    """Publishes ticks at their stamps plus ``delay`` from a thread of its own.

    :param publish: sends one serialized message on a topic (called on this thread only).
    :param delay: [s] how long after its stamp a tick goes out.
    :param clock: the clock of the stamps [ns].
    :param priority: ``SCHED_FIFO`` priority of the thread (0: the normal scheduler).
    :param max_lag: [s] a tick later than this is dropped instead of published.
    """

    def __init__(self, publish: Callable[[str, bytes], None], delay: float = 0.025,
                 clock: Callable[[], int] = time.time_ns, priority: int = 0,
                 max_lag: float = 0.5) -> None:
        self._publish = publish
        self._max_lag = max_lag
        self.priority = priority
        self.priority_error: str | None = None
        self._delay_ns = int(delay * 1e9)
        self._clock = clock
        self._ticks: collections.deque[Tick] = collections.deque()
        self._ready = threading.Condition()
        self._stopping = False
        self.published = 0          # ticks published
        self.late = 0               # ticks handed over after their time had passed
        self.dropped = 0            # ticks more than max_lag late
        self._thread = threading.Thread(target=self._run, name="paced publisher", daemon=True)
        self._thread.start()

    def put(self, ticks: Sequence[Tick]) -> None:
        """Queue ticks, oldest first (the reader thread's block)."""
        if ticks:
            with self._ready:
                self._ticks.extend(ticks)
                self._ready.notify()

    def stop(self, timeout: float = 1.0) -> None:
        """Publish what is queued, then end the thread."""
        with self._ready:
            self._stopping = True
            self._ready.notify()
        self._thread.join(timeout)

    def _run(self) -> None:
        if self.priority > 0:
            self.priority_error = fifo_priority(self.priority)
        while True:
            with self._ready:
                while not self._ticks and not self._stopping:
                    self._ready.wait()
                if not self._ticks:
                    return
                t_ns, messages = self._ticks.popleft()
            wait = (t_ns + self._delay_ns - self._clock()) * 1e-9
            if wait < -self._max_lag:
                self.dropped += 1
                continue
            if wait <= 0.0:
                self.late += 1
            elif not self._stopping:
                time.sleep(wait)
            for topic, message in messages:
                self._publish(topic, message)
            self.published += 1
