"""The recorder's ``recording.*`` parameters in a real robot process: RL-rate bags without a
1 kHz topic, an episode refused at a nearly full disk with the reason in the reset's reply and
no bag, and a bad value that stops the start.

Episodes are driven by hand (a status, a reset, a step, the final status): only the robot
process runs.
"""
from __future__ import annotations

import time
from pathlib import Path

import pytest
from conftest import SHORT_STEP
from robot_client import RobotClient

pytestmark = pytest.mark.ros


def status(episode_id: str, state: str):
    from qg_common.conversions import time_msg
    from qg_interfaces.msg import EpisodeStatus
    return EpisodeStatus(stamp=time_msg(time.time_ns()), episode_id=episode_id, state=state,
                         mode="train", reward_type="sparse", initial_pose=1, step=0, max_steps=1)


def test_rl_rate_bags_hold_no_1khz_topic_in_a_robot_process(stack) -> None:
    from qg_common.topics import LATCHED
    from qg_interfaces.msg import EpisodeStatus
    from qg_recording.bag_reader import bag_info
    from qg_recording.disk_keeper import RL_RATE_TOPICS, disk_bytes

    episodes = Path(stack.env["QG_RUNS_DIR"]) / "episodes"
    stack.start(("robot", "robot_bridge_node", "robot",
                 ("--ros-args", "-p", "recording.mode:=rl_rate", *SHORT_STEP)))
    with stack.client() as cli:
        statuses = cli.node.create_publisher(EpisodeStatus, "/episode_status", LATCHED)
        robot = RobotClient(cli)
        assert robot.reset(1).success, stack.logs()  # the robot is up
        statuses.publish(status("rl_0001", "resetting"))
        reply = robot.reset(1, session="rl_0001")
        assert reply.success, reply.message
        assert robot.step(1, (0.0, 0.0, -8.0, 0.2, 0.0, 0.0), timeout=20.0,
                          session="rl_0001") is not None
        statuses.publish(status("rl_0001", "done"))
        bag = episodes / "rl_0001"
        assert cli.spin_until(lambda: bag.exists() and bag_info(bag).complete, 30.0), stack.logs()
        # the bag's bytes, logged once it is closed
        assert cli.spin_until(lambda: "recorded rl_0001" in stack.logs(), 10.0), stack.logs()
    info = bag_info(bag)
    recorded = {t.name for t in info.topics if t.message_count}
    assert {"/episode_status", "/ee_at_rest", "/wrench_setpoint"} <= recorded <= RL_RATE_TOPICS
    assert "/joint_states" not in {t.name for t in info.topics}
    logged = next(line for line in stack.logs().splitlines() if "recorded rl_0001" in line)
    assert f": {disk_bytes(bag)} bytes (" in logged, logged      # the bag's bytes on disk
    assert disk_bytes(bag) < 200 * 1024
    assert "without its 1 kHz topics" in logged, logged


def test_a_nearly_full_disk_refuses_the_episode_before_its_bag(stack) -> None:
    from qg_common.topics import LATCHED
    from qg_interfaces.msg import EpisodeStatus

    episodes = Path(stack.env["QG_RUNS_DIR"]) / "episodes"
    # no disk has a billion MiB free: the real free space (statvfs) is too little
    stack.start(("robot", "robot_bridge_node", "robot",
                 ("--ros-args", "-p", "recording.min_free_mb:=1000000000.0", *SHORT_STEP)))
    with stack.client() as cli:
        statuses = cli.node.create_publisher(EpisodeStatus, "/episode_status", LATCHED)
        robot = RobotClient(cli)
        assert robot.reset(1).success, stack.logs()
        statuses.publish(status("full_0001", "resetting"))
        reply = robot.reset(1, session="full_0001")
    assert not reply.success
    assert "recording refused for full_0001" in reply.message, reply.message
    assert "min_free_mb = 1e+09 MiB" in reply.message, reply.message
    assert not (episodes / "full_0001").exists()
    assert not episodes.exists() or not any(episodes.iterdir())


def test_a_bad_recording_mode_stops_the_start(stack) -> None:
    stack.start(("robot", "robot_bridge_node", "robot",
                 ("--ros-args", "-p", "recording.mode:=sometimes")))
    deadline = time.monotonic() + 60.0
    exited = []
    while not exited and time.monotonic() < deadline:
        exited = stack.launcher.poll()
        time.sleep(0.1)
    assert exited and exited[0][0] == "robot" and exited[0][1] != 0, stack.logs()
    assert "recording.mode must be one of ['all', 'rl_rate', 'every_k']" in stack.logs()
