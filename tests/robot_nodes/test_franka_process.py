"""The composed ``robot`` process driving franky-sim's FR3 through libfranka (``robot:=franka``),
as ``qgl up --config config/stack_franka.yaml`` runs it: a real robot's node is ``hardware``
(no ``sim``, no ground truth, no simulated clock), the arm moves to a start by ``move_to_start``,
steps end at rest in the robot's own base frame, and the commanded torques are on
``/joint_commands`` beside the measured ones on ``/joint_states``."""
from __future__ import annotations

import os

import numpy as np
import pytest
from conftest import Stack
from qg_common.rotations import matrix_from_quaternion
from robot_client import DEEP, RobotClient, shaft_start, wrench

pytestmark = pytest.mark.ros

#: A loopback address of this test's own (franky-sim binds libfranka's fixed port 1337).
ADDRESS = f"127.0.{35 + os.getpid() % 200}.{201 + os.getpid() % 50}"


#: [rad/s] the fastest joint of an arm held still (held after a step: 7e-4 measured)
STILL = 0.01


def _stamp(message) -> tuple[int, int]:
    return message.header.stamp.sec, message.header.stamp.nanosec


class _StillTicks:
    """(measured, commanded) torques of the ticks seen on both topics with the arm still,
    paired as the messages arrive (each topic's message may come first)."""

    def __init__(self) -> None:
        self.pairs: list[tuple[np.ndarray, np.ndarray]] = []
        self.clear()

    def clear(self) -> None:
        self.pairs.clear()
        self._still: dict[tuple[int, int], np.ndarray] = {}   # measured, awaiting its command
        self._commands: dict[tuple[int, int], np.ndarray] = {}

    def measured(self, message) -> None:
        if np.abs(message.velocity).max() >= STILL:
            return
        stamp, tau = _stamp(message), np.array(message.effort)
        if stamp in self._commands:
            self.pairs.append((tau, self._commands.pop(stamp)))
        else:
            self._still[stamp] = tau

    def commanded(self, message) -> None:
        stamp, tau = _stamp(message), np.array(message.effort)
        if stamp in self._still:
            self.pairs.append((self._still.pop(stamp), tau))
        else:
            self._commands[stamp] = tau


@pytest.mark.alone   # two 1 kHz loops on the wall clock: libfranka's own and franky-sim's
def test_the_robot_process_drives_franky_sim_through_libfranka(tmp_path, machine_to_itself):
    # On two cores beside other workers' processes (another franky-sim among them), libfranka's
    # thread missed its 50 ms torque signal timeout: a real arm's computer runs nothing else.
    stack = Stack(tmp_path)
    with machine_to_itself():
        _drive_franky_sim(stack)


