"""The robot's loop in its own process: every tick reaches the robot process in order and the
events after their ticks, the numbers are those of the same loop run in process, and neither
process outlives the other silently."""
from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest
from arms import start
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.hardware_interface import robot_plugin
from robot_bridge_node.core.interface_kinds import interface_kind
from robot_bridge_node.core.loop_link import LoopLink
from robot_bridge_node.core.loop_runner import SetpointCommand, StepEvent
from robot_bridge_node.core.sample_ring import HAS_TRUTH, PUBLISH
from robot_bridge_node.robot_process import shipped_loop_spec

ROBOT = "sim_panda"
SETPOINT = WrenchSetpoint.residual(-15.0, 1.5, -0.5)


class Listener:
    """Keeps what the link hands over, and in which order."""

    def __init__(self) -> None:
        self.records: list[np.ndarray] = []
        self.events: list[StepEvent] = []
        self.last_t_at_event: list[int] = []
        self.failures: list[str] = []
        self.arrived = threading.Event()

    def samples(self, records: np.ndarray) -> None:
        self.records.append(records)

    def at_rest(self, event: StepEvent) -> None:
        self.last_t_at_event.append(int(self.records[-1]["t_ns"][-1]))
        self.events.append(event)
        self.arrived.set()

    def timing(self, snapshot) -> None:
        pass

    def log(self, level: str, message: str) -> None:
        pass

    def failed(self, message: str) -> None:
        self.failures.append(message)
        self.arrived.set()

    def wait_for_event(self, seq: int, timeout: float = 30.0) -> StepEvent:
        deadline = time.monotonic() + timeout
        while not any(e.seq == seq for e in self.events):
            assert time.monotonic() < deadline, f"no at-rest event {seq}"
            self.arrived.wait(0.05)
            self.arrived.clear()
        return next(e for e in self.events if e.seq == seq)


@pytest.mark.slow
def test_every_tick_arrives_in_order_and_the_loop_computes_what_it_does_in_process() -> None:
    listener = Listener()
    link = LoopLink(shipped_loop_spec(ROBOT), 7, listener)
    link.start()
    try:
        settled = link.reset(start(3))
        link.send_setpoint(SetpointCommand(1, SETPOINT))
        step = listener.wait_for_event(1)
        time.sleep(0.1)
    finally:
        link.stop()
    records = np.concatenate(listener.records)
    ticks = records["tick"]
    assert np.array_equal(ticks, np.arange(len(ticks))) and link.ring.lost == 0
    # the state the loop began with and the settled start (one sample each), then one sample
    # per tick of the step, 1 ms apart
    step_ticks = round(step.result.duration / 1e-3)
    assert len(records) == 2 + step_ticks
    assert np.all(np.diff(records["t_ns"][1:]) == 1_000_000)
    assert [e.seq for e in listener.events] == [0, 1]
    assert listener.last_t_at_event == [settled.t_ns, step.t_ns]   # events after their ticks
    assert records["t_ns"][-1] == step.t_ns and not listener.failures
    # every 10th tick published (publish_every), each with the ground truth (truth_every 10)
    published = (records["flags"] & PUBLISH) != 0
    assert published.sum() == 2 + step_ticks // 10
    assert np.array_equal(published, (records["flags"] & HAS_TRUTH) != 0)

    # The same loop in this process, from the same history: the same numbers, bit for bit.
    s = shipped_loop_spec(ROBOT)
    plugin = robot_plugin(s.robot)
    loop = interface_kind(plugin.interface).build_loop(
        plugin.create(s.robot_params), s.bridge_params, s.estimator_params)
    loop.begin()
    loop.reset(start(3))
    result = loop.execute(SETPOINT)
    assert result.duration == step.result.duration
    assert np.array_equal(result.wrench_estimate, step.result.wrench_estimate)
    assert np.array_equal(loop.controller.tool.position, step.position)
    assert np.array_equal(loop.hardware.read().q, records["q"][-1])


def test_a_loop_that_cannot_be_built_says_why_and_leaves_no_process() -> None:
    misnamed = dataclasses.replace(shipped_loop_spec(ROBOT), robot="sim_pandaa")
    link = LoopLink(misnamed, 7, Listener())
    with pytest.raises(RuntimeError, match="no robot plugin named 'sim_pandaa'"):
        link.start()
    assert link.process.poll() is not None


def test_a_killed_loop_process_is_reported_and_stop_raises() -> None:
    listener = Listener()
    link = LoopLink(shipped_loop_spec(ROBOT), 7, listener)
    link.start()
    link.process.send_signal(signal.SIGKILL)
    deadline = time.monotonic() + 10.0
    while not listener.failures:
        assert time.monotonic() < deadline, "the link did not notice"
        time.sleep(0.02)
    assert "exited (-9)" in listener.failures[0]
    with pytest.raises(RuntimeError, match="exited"):
        link.stop()


@pytest.mark.parametrize("forked", [False, True])
@pytest.mark.slow
def test_the_loop_process_ends_with_the_process_that_started_it(forked: bool) -> None:
    parent = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys, time
        from robot_bridge_node.core.loop_link import ForkedLoopProcess, LoopLink
        forked = ForkedLoopProcess() if {forked} else None
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from test_loop_process import ROBOT, Listener
        from robot_bridge_node.robot_process import shipped_loop_spec
        link = LoopLink(shipped_loop_spec(ROBOT), 7, Listener(), forked=forked)
        link.start()
        print(link.process.pid, flush=True)
        time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    parent.send_signal(signal.SIGKILL)           # no cleanup runs in the parent
    parent.wait()
    deadline = time.monotonic() + 10.0
    while os.path.exists(f"/proc/{child}") and "Z" not in _state(child):
        assert time.monotonic() < deadline, "the loop process outlived its parent"
        time.sleep(0.05)


def test_a_forked_loop_process_steps_and_ends_cleanly_and_an_unused_one_ends_with_its_socket(
        ) -> None:
    """The robot process forks its loop process before ROS starts (no threads to fork with):
    in a process of its own here, as a pytest worker has threads."""
    result = subprocess.run([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        from robot_bridge_node.core.loop_link import ForkedLoopProcess, LoopLink
        unused, used = ForkedLoopProcess(), ForkedLoopProcess()
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from test_loop_process import ROBOT, SETPOINT, Listener, start
        from robot_bridge_node.core.loop_runner import SetpointCommand
        from robot_bridge_node.robot_process import shipped_loop_spec
        listener = Listener()
        link = LoopLink(shipped_loop_spec(ROBOT), 7, listener, forked=used)
        link.start()
        link.reset(start(2))
        link.send_setpoint(SetpointCommand(1, SETPOINT))
        event = listener.wait_for_event(1)
        link.stop()
        unused.socket.close()        # its robot process stopped before starting a loop
        print(used.returncode, unused.wait(10.0), event.seq, len(listener.failures),
              sum(len(r) for r in listener.records) > 20)
        """)], capture_output=True, text=True, timeout=120)
    assert result.stdout.split() == ["0", "0", "1", "0", "True"], result.stderr


def _state(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"
