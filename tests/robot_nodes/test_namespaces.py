"""Relative names: ``__ns`` puts a whole robot process in a namespace, and two robots side by
side never hear each other."""
from __future__ import annotations

import pytest
from robot_client import RobotClient

pytestmark = pytest.mark.ros


def test_two_namespaced_robot_processes_run_side_by_side_without_crosstalk(stack):
    stack.start(*[(ns, "robot_bridge_node", "robot", ("--ros-args", "-r", f"__ns:=/{ns}"))
                  for ns in ("robot1", "robot2")])
    with stack.client() as cli:
        names = set()
        assert cli.spin_until(lambda: names.update(cli.node_names())
                              or {"/robot1/bridge", "/robot2/bridge", "/robot1/sim",
                                  "/robot2/sim"} <= names, 30.0), f"{names}\n{stack.logs()}"
        one, two = RobotClient(cli, "/robot1"), RobotClient(cli, "/robot2")
        assert one.reset(1).success, stack.logs()
        assert two.reset(5).success, stack.logs()
        settled = (len(one.events), len(two.events))
        cli.spin_for(0.5)
        assert (len(one.events), len(two.events)) == settled == (1, 1)
        # A setpoint to robot1 moves robot1 only: robot2 reports nothing.
        assert one.step(1, (0.0, 0.0, -10.0, 0.5, 0.0, 0.0)) is not None, stack.logs()
        cli.spin_for(0.5)
        assert len(two.events) == 1 and two.event(1) is None
        assert two.step(7, (0.0, 0.0, -10.0, 0.0, -0.5, 0.0)) is not None, stack.logs()
        assert one.event(7) is None
        # Each robot answered from its own start pose: 45 deg * pose apart in tilt direction.
        assert one.events[0].ee_pose.orientation != two.events[0].ee_pose.orientation
    assert stack.launcher.poll() == []
