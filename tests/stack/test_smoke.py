"""Every executable starts as a real process, is discovered, answers, and stops cleanly.

The composed robot, the executor and the learner here; the robot's separate processes (``sim``,
``bridge``, ``wrench_estimator``) in ``tests/robot_nodes/test_realtime.py``, where each robot
runs as them alone: started beside the composed robot, they ran a second robot in the same
namespace, whose 1 kHz processes took two thirds of this file's CPU time."""
from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest
from conftest import Stack

pytestmark = pytest.mark.ros

EXECUTABLES = [
    ("robot", "robot_bridge_node", "robot", {"/sim", "/bridge", "/wrench_estimator", "/recorder"}),
    ("executor", "qg_learning_node", "executor", {"/executor"}),
    ("learner", "qg_learning_node", "learner", {"/learner"}),
]


@pytest.fixture(scope="module")
def every_executable(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    """Every executable, started once for the tests below that only ask it questions and then
    stop it (the last one, SIGINT to all; one before it, SIGTERM to the learner)."""
    stack = Stack(tmp_path_factory.mktemp("every_executable"))
    try:
        stack.start(*[(name, pkg, exe) for name, pkg, exe, _ in EXECUTABLES])
        yield stack
    finally:
        stack.stop(grace=3.0)


def test_every_executable_starts_and_is_discovered(every_executable):
    stack = every_executable
    expected = set().union(*(nodes for *_, nodes in EXECUTABLES))
    with stack.client() as cli:
        found = cli.spin_until(lambda: expected <= cli.node_names(), timeout=30.0)
        assert found, f"missing {expected - cli.node_names()}\n{stack.logs()}"


def test_start_episode_crosses_processes_and_rejects_bad_fields(every_executable):
    from qg_common.ros_client import RESEND_AFTER, call_service
    from qg_interfaces.srv import StartEpisode
    stack = every_executable
    with stack.client() as cli:
        bad = call_service(cli, StartEpisode, "/executor/start_episode",
                           StartEpisode.Request(mode="fly", initial_pose=8, reward="lots"), 30.0,
                           resend_after=RESEND_AFTER)  # refused: safe to send twice
        assert not bad.success
        for word in ("mode", "initial_pose", "reward"):
            assert word in bad.message
        assert bad.episode_id == ""
    assert stack.launcher.poll() == [], "the executor must survive bad requests"


def test_sigterm_also_exits_zero(every_executable):
    stack = every_executable
    with stack.client() as cli:
        assert cli.spin_until(lambda: "/learner" in cli.node_names(), timeout=30.0)
    proc = next(r for r in stack.launcher.running if r.spec.name == "learner").popen
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=5.0) == 0, stack.logs()


def test_every_executable_exits_zero_on_sigint(every_executable):
    stack = every_executable
    with stack.client() as cli:     # up (when this test runs alone)
        assert cli.spin_until(lambda: "/executor" in cli.node_names(), timeout=30.0)
    t0 = time.monotonic()
    codes = stack.stop(grace=5.0)
    elapsed = time.monotonic() - t0
    assert codes == {name: 0 for name, *_ in EXECUTABLES}, stack.logs()
    assert elapsed < 5.0


def qgl(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "qg_bringup.main", *args],
                          capture_output=True, text=True, timeout=timeout)


def test_qgl_up_with_missing_or_malformed_config_says_one_line_and_exits_2(tmp_path):
    missing = qgl("up", "--config", str(tmp_path / "nope.yaml"))
    assert missing.returncode == 2
    assert missing.stderr.strip().count("\n") == 0 and "not found" in missing.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("processes: [\n  - name: x\n")
    malformed = qgl("up", "--config", str(bad))
    assert malformed.returncode == 2
    assert malformed.stderr.strip().count("\n") == 0 and "malformed YAML" in malformed.stderr


def test_qgl_up_robots_needs_one_learner_and_at_least_one_robot(tmp_path):
    none = qgl("up", "--robots", "0")
    assert none.returncode == 2 and "--robots must be >= 1" in none.stderr
    cfg = tmp_path / "stack.yaml"
    cfg.write_text("processes:\n"
                   "  - {name: executor, package: qg_learning_node, executable: executor}\n")
    no_learner = qgl("up", "--config", str(cfg), "--robots", "2")
    assert no_learner.returncode == 2 and "exactly one learner" in no_learner.stderr
    bad_robot = qgl("episode", "start", "--robot", "robot-1")
    assert bad_robot.returncode == 2 and "not a ROS namespace" in bad_robot.stderr


def test_qgl_up_reports_a_dying_node_and_exits_nonzero(tmp_path):
    cfg = tmp_path / "stack.yaml"
    # A params file that does not exist makes the learner fail at start-up.
    cfg.write_text("processes:\n"
                   "  - {name: executor, package: qg_learning_node, executable: executor}\n"
                   "  - {name: learner, package: qg_learning_node, executable: learner,\n"
                   "     args: [--ros-args, --params-file, /nonexistent/learner.yaml]}\n")
    result = qgl("up", "--config", str(cfg), timeout=60.0)
    assert result.returncode != 0
    assert "process 'learner' exited" in result.stdout


def test_killing_qgl_up_stops_every_node_it_started(tmp_path):
    """SIGKILL leaves the launcher no chance to clean up: the kernel ends its children."""
    cfg = tmp_path / "stack.yaml"
    cfg.write_text("processes:\n"
                   "  - {name: executor, package: qg_learning_node, executable: executor}\n"
                   "  - {name: learner, package: qg_learning_node, executable: learner}\n")
    up = subprocess.Popen([sys.executable, "-m", "qg_bringup.main", "up", "--config",
                           str(cfg)], stdout=subprocess.PIPE, text=True)
    line = up.stdout.readline()
    while "[qgl] started" not in line:
        assert line, "qgl up ended before starting its nodes"
        line = up.stdout.readline()
    pids = [int(p) for p in re.findall(r"pid (\d+)", line)]
    assert len(pids) == 2
    up.kill()
    up.wait(timeout=10.0)
    deadline = time.monotonic() + 10.0
    alive = pids
    while alive and time.monotonic() < deadline:
        alive = [p for p in alive if _alive(p)]
        time.sleep(0.1)
    assert alive == [], f"nodes outlived qgl up: {alive}"


def _alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie awaiting its reaper counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
