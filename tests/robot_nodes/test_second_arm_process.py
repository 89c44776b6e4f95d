"""The xArm 7 (``robot:=sim_xarm7``) through the same ``robot`` process as the Panda: it inserts
the shaft; nothing but the ``robot`` parameter differs from the Panda's runs (the separate
processes: test_realtime.py)."""
from __future__ import annotations

import numpy as np
import pytest
from robot_client import DEEP, RobotClient, wrench

pytestmark = pytest.mark.ros

XARM = ("--ros-args", "-p", "robot:=sim_xarm7")


def test_the_composed_robot_process_runs_a_shaft_episode_on_the_xarm(stack):
    from sensor_msgs.msg import JointState
    stack.start(("robot", "robot_bridge_node", "robot", XARM))
    with stack.client() as cli:
        names: list[list[str]] = []
        cli.node.create_subscription(JointState, "/joint_states",
                                     lambda m: names.append(list(m.name)), DEEP)
        robot = RobotClient(cli)
        reply = robot.reset(0)
        assert reply.success, reply.message + stack.logs()
        assert names and names[-1] == [f"joint{i}" for i in range(1, 8)]
        rng = np.random.default_rng(0)       # the in-process test's residuals: 12 steps there
        inserted = 0
        for seq in range(1, 101):
            tx, ty = 3.0 * rng.uniform(-1.0, 1.0, 2)
            event = robot.step(seq, (0.0, 0.0, -15.0, tx, ty, 0.0))
            assert event is not None, f"no AtRest for seq {seq}\n{stack.logs()}"
            assert np.all(np.isfinite(wrench(event.wrench_estimate)))
            if event.ground_truth.success:
                inserted = seq
                break
        assert inserted, f"not inserted in 100 steps (depth {event.ground_truth.insertion_depth})"
    assert stack.stop() == {"robot": 0}
