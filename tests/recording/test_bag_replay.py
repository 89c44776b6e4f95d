"""`qgl replay` republishes a bag with its original timing, scaled by --rate (process level)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from qg_recording.bag_writer import BagWriter
from qg_recording.cdr import encode_twist_stamped, encode_wrench_stamped

N = 101  # one every 10 ms: a 1.0 s bag


def write_bag(directory: Path) -> None:
    with BagWriter(directory) as writer:
        writer.add_topic("/wrench_estimate", "geometry_msgs/msg/WrenchStamped", "reliable", 1000)
        writer.add_topic("/ee_twist", "geometry_msgs/msg/TwistStamped", "reliable", 1000)
        for i in range(N):
            t = 5_000_000_000 + i * 10_000_000
            writer.write("/wrench_estimate", encode_wrench_stamped(t, "tool", [float(i), 0, 0], [0, 0, 0]), t)
            writer.write("/ee_twist", encode_twist_stamped(t, "base", [0, 0, 0], [0, 0, 0]), t)


@pytest.mark.ros
@pytest.mark.alone
def test_replay_at_rate_two_takes_half_the_time(stack, tmp_path: Path, machine_to_itself) -> None:
    from geometry_msgs.msg import TwistStamped, WrenchStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    write_bag(tmp_path / "bag")
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    arrivals: list[tuple[float, float]] = []
    twists: list[TwistStamped] = []
    # The player starts beside the other workers and waits for its subscribers, which come
    # only with the machine to this test: the timed part is the replay, not a process start.
    player = subprocess.Popen(
        [sys.executable, "-m", "qg_bringup.main", "replay", str(tmp_path / "bag"),
         "--rate", "2", "--topics", "/wrench_estimate", "--wait-for-subscribers", "120",
         "--start-delay", "0.5"],
        env=stack.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with stack.client("replay_listener") as cli:
            with machine_to_itself():
                cli.node.create_subscription(
                    WrenchStamped, "/wrench_estimate",
                    lambda m: arrivals.append((time.monotonic(), m.wrench.force.x)), qos)
                cli.node.create_subscription(TwistStamped, "/ee_twist", twists.append, qos)
                cli.spin_until(lambda: len(arrivals) >= N, timeout=45.0)
                cli.spin_for(0.3)  # a filtered-out topic would have arrived by now
            out, err = player.communicate(timeout=30)
    finally:
        player.kill()
    assert player.returncode == 0, err
    assert [x for _, x in arrivals] == [float(i) for i in range(N)]  # all, in order
    assert twists == []  # --topics left /ee_twist out
    span = arrivals[-1][0] - arrivals[0][0]
    assert 0.4 <= span <= 0.8, span  # 1.0 s of recording at rate 2 (subscriber side, loaded host)
    published = float(out.split(" messages in ")[1].split()[0])
    assert f"published {N} messages" in out and 0.49 <= published <= 0.6, out
