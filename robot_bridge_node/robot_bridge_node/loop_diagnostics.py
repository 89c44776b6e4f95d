"""The realtime loop's timing on ``diagnostics`` (``diagnostic_msgs/DiagnosticArray``, 1 Hz).

What ``ros2 topic echo /diagnostics`` (or rqt's robot monitor) shows of the 1 kHz loop: the last
second's tick period p50/p99/max and share of ticks on time, and the counts since start,
histogram included, so a client can take the percentiles of any window by subtracting two
messages (``snapshot_from_status``; ``benchmarks/realtime_bench.py`` does). The level is
WARN when more than 0.5 % of the last second's ticks were late.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from qg_common import topics
from rclpy.node import Node

from robot_bridge_node.core.tick_timing import TimingSnapshot

__all__ = ["STATUS_NAME", "LoopDiagnostics", "timing_status", "snapshot_from_status"]

#: ``DiagnosticStatus.name`` of the loop's timing (prefixed with the node's namespace).
STATUS_NAME = "robot loop timing"
#: Late ticks above this share of a window make the status WARN.
WARN_LATE_FRACTION = 0.005
_COUNTS = ("period_ns", "late_after_ns", "ticks", "missed", "late", "max_ns")


def timing_status(total: TimingSnapshot, window: TimingSnapshot, name: str,
                  hardware_id: str) -> DiagnosticStatus:
    """The status of the loop: ``window``'s figures in the message, ``total``'s counts and
    histogram (nonzero bins as ``index:count``) as values."""
    late = 1.0 - window.on_time_fraction if window.ticks + window.missed else 0.0
    figures = window.summary()
    status = DiagnosticStatus(
        level=DiagnosticStatus.WARN if late > WARN_LATE_FRACTION else DiagnosticStatus.OK,
        name=name, hardware_id=hardware_id,
        message=(f"last {window.ticks + window.missed} ticks: period p99 "
                 f"{figures['period_p99_ms']:.2f} ms, {figures['on_time_percent']:.2f} % on time"))
    bins = np.flatnonzero(total.histogram)
    status.values = [
        *(KeyValue(key=f"window_{key}", value=f"{value:.4g}") for key, value in figures.items()),
        *(KeyValue(key=key, value=str(int(getattr(total, key)))) for key in _COUNTS),
        KeyValue(key="histogram_10us", value=" ".join(f"{i}:{total.histogram[i]}" for i in bins))]
    return status


def snapshot_from_status(status: DiagnosticStatus) -> TimingSnapshot:
    """The counts since start that ``timing_status`` put in ``status``.

    :raises ValueError: if ``status`` is not a loop timing status.
    """
    values = {kv.key: kv.value for kv in status.values}
    try:
        pairs = [item.split(":") for item in values["histogram_10us"].split()]
        return TimingSnapshot.from_bins(*(int(values[key]) for key in _COUNTS),
                                        bins=[int(index) for index, _ in pairs],
                                        counts=[int(count) for _, count in pairs])
    except (KeyError, ValueError) as exc:
        raise ValueError(f"{status.name!r} is not a loop timing status: {exc}") from exc


class LoopDiagnostics:
    """Publishes the loop's timing once a second while ``source`` has one.

    :param node: publishes ``diagnostics`` (relative: a namespaced robot's is its own).
    :param source: the counts since start, or ``None`` while there are none (a lockstep loop
        has no wall-clock period).
    :param hardware_id: the robot (its plugin's name).
    """

    def __init__(self, node: Node, source: Callable[[], TimingSnapshot | None],
                 hardware_id: str) -> None:
        self.node = node
        self.source = source
        self.hardware_id = hardware_id
        self.name = f"{node.get_namespace().rstrip('/')}/{STATUS_NAME}".lstrip("/")
        self._previous: TimingSnapshot | None = None
        self.publisher = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        node.create_timer(1.0, self._publish)

    def _publish(self) -> None:
        total = self.source()
        if total is None:
            return
        window = total if self._previous is None else total.since(self._previous)
        self._previous = total
        msg = DiagnosticArray(status=[timing_status(total, window, self.name,
                                                    self.hardware_id)])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.publisher.publish(msg)
