"""The composed ``robot`` process in lockstep: resets, RL steps, bad input, clean exit."""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator

import numpy as np
import pytest
from conftest import Stack
from robot_client import DEEP, RobotClient, shaft_start, wrench

pytestmark = pytest.mark.ros

ROBOT = ("robot", "robot_bridge_node", "robot")


def test_reset_and_setpoints_complete_with_their_seq_and_a_rerun_repeats_them_exactly(stack):
    stack.start(ROBOT)
    rng = np.random.default_rng(3)
    plan = [(-10.0, *rng.uniform(-1.0, 1.0, 2)) for _ in range(5)]   # default steps: <= 3 s each
    with stack.client() as cli:
        from rosgraph_msgs.msg import Clock
        clock: list[int] = []
        cli.node.create_subscription(
            Clock, "/clock", lambda m: clock.append(m.clock.sec * 10**9 + m.clock.nanosec), DEEP)
        robot = RobotClient(cli)
        reply = robot.reset(3)
        assert reply.success, reply.message + stack.logs()
        obs = reply.observation
        assert obs.seq == 0
        assert obs.duration == pytest.approx(0.1, abs=1e-9)          # the settle time
        assert obs.ground_truth.tilt == pytest.approx(math.radians(15.0), abs=0.02)
        assert np.all(np.isfinite(wrench(obs.wrench_estimate)))
        assert obs.ee_pose.position.z == pytest.approx(0.25 + 0.06, abs=0.02)

        first = []
        for seq, (fz, tx, ty) in enumerate(plan, start=1):
            event = robot.step(seq, (0.0, 0.0, fz, tx, ty, 0.0))
            assert event is not None, f"no AtRest for seq {seq}\n{stack.logs()}"
            assert 0.02 - 1e-9 <= event.duration <= 3.0 + 1e-9    # rest.max_time
            assert np.all(np.isfinite(wrench(event.wrench_estimate)))
            first.append(event)
        # Simulated time on /clock: monotonic, and at least as long as the steps took.
        cli.spin_for(0.2)
        assert clock and np.all(np.diff(clock) > 0)
        assert (clock[-1] - clock[0]) * 1e-9 >= sum(e.duration for e in first[1:]) - 0.011
        # Pressing down: the bearing face pushes back up the shaft (contact Fz < 0, tool frame).
        assert wrench(first[-1].ground_truth.contact_wrench)[2] < -1.0
        assert wrench(first[-1].wrench_estimate)[2] < -1.0

    # Lockstep is deterministic: a new process given the same reset and setpoints repeats them.
    assert stack.stop() == {"robot": 0}
    stack.start(("robot_again", *ROBOT[1:]))
    with stack.client() as cli:
        robot = RobotClient(cli)
        assert robot.reset(3).success
        for seq, (fz, tx, ty) in enumerate(plan[:3], start=1):
            again = robot.step(seq, (0.0, 0.0, fz, tx, ty, 0.0))
            assert again is not None
            assert again.duration == first[seq - 1].duration
            np.testing.assert_array_equal(wrench(again.wrench_estimate),
                                          wrench(first[seq - 1].wrench_estimate))
            assert again.ee_pose == first[seq - 1].ee_pose