def _drive_franky_sim(stack: Stack) -> None:
    try:
        stack.start(("franka_sim", "franka_sim_node", "franka_sim",
                     ("--address", ADDRESS, "--realtime-priority", "40")),
                    ("robot", "robot_bridge_node", "robot",
                     ("--ros-args", "-p", "robot:=franka", "-p", f"franka.address:={ADDRESS}")))
        with stack.client() as cli:
            # The 1 kHz topics' subscriptions first: discovery on a loaded machine can take
            # seconds, and the reset gives it the time.
            from geometry_msgs.msg import WrenchStamped
            from sensor_msgs.msg import JointState
            measured: list[JointState] = []
            commanded: list[JointState] = []
            libfranka: list[WrenchStamped] = []
            still = _StillTicks()
            cli.node.create_subscription(JointState, "/joint_states",
                                         lambda m: (measured.append(m), still.measured(m)), DEEP)
            cli.node.create_subscription(JointState, "/joint_commands",
                                         lambda m: (commanded.append(m), still.commanded(m)),
                                         DEEP)
            cli.node.create_subscription(WrenchStamped, "/franka/external_wrench",
                                         libfranka.append, DEEP)
            robot = RobotClient(cli)
            start = shaft_start(2)
            reply = robot.reset(start, timeout=90.0)
            assert reply.success, reply.message + stack.logs()
            obs = reply.observation
            # The FR3's URDF root (``base``, fixed to ``fr3_link0``), not the Panda's link0.
            assert obs.header.frame_id == "base"
            assert obs.fault == ""
            position = np.array([obs.ee_pose.position.x, obs.ee_pose.position.y,
                                 obs.ee_pose.position.z])
            assert np.linalg.norm(position - start.position) < 1e-3, (position, start.position)
            q = obs.ee_pose.orientation
            rotation = matrix_from_quaternion(q.x, q.y, q.z, q.w)
            angle = np.arccos(np.clip((np.trace(start.rotation.T @ rotation) - 1) / 2, -1, 1))
            assert angle < np.radians(0.5)
            # A real robot has no truth: the event's ground truth is zeros.
            assert obs.ground_truth.insertion_depth == 0.0 and obs.ground_truth.tilt == 0.0

            # A step in free air, its setpoint sent once (it holds until the step ends): a pull
            # (a positive Fz, against the task's push) draws the tool back along its axis, away
            # from whatever the scene has below it.
            event = robot.step(1, (0.0, 0.0, 8.0, 0.0, 0.0, 0.0))
            assert event is not None, stack.logs()
            assert event.fault == "" and event.header.frame_id == "base"
            moved = np.array([event.ee_pose.position.x, event.ee_pose.position.y,
                              event.ee_pose.position.z]) - position
            back = -float(np.dot(moved, start.rotation[:, 2]))
            assert back > 2e-3 and np.linalg.norm(moved + back * start.rotation[:, 2]) \
                < 0.5 * back, (moved, event.duration)

            # The 1 kHz topics, the arm held still (the watchdog holds it 0.1 s after the step):
            # the loop's torque (gravity included; the plugin takes it out for libfranka, which
            # adds it back) and franky-sim's measured one, two fields that agree at rest. They
            # are compared tick by tick (both carry the tick's stamp) on ticks where the arm is
            # still: a loaded machine hands a subscriber a backlog, and two topics' backlogs
            # need not cover the same ticks (medians of each differed by 2.1 Nm in a suite run).
            cli.spin_for(0.5)
            for received in (measured, commanded, libfranka):
                received.clear()
            still.clear()
            # The pairing is kept as messages arrive: a predicate that paired every message
            # again on each spin fell behind a loaded machine's 1 kHz stream (1,470 messages,
            # a few seconds of the arm's time, read in 30 s).
            assert cli.spin_until(lambda: len(libfranka) >= 20 and len(still.pairs) >= 20,
                                  30.0), \
                (len(commanded), len(measured), len(libfranka), len(still.pairs),
                 max((float(np.abs(m.velocity).max()) for m in measured), default=None),
                 stack.logs())
            # libfranka's own estimate beside the EKF's, as libfranka gives it (base frame);
            # franky-sim's is zeros.
            assert libfranka[-1].header.frame_id == "base"
            assert wrench(libfranka[-1].wrench).tolist() == [0.0] * 6
            names = [f"fr3_joint{i}" for i in range(1, 8)]
            assert list(measured[-1].name) == names and list(commanded[-1].name) == names
            pairs = list(still.pairs)
            tau = np.median([t for t, _ in pairs], axis=0)
            tau_cmd = np.median([c for _, c in pairs], axis=0)
            assert np.all(np.isfinite(tau_cmd)) and np.abs(tau_cmd).max() > 5.0   # gravity
            assert np.abs(tau - tau_cmd).max() < 0.05, (tau, tau_cmd)

            # The graph of nodes arrives by discovery, which can trail the topics' data.
            expected = {"hardware", "bridge", "wrench_estimator", "recorder"}
            assert cli.spin_until(lambda: expected <= set(cli.node.get_node_names()), 10.0), \
                cli.node.get_node_names()
            nodes = set(cli.node.get_node_names())
            assert "sim" not in nodes
            topics = dict(cli.node.get_topic_names_and_types())
            assert "/sim/ground_truth" not in topics and "/clock" not in topics
    finally:
        stack.stop(grace=5.0)


def test_an_unreachable_franka_stops_the_robot_process_in_time_with_its_reason(tmp_path):
    """Nothing serves libfranka at the address: the robot process ends within 10 s (refused
    connections are retried for ``franka.connect_timeout``, 5 s) with exit code 1 and one line
    naming the address and why, and leaves no loop process behind."""
    import time
    unserved = f"127.0.{35 + os.getpid() % 200}.254"
    stack = Stack(tmp_path)
    try:
        began = time.monotonic()
        stack.start(("robot", "robot_bridge_node", "robot",
                     ("--ros-args", "-p", "robot:=franka", "-p", f"franka.address:={unserved}")))
        name, code = stack.launcher.wait_any(period=0.05)
        took = time.monotonic() - began
        assert (name, code) == ("robot", 1) and took < 10.0, (took, stack.logs())
        log = stack.logs()
        assert f"error: the robot loop could not be built: the Franka at {unserved}" in log
        assert "connection refused" in log and "Traceback" not in log
        # The forked loop process carries the same command line: none is left.
        import subprocess
        left = subprocess.run(["pgrep", "-f", f"franka.address:={unserved}"],
                              capture_output=True, text=True).stdout.split()
        assert left == [], left
    finally:
        stack.stop(grace=1.0)
