"""A realtime loop's timing: periods, late and dropped ticks, percentiles of any window."""
from __future__ import annotations

import math

from robot_bridge_node.core.tick_timing import TickTiming


def run(timing: TickTiming, periods_us: list[int], start_ns: int = 0) -> int:
    t = start_ns
    timing.tick(t)
    for period in periods_us:
        t += period * 1000
        timing.tick(t)
    return t


def test_periods_late_ticks_and_drops_are_counted() -> None:
    timing = TickTiming(0.001)
    run(timing, [1000] * 97 + [1600, 2000, 900])   # two ticks more than half a period late
    timing.drop(3)
    s = timing.snapshot()
    assert (s.ticks, s.late, s.missed, s.max_ns) == (100, 2, 3, 2_000_000)
    assert math.isclose(s.on_time_fraction, 98 / 103)
    assert s.percentile_ms(50) == 1.01             # the 1.00-1.01 ms bin's upper edge
    assert s.percentile_ms(99) == 1.61


def test_a_window_is_the_difference_of_two_snapshots() -> None:
    timing = TickTiming(0.001)
    end = run(timing, [5000] * 10)                  # a bad start...
    first = timing.snapshot()
    timing.restart()
    run(timing, [1000] * 50, start_ns=end + 10**9)  # ...then on time, after a pause
    window = timing.snapshot().since(first)
    assert (window.ticks, window.late, window.missed) == (50, 0, 0)
    assert window.percentile_ms(99) == 1.01 and window.on_time_fraction == 1.0
    assert math.isnan(TickTiming(0.001).snapshot().percentile_ms(50))
