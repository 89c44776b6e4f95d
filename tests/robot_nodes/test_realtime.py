"""Realtime mode: the composed process at wall-clock 1 kHz, and sim/bridge/estimator as three
separate processes."""
from __future__ import annotations

import signal
import time
from collections.abc import Iterator

import numpy as np
import pytest
from conftest import SHORT_STEP, Stack
from qg_common import conversions
from robot_client import DEEP, RobotClient, peg_start, wrench

pytestmark = pytest.mark.ros


def stamps_for(cli, topic: str, msg_type, seconds: float) -> list[int]:
    """[ns] Stamps of the messages of ``topic`` received within ``seconds`` of stamp time after
    the first one received."""
    stamps: list[int] = []
    cli.node.create_subscription(
        msg_type, topic, lambda m: stamps.append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec),
        DEEP)
    assert cli.spin_until(lambda: stamps and stamps[-1] - stamps[0] > (seconds + 0.2) * 1e9, 30.0), \
        f"{topic}: {len(stamps)} messages"
    return [s for s in stamps if s - stamps[0] < seconds * 1e9]


@pytest.mark.alone          # it counts states per wall second
def test_composed_realtime_is_paced_by_the_wall_clock_and_completes_steps(stack,
                                                                          machine_to_itself):
    from sensor_msgs.msg import JointState
    # The robot starts with the machine to this test: a realtime loop ticks at 1 kHz from its
    # start, and it spent 3-9 s of a core here waiting for the other alone tests' timed parts
    # (3.2 s of CPU for the whole test when it runs by itself).
    with machine_to_itself(), stack.client() as cli:
        stack.start(("robot", "robot_bridge_node", "robot",
                     ("--ros-args", "-p", "sim.clock_mode:=realtime", *SHORT_STEP)))
        robot = RobotClient(cli)
        assert robot.reset(2).success
        # The loop reports its own timing once a second (counts and a histogram of
        # periods), read at the end: two reports published after this subscription bracket
        # a second of the timed part. The states after the step are taken meanwhile.
        from diagnostic_msgs.msg import DiagnosticArray
        from robot_bridge_node.loop_diagnostics import snapshot_from_status
        reports: list = []
        cli.node.create_subscription(DiagnosticArray, "/diagnostics",
                                     lambda m: reports.append((time.monotonic(), m)), DEEP)
        states: list[tuple[float, int]] = []           # (arrival, stamp [ns])
        cli.node.create_subscription(
            JointState, "/joint_states",
            lambda m: states.append((time.monotonic(), conversions.time_ns(m.header.stamp))),
            DEEP)
        event = robot.step(1, (0.0, 0.0, -8.0, 0.3, 0.0, 0.0), timeout=10.0)
        assert event is not None, stack.logs()
        stepped = time.monotonic()
        # At least the rest detector's 20 ms; a sum of 1 ms periods, 20 of them came to
        # 0.019999999999999574 once.
        assert 0.02 - 1e-9 <= event.duration <= 0.6
        assert np.all(np.isfinite(wrench(event.wrench_estimate)))

        def after_step() -> list[tuple[float, int]]:
            return [s for s in states if s[0] >= stepped]

        def window_taken() -> bool:
            taken = after_step()
            return len(reports) >= 2 and len(taken) >= 2 and \
                taken[-1][0] - taken[0][0] >= 1.0 and taken[-1][1] - taken[0][1] > 1.2e9
        assert cli.spin_until(window_taken, 10.0), \
            f"{len(reports)} /diagnostics, {len(after_step())} /joint_states after the step"
        # Pacing, not speed: the loop never runs ahead of the wall clock, and it keeps
        # ticking. Whether it holds 1 kHz is machine-dependent: benchmarks/realtime_bench.py
        # measures it.
        taken = after_step()
        n = sum(stamp - taken[0][1] < 1e9 for _, stamp in taken)
        wall_rate = sum(arrival - taken[0][0] < 1.0 for arrival, _ in taken) / 1.0
        # The stamps are the loop's wall clock (realtime mode). A tick's stamp is taken
        # after its work, so stamps jitter by a tick or two and a window that opens on a
        # late one holds a little more than 1000 (1002 seen once); running ahead of the
        # wall clock would give thousands.
        assert n <= 1003, f"{n} /joint_states stamped within 1 s: faster than real time"
        # Arrivals say only that the loop keeps ticking. They come in bursts, so they
        # cannot bound the pace from above: a second of arrivals that opened on a late
        # state held its backlog too (1053 once, while its stamps gave <= 1003).
        assert wall_rate >= 200, f"{wall_rate:.0f} /joint_states per wall second"
        (t1, first), (t2, second) = reports[-2:]
        (status,) = second.status
        assert (status.name, status.hardware_id) == ("robot loop timing", "sim_panda")
        earlier, later = snapshot_from_status(first.status[0]), snapshot_from_status(status)
        window = later.since(earlier)
        due = window.ticks + window.missed        # every millisecond of the second in between
        assert abs(due - 1000 * (t2 - t1)) < 100, (due, t2 - t1)
        assert window.histogram.sum() == window.ticks and window.late <= window.ticks
    assert stack.launcher.poll() == []


