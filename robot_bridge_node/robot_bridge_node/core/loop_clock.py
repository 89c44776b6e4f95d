"""The loop's time: one control period a tick, or the stamps of the states it reads.

The controller's, the safety filter's and the rest detector's ``dt``, the realtime watchdog and
an RL step's time limit all run on it, so a loop that reads states over a link (and may miss
some) still ends a step after the robot's time, not after a count of ticks.
"""
from __future__ import annotations

from typing import Protocol

from robot_bridge_node.core.hardware_interface import StampedStates

__all__ = ["LoopClock", "TickClock", "StateClock", "MAX_STATE_GAP"]


class LoopClock(Protocol):
    """The loop's time since the last reset, which the controller's, the safety filter's and the
    rest detector's ``dt``, the watchdog and a step's time limit all run on."""

    @property
    def time(self) -> float:
        """[s] since the last reset, up to the last tick ``advance``d."""
        ...

    def restart(self) -> None:
        """Time 0 is now (the hardware's state was just read after a reset)."""
        ...

    def period(self) -> float:
        """[s] how much time the tick under way covers (its state was just read)."""
        ...

    def advance(self, dt: float) -> None:
        """The tick under way, of ``period`` ``dt``, is done."""
        ...


class TickClock:
    """Every tick is one control period: the robot's state advances by exactly ``dt`` between
    reads (an in-process simulation steps in ``write``; a real arm's 1 kHz loop)."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.ticks = 0

    @property
    def time(self) -> float:
        return self.ticks * self.dt

    def restart(self) -> None:
        self.ticks = 0

    def period(self) -> float:
        return self.dt

    def advance(self, dt: float) -> None:
        del dt
        self.ticks += 1


#: [s] The most one tick on a ``StateClock`` counts: a longer gap between states (the loop, the
#: robot or the link between them stalled) counts as this long, so one hiccup cannot end a step.
#: It is the separate sim's ``command_timeout``, after which that sim holds the arm itself.
MAX_STATE_GAP = 0.02


class StateClock:
    """The time of the states read: a tick covers the time from the previous state's stamp to
    its own. A loop that misses states (a busy machine, states over topics) still ends a step
    at its time limit of the robot's time instead of after that many ticks.

    :param hardware: reports when the state it returned was measured.
    :param max_period: [s] the most one tick counts: a longer gap (the robot's process stalled,
        or the loop did) is counted as this long, so one hiccup cannot end a step.
    """

    def __init__(self, hardware: StampedStates, max_period: float) -> None:
        if max_period <= 0.0:
            raise ValueError(f"max_period must be > 0, got {max_period}")
        self.hardware = hardware
        self.max_period = max_period
        self.time = 0.0
        self._last = 0.0       # stamp of the last tick's state
        self._current = 0.0    # stamp of the state the tick under way read

    def restart(self) -> None:
        self.time = 0.0
        self._last = self._current = self.hardware.state_time()

    def period(self) -> float:
        """The stamp difference, in ``[0, max_period]`` (0: the same state read again)."""
        self._current = max(self._last, self.hardware.state_time())
        return min(self._current - self._last, self.max_period)

    def advance(self, dt: float) -> None:
        self.time += dt
        self._last = self._current
