"""How well a wall-clock loop keeps its period: every tick's period in a histogram.

A torque-controlled arm's controller must answer every millisecond (libfranka stops the robot
after a few missed cycles), so a realtime loop reports how its ticks were spaced, as
ros2_control's controller manager and libfranka's ``RobotState`` do. A tick is *on time* when it
started at most half a period late (its period, start to start, is at most 1.5 periods); ticks
the pacer dropped after falling a whole period behind are late too. The histogram has 10 us bins
up to 20 ms, so the counts of any window (the difference of two snapshots) give its percentiles.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["TickTiming", "TimingSnapshot", "BIN_NS", "N_BINS"]

BIN_NS = 10_000          # [ns] histogram bin width
N_BINS = 2001            # bins of 0..20 ms; the last one counts every longer period


@dataclass(frozen=True)
class TimingSnapshot:
    """Counts since the loop started; subtract two for a window (``since``).

    :param ticks: ticks timed (each one's period is in ``histogram``).
    :param missed: ticks the pacer dropped (it fell a whole period behind).
    :param late: timed ticks whose period exceeded ``late_after_ns``.
    :param max_ns: the longest period [ns] (of the whole run: not windowed).
    :param histogram: (N_BINS,) counts of periods in ``BIN_NS`` bins.
    """
    period_ns: int
    late_after_ns: int
    ticks: int
    missed: int
    late: int
    max_ns: int
    histogram: np.ndarray

    @classmethod
    def from_bins(cls, period_ns: int, late_after_ns: int, ticks: int, missed: int, late: int,
                  max_ns: int, bins: Sequence[int], counts: Sequence[int]) -> TimingSnapshot:
        """A snapshot whose histogram is given by its nonzero bins (their indices and counts)."""
        histogram = np.zeros(N_BINS, dtype=np.int64)
        histogram[np.asarray(bins, dtype=np.int64)] = counts
        return cls(period_ns, late_after_ns, ticks, missed, late, max_ns, histogram)

    def __reduce__(self) -> tuple:
        """Pickled with its nonzero bins only: the loop process sends one every second, ~0.5 kB
        instead of the 16 kB of the whole histogram."""
        bins = np.flatnonzero(self.histogram)
        return (TimingSnapshot.from_bins, (self.period_ns, self.late_after_ns, self.ticks,
                                           self.missed, self.late, self.max_ns, bins,
                                           self.histogram[bins]))

    def since(self, earlier: TimingSnapshot) -> TimingSnapshot:
        """The window from ``earlier`` to this snapshot (``max_ns`` stays this one's)."""
        return TimingSnapshot(self.period_ns, self.late_after_ns, self.ticks - earlier.ticks,
                              self.missed - earlier.missed, self.late - earlier.late, self.max_ns,
                              self.histogram - earlier.histogram)

    def percentile_ms(self, q: float) -> float:
        """[ms] the ``q``-th percentile of the periods (upper edge of its bin); nan if none."""
        total = int(self.histogram.sum())
        if total == 0:
            return float("nan")
        index = int(np.searchsorted(np.cumsum(self.histogram), q / 100.0 * total))
        return (min(index, N_BINS - 1) + 1) * BIN_NS / 1e6

    @property
    def on_time_fraction(self) -> float:
        """Ticks on time over ticks due (timed plus dropped); nan if none."""
        due = self.ticks + self.missed
        return (self.ticks - self.late) / due if due else float("nan")

    def summary(self) -> dict[str, float]:
        """The figures a report or a diagnostics message shows."""
        return {"ticks": self.ticks, "missed": self.missed, "late": self.late,
                "on_time_percent": 100.0 * self.on_time_fraction,
                "period_p50_ms": self.percentile_ms(50), "period_p99_ms": self.percentile_ms(99),
                "period_max_ms": self.max_ns * 1e-6}


class TickTiming:
    """Fed the start time of every tick (``tick``) and the ticks a pacer dropped (``drop``).

    :param period: [s] the loop's period.
    """

    def __init__(self, period: float) -> None:
        if period <= 0.0:
            raise ValueError(f"period must be > 0 s, got {period}")
        self.period_ns = round(period * 1e9)
        self.late_after_ns = self.period_ns * 3 // 2
        self._counts = [0] * N_BINS        # a list: one tick costs an index and an add
        self._last: int | None = None
        self.ticks = self.missed = self.late = self.max_ns = 0

    def restart(self) -> None:
        """The next tick has no predecessor (the loop paused, e.g. it was not running)."""
        self._last = None

    def tick(self, start_ns: int) -> None:
        """A tick started at ``start_ns`` (a monotonic clock)."""
        last, self._last = self._last, start_ns
        if last is None:
            return
        period = start_ns - last
        self._counts[min(period // BIN_NS, N_BINS - 1)] += 1
        self.ticks += 1
        if period > self.late_after_ns:
            self.late += 1
        if period > self.max_ns:
            self.max_ns = period

    def drop(self, ticks: int) -> None:
        """The pacer dropped ``ticks`` ticks."""
        self.missed += ticks

    def snapshot(self) -> TimingSnapshot:
        return TimingSnapshot(self.period_ns, self.late_after_ns, self.ticks, self.missed,
                              self.late, self.max_ns, np.array(self._counts, dtype=np.int64))
