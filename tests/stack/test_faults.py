"""Faults of the RL nodes with real processes: shutdown mid-episode, a learner restarted or
busy training."""
from __future__ import annotations

import signal
import time

import pytest
from test_episodes import ROBOT, Episodes, executor_spec

pytestmark = pytest.mark.ros


def test_executor_stopped_mid_episode_aborts_it_and_exits_zero(stack):
    """SIGINT (Ctrl-C, ``qgl up`` stopping) and SIGTERM alike: the running episode ends as
    ``aborted`` (reason ``shutdown``) on the latched status, the robot gets the zero residual,
    and the process says so and exits 0 without a traceback."""
    from qg_interfaces.msg import WrenchSetpoint

    from qg_common.topics import COMMAND_QOS
    stack.start(ROBOT)
    with stack.client() as cli:
        episodes = Episodes(cli)
        setpoints: list = []
        cli.node.create_subscription(WrenchSetpoint, "/wrench_setpoint", setpoints.append,
                                     COMMAND_QOS)
        episodes.wait_for_robot()
        for name, sig in (("executor_int", signal.SIGINT), ("executor_term", signal.SIGTERM)):
            spec = executor_spec(max_steps=400)
            stack.start((name, *spec[1:]))
            response = episodes.start(mode="train", initial_pose=1)
            assert response.success, response.message + stack.logs()
            assert cli.spin_until(lambda: any(s.episode_id == response.episode_id and s.step >= 2
                                              for s in episodes.statuses), 120.0), stack.logs()
            proc = next(r for r in stack.launcher.running if r.spec.name == name).popen
            proc.send_signal(sig)
            final = episodes.final(response.episode_id, timeout=10.0)
            assert final.state == "aborted" and final.message == "shutdown", (final, stack.logs())
            assert proc.wait(timeout=5.0) == 0, stack.logs()
            cli.spin_for(0.3)
            assert setpoints[-1].seq > final.step            # after the last step's command
            assert [setpoints[-1].wrench.force.z, setpoints[-1].wrench.torque.x,
                    setpoints[-1].wrench.torque.y] == [-15.0, 0.0, 0.0]   # the zero residual
            log = (stack.log_dir / f"{name}.log").read_text()
            assert "Traceback" not in log and "InvalidHandle" not in log, log
            said = [line for line in log.splitlines() if "shutdown" in line]
            assert len(said) == 1 and response.episode_id in said[0], log