@pytest.fixture(scope="module")
def robot_process(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    """One robot process for the three tests below, which each begin with a reset of their own
    and leave nothing behind that the next one reads (their sequence numbers, sessions and
    request ids differ); the last one stops it. One start instead of three."""
    stack = Stack(tmp_path_factory.mktemp("robot_process"))
    try:
        stack.start(ROBOT)
        yield stack
    finally:
        stack.stop(grace=3.0)


def test_only_the_served_session_steers_the_arm(robot_process: Stack) -> None:
    """Setpoints of another session are dropped, counted and logged; a reset opens a session."""
    stack = robot_process
    with stack.client() as cli:
        robot = RobotClient(cli)
        assert robot.reset(2, session="episode_a").success
        for seq in (1, 2, 3):            # an intruder with fresh sequence numbers and a hard push
            robot.send(seq, (0.0, 0.0, -20.0, 3.0, 3.0, 0.0), session="intruder")
        cli.spin_for(1.0)
        assert [robot.event(seq) for seq in (1, 2, 3)] == [None, None, None]
        event = robot.step(4, (0.0, 0.0, -10.0, 0.0, 0.0, 0.0), session="episode_a")
        assert event is not None, stack.logs()
        assert event.foreign_setpoints == 3
        assert "setpoint 1 of session 'intruder' ignored: serving 'episode_a'" in stack.logs()
        # A reset without a session serves any sender, and starts counting from zero.
        assert robot.reset(2).success
        event = robot.step(5, (0.0, 0.0, -10.0, 0.0, 0.0, 0.0), session="anyone")
        assert event is not None and event.foreign_setpoints == 0


def test_a_reset_asked_again_with_its_request_id_is_answered_not_redone(
        robot_process: Stack) -> None:
    """A client whose reply got lost asks again with the same id: it gets the first reply, and
    the arm, which has moved on, is not reset again (no settling: the lockstep clock stands)."""
    from qg_common.conversions import start_pose_request
    from qg_common.ros_client import call_service
    from qg_interfaces.srv import MoveToStart
    from rosgraph_msgs.msg import Clock
    stack = robot_process
    with stack.client() as cli:
        clock: list[int] = []
        cli.node.create_subscription(
            Clock, "/clock", lambda m: clock.append(m.clock.sec * 10**9 + m.clock.nanosec), DEEP)
        robot = RobotClient(cli)
        request = start_pose_request(shaft_start(2), request_id="reset-once")
        first = call_service(cli, MoveToStart, "/move_to_start", request, 60.0)
        assert first.success, first.message + stack.logs()
        moved = robot.step(1, (0.0, 0.0, -10.0, 1.0, 0.0, 0.0))
        assert moved is not None, stack.logs()
        cli.spin_for(0.3)
        before = clock[-1]
        again = call_service(cli, MoveToStart, "/move_to_start", request, 60.0)
        cli.spin_for(0.3)
        assert (again.success, again.message, again.observation) == \
            (first.success, first.message, first.observation)
        assert clock[-1] == before                      # nothing stepped: no second reset
        assert "move_to_start reset-once asked again: its reply again" in stack.logs()
        fresh = call_service(cli, MoveToStart, "/move_to_start",
                             start_pose_request(shaft_start(2), request_id="reset-twice"), 60.0)
        cli.spin_for(0.3)
        assert fresh.success and clock[-1] >= before + 0.1e9 - 1   # a new id: settled again


def test_bad_reset_and_nan_setpoint_are_rejected_and_the_process_stays_up(
        robot_process: Stack) -> None:
    """The shared process's last test: after the others, it stops it."""
    stack = robot_process
    with stack.client() as cli:
        robot = RobotClient(cli)
        nowhere = shaft_start(2)
        bad = robot.reset(dataclasses.replace(nowhere, position=np.array([0.4, math.nan, 0.3])))
        assert not bad.success and "finite" in bad.message, bad.message
        far = robot.reset(dataclasses.replace(nowhere, position=np.array([3.0, 0.0, 0.3])))
        assert not far.success and "moving to start 2 failed" in far.message, far.message
        assert "inverse kinematics did not converge" in far.message

        assert robot.step(1, (0.0, 0.0, math.nan, 0.0, 0.0, 0.0), timeout=1.0) is None
        logs = stack.logs()
        assert "setpoint 1 rejected" in logs and "NaN" in logs, logs

        event = robot.step(2, (0.0, 0.0, -5.0, 0.2, 0.0, 0.0))
        assert event is not None, stack.logs()
        assert np.all(np.isfinite(wrench(event.wrench_estimate)))
    assert stack.launcher.poll() == []
    t0 = time.monotonic()
    codes = stack.stop(grace=5.0)
    assert codes == {"robot": 0}, stack.logs()
    assert time.monotonic() - t0 < 5.0
