"""The realtime ticks leave the robot process spread as they were measured:
a block of ticks handed over at once goes out one tick at a time, each at its stamp plus the
delay, never before; a tick already due goes out at once; nothing is dropped or reordered."""
from __future__ import annotations

import time

import pytest
from robot_bridge_node.core.paced_publisher import PacedPublisher

MS = 1_000_000


@pytest.mark.alone   # the publisher's thread keeps the wall clock: a preempted one bursts
def test_a_block_handed_over_at_once_goes_out_spread_as_stamped_and_in_order(
        machine_to_itself) -> None:
    with machine_to_itself():
        _a_block_goes_out_spread()


def _a_block_goes_out_spread() -> None:
    sent: list[tuple[float, str, bytes]] = []
    paced = PacedPublisher(lambda topic, data: sent.append((time.time_ns(), topic, data)),
                           delay=0.005)
    now = time.time_ns()
    ticks = [(now + k * MS, [("/joint_states", bytes([k])), ("/ee_pose", bytes([k]))])
             for k in range(30)]
    paced.put(ticks[:20])                       # a block, then the next one a little later
    time.sleep(0.002)
    paced.put(ticks[20:])
    deadline = time.monotonic() + 2.0
    while paced.published < 30 and time.monotonic() < deadline:
        time.sleep(0.005)
    paced.stop(timeout=2.0)
    assert [data for _, topic, data in sent if topic == "/joint_states"] == \
        [bytes([k]) for k in range(30)]
    by_tick = {data: t for t, topic, data in sent if topic == "/joint_states"}
    for t_ns, _ in ticks:
        k = (t_ns - now) // MS
        assert by_tick[bytes([k])] >= t_ns + 5 * MS, k        # never before its time
    first, last = by_tick[bytes([0])], by_tick[bytes([29])]
    assert last - first >= 25 * MS                  # spread over the ticks' 29 ms, no burst
    assert paced.published == 30


def test_ticks_already_due_go_out_at_once_and_those_too_late_are_dropped() -> None:
    """Ticks 0.1 s overdue go out at once (counted late); those more than ``max_lag`` overdue
    (a process far behind) are dropped and counted, so the live topics never trail far."""
    sent: list[bytes] = []
    paced = PacedPublisher(lambda topic, data: sent.append(data), delay=0.005, max_lag=0.5)
    now = time.time_ns()
    stale = [(now - 1000 * MS + k * MS, [("/joint_states", b"stale")]) for k in range(20)]
    due = [(now - 100 * MS + k * MS, [("/joint_states", bytes([k]))]) for k in range(50)]
    start = time.perf_counter()
    paced.put(stale + due)
    deadline = time.monotonic() + 2.0
    while paced.published + paced.dropped < 70 and time.monotonic() < deadline:
        time.sleep(0.005)
    paced.stop(timeout=2.0)
    assert sent == [bytes([k]) for k in range(50)]
    assert (paced.dropped, paced.late) == (20, 50)
    assert time.perf_counter() - start < 1.0
