"""A fixed wall-clock period for a loop thread, kept without ROS (the robot's loop process has
no rclpy; the separate sim and the composed robot process use it too)."""
from __future__ import annotations

import os
import time

__all__ = ["RealtimePacer", "DEFAULT_SPIN", "FIFO_SPIN", "fifo_priority"]

#: [s] Busy-wait before each deadline under the normal scheduler: ``time.sleep(0.5 ms)`` woke
#: 70-100 us late at the median, 100-150 us at p99 (2026-11-27, 2 cores, idle and beside two
#: CPU hogs).
DEFAULT_SPIN = 2e-4
#: [s] The same at ``SCHED_FIFO`` priority, where the sleep woke 20-30 us late at the median and
#: 80-85 us at p99: half the spinning, which is 10 % of a core at 1 kHz.
FIFO_SPIN = 1e-4


def fifo_priority(priority: int) -> str | None:
    """Put the calling thread under ``SCHED_FIFO`` at ``priority`` (1..99); why the system
    refused (no ``CAP_SYS_NICE``), or None. A thread that runs at it wakes on time whatever
    else the machine runs, and must never spin without end."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return str(exc)
    return None


class RealtimePacer:
    """Holds a fixed wall-clock period: sleeps most of the wait, busy-waits the last bit.

    ``time.sleep`` on Linux wakes tens of microseconds late, so the pacer sleeps until ``spin``
    before the deadline and spins the rest. Deadlines are absolute (``start + k * period``), so
    short delays are made up on the next ticks; a loop more than one period behind re-anchors
    instead of bursting through the missed ticks (hardware would have dropped them), and counts
    them.

    :param period: [s] tick period.
    :param spin: [s] busy-wait before each deadline.
    """

    def __init__(self, period: float, spin: float = DEFAULT_SPIN) -> None:
        if period <= 0.0 or spin < 0.0:
            raise ValueError(f"period must be > 0 and spin >= 0, got {period}, {spin}")
        self.period = period
        self.spin = spin
        self.missed = 0
        self._next: float | None = None

    def restart(self) -> None:
        """Forget the deadline: the next ``wait`` returns at once and anchors the period anew
        (after a pause on purpose, whose missed ticks are not dropped ones)."""
        self._next = None

    def wait(self) -> int:
        """Return at the next deadline (at once on the first call); the number of ticks dropped
        on the way (0 unless the loop fell a whole period behind)."""
        now = time.perf_counter()
        if self._next is None:
            self._next = now
            return 0
        self._next += self.period
        if now - self._next > self.period:
            dropped = int((now - self._next) / self.period)
            self.missed += dropped
            self._next = now
            return dropped
        remaining = self._next - now
        if remaining > self.spin:
            time.sleep(remaining - self.spin)
        while time.perf_counter() < self._next:
            pass
        return 0