@pytest.mark.parametrize("robot", ["sim_panda", "sim_xarm7"])
def test_separate_sim_bridge_and_estimator_processes_complete_a_step(stack, robot):
    """Every torque robot runs as three processes, each told only its ``robot`` name."""
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    args = ("--ros-args", "-p", f"robot:={robot}")
    stack.start(("sim", "sim_robot_node", "sim", args),
                ("bridge", "robot_bridge_node", "bridge", (*args, *SHORT_STEP)),
                ("wrench_estimator", "robot_bridge_node", "wrench_estimator", args))
    with stack.client() as cli:
        estimates: list[WrenchStamped] = []
        cli.node.create_subscription(WrenchStamped, "/wrench_estimate", estimates.append, DEEP)
        assert cli.spin_until(lambda: len(estimates) >= 100, 30.0), \
            f"{len(estimates)} /wrench_estimate\n{stack.logs()}"
        assert cli.spin_until(lambda: {"/sim", "/bridge", "/wrench_estimator"}
                              <= cli.node_names(), 30.0), cli.node_names()
        assert all(np.all(np.isfinite(wrench(e.wrench))) for e in estimates)
        robot = RobotClient(cli)
        reply = robot.reset(1, timeout=30.0)
        assert reply.success, reply.message
        t0 = time.monotonic()
        event = robot.step(1, (0.0, 0.0, -8.0, 0.0, 0.3, 0.0), timeout=20.0)
        assert event is not None, stack.logs()
        # The step's length in wall time is a speed figure, not a property: 0.21-0.35 s here
        # with the machine idle or one core busy, 2.0 s once with both cores busy (its
        # event.duration 0.03 s) and 2.55 s once in CI: three 1 kHz processes share 2 cores.
        # benchmarks/realtime_bench.py measures the loop's timing; here a hung step fails.
        print(f"separate processes: one step took {time.monotonic() - t0:.2f} s of wall time")
        assert time.monotonic() - t0 < 10.0, stack.logs()
        assert event.duration <= 0.25 + 0.02
        # Two restarts: the sim's start and the reset. A process's line reaches its log file
        # through the launcher's reading thread, a little after the process wrote it (once, in
        # a rehearsal of CI, the logs read right after the step held only the first).
        assert cli.spin_until(lambda: stack.logs().count("the sim restarted") == 2, 5.0), \
            stack.logs()
        assert np.all(np.isfinite(wrench(event.wrench_estimate)))
        # The shaft is still in the counterbore: the sim's hold and the bridge kept it there
        # (the xArm's wrist, damped as the Panda's, had swung it 9 mm off the axis).
        assert event.ground_truth.lateral_offset < 0.005, stack.logs()
        # The sim runs realtime whatever sim.clock_mode says, its rates included: the bridge
        # ticks once per state, so lockstep's 100 Hz would make every step ten times as long.
        # A reader on a busy host misses many of 1000 states a second (45 of 2 s seen in a CI
        # rehearsal, right after start), so the test reads the period from the stamps it gets,
        # once the stack is warm: a tick's states are 1 ms apart, lockstep's 10 ms. The sim
        # node's clock is the same for every robot: read once (1.4 s of three 1 kHz processes).
        if robot == "sim_panda":
            stamps = stamps_for(cli, "/joint_states", JointState, 1.0)
            gaps = np.diff(stamps)
            assert len(stamps) <= 1001 and gaps.size >= 10, f"{len(stamps)} states in 1 s"
            assert gaps[gaps > 0].min() < 2e6, \
                f"closest states {gaps[gaps > 0].min() / 1e6} ms apart"
    t0 = time.monotonic()
    codes = stack.stop(grace=5.0)
    assert codes == {"sim": 0, "bridge": 0, "wrench_estimator": 0}, stack.logs()
    assert time.monotonic() - t0 < 5.0      # SIGINT ends each within the grace


NEXTAGE = ("--ros-args", "-p", "robot:=sim_nextage")


@pytest.fixture(scope="module")
def nextage(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    """The Nextage's sim and bridge, started once for the two tests below: the first resets
    it right after start-up, the second then restarts its bridge."""
    stack = Stack(tmp_path_factory.mktemp("nextage"))
    try:
        stack.start(("sim", "sim_robot_node", "sim", NEXTAGE),
                    ("bridge", "robot_bridge_node", "bridge", (*NEXTAGE, *SHORT_STEP)))
        yield stack
    finally:
        stack.stop(grace=3.0)


def test_a_position_robot_runs_as_separate_sim_and_bridge_processes(nextage: Stack):
    """The Nextage (interface kind ``position``): the sim applies ``joint_commands.position``
    and publishes its wrist sensor on ``wrench_estimate``; no estimator process is needed."""
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header
    stack = nextage
    with stack.client() as cli:
        sensed: list[WrenchStamped] = []
        cli.node.create_subscription(WrenchStamped, "/wrench_estimate", sensed.append, DEEP)
        states: list[tuple[int, np.ndarray]] = []
        cli.node.create_subscription(
            JointState, "/joint_states",
            lambda m: states.append((conversions.time_ns(m.header.stamp), np.array(m.position))),
            DEEP)
        restarts: list[int] = []
        cli.node.create_subscription(Header, "/sim/restarted",
                                     lambda m: restarts.append(conversions.time_ns(m.stamp)), 10)
        robot = RobotClient(cli)
        # The first reset right after start-up: the bridge is still commanding the old pose.
        # (sim/restarted is latched: the start's restart may come first.)
        asked = time.time_ns()
        reply = robot.reset(peg_start(2), timeout=30.0)
        assert reply.success, reply.message + stack.logs()
        assert cli.spin_until(lambda: restarts and restarts[-1] > asked, 5.0), restarts
        # The reply is the bridge's report of settling from this reset, not from the start.
        assert conversions.time_ns(reply.observation.header.stamp) > restarts[-1]
        event = robot.step(1, (0.0,) * 6, timeout=20.0)
        assert event is not None, stack.logs()
        assert event.duration <= 0.25 + 0.02
        assert sensed and np.all(np.isfinite(wrench(sensed[-1].wrench)))
        # The arm stays in the configuration the reset put it in. The sim used to apply the
        # bridge's commands for the pose before the reset until the bridge took the restart:
        # one joint 69 deg back toward the old pose (3 of 3 runs), the reply's pose off by
        # 0.02-8.6 mm (7 runs). Now it holds until the bridge's commands follow the restart.
        # The states of the step may still be on their way when its at-rest event is in (one
        # CI run had 7 of them by then, on loaded cores): the sim goes on publishing at 1 kHz.
        def since_restart() -> list[np.ndarray]:
            return [q for stamp, q in states if stamp >= restarts[-1]]
        assert cli.spin_until(lambda: len(since_restart()) >= 10, 5.0), \
            f"{len(since_restart())} joint states after the restart"
        after = since_restart()
        moved = np.degrees(np.max(np.abs(np.array(after) - after[0])))
        print(f"position robot: largest joint motion after the reset {moved:.3f} deg")
        assert moved < 0.5, stack.logs()
        start, end = reply.observation.ee_pose.position, event.ee_pose.position
        drift = np.linalg.norm([end.x - start.x, end.y - start.y, end.z - start.z])
        print(f"position robot: drift over one held step {drift * 1e3:.3f} mm")
        assert drift < 1e-4, stack.logs()
    assert stack.launcher.poll() == [], stack.logs()


def test_a_bridge_started_after_a_reset_takes_control_of_the_separate_sim(nextage: Stack):
    """The sim applies only commands that follow its latest restart, so a bridge that comes up
    (or is discovered) after a reset must still learn of it: ``sim/restarted`` is latched.
    Volatile, a restarted bridge's commands were ignored and the sim warned after 1 s of them."""
    stack = nextage
    with stack.client() as cli:
        robot = RobotClient(cli)
        assert robot.reset(peg_start(3), timeout=30.0).success, stack.logs()

        def readers() -> set[bytes]:
            return {bytes(i.endpoint_gid) for i in
                    cli.node.get_subscriptions_info_by_topic("/wrench_setpoint")}
        old_readers = readers()
        bridge = next(r for r in stack.launcher.running if r.spec.name == "bridge").popen
        bridge.send_signal(signal.SIGINT)
        assert bridge.wait(timeout=10.0) == 0, stack.logs()
        stack.start(("bridge2", "robot_bridge_node", "bridge", (*NEXTAGE, *SHORT_STEP)))
        log = stack.log_dir / "bridge2.log"
        assert cli.spin_until(lambda: log.exists() and "the sim restarted" in log.read_text(),
                              30.0), stack.logs()
        # The setpoint goes once: to the new bridge's reader, not the old one's lingering entry.
        assert cli.spin_until(lambda: bool(readers() - old_readers), 30.0), stack.logs()
        cli.spin_for(0.2)
        event = robot.step(1, (0.0,) * 6, timeout=20.0)
        assert event is not None, stack.logs()
        cli.spin_for(1.5)                       # past the sim's 1 s before it warns
    assert "follow an earlier restart" not in stack.logs(), stack.logs()
    codes = stack.stop(grace=5.0)
    assert (codes.get("sim"), codes.get("bridge2")) == (0, 0), (codes, stack.logs())
