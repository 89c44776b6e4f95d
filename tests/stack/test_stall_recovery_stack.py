"""Stall recovery through the ROS stack: the executor node recovers a stalled test episode, and
each recovery is in the episode's status and in its bag.

The actor is the recorded stalling one (``tests/fixtures/stalled_tilt_motion_seed0.npz``, the
stall probe's learning on seed 0 at critic lr 1e-4 in the default ``tilt_motion`` state: on
pose 1 it jams the shaft), published on ``/actor_parameters`` as a learner would; the robot
process runs the default step on robot 0, and the executor reads no progress from the state's
motion (``ResidualTask.progress_dims``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_episodes import Episodes, wait_for_bag

pytestmark = pytest.mark.ros

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "stalled_tilt_motion_seed0.npz"
CAP = 200          # the report's test cap


def test_the_executor_recovers_a_stalled_test_episode_and_says_so(stack, capsys):
    from qg_bringup.episode_wait import wait_for_episode
    from qg_common.topics import LATCHED
    from qg_interfaces.msg import ActorParameters
    from qg_learning_node.conversions import actor_to_msg
    from qg_recording.player import message_class
    from rclpy.serialization import deserialize_message
    from rosbags.highlevel import AnyReader

    data = np.load(FIXTURE)
    tensors = [(str(name), data[f"actor_{i}"]) for i, name in enumerate(data["actor_names"])]
    stack.start(("robot", "robot_bridge_node", "robot",
                 ("--ros-args", "-p", "sim.clock_mode:=lockstep")),
                ("executor", "qg_learning_node", "executor",
                 ("--ros-args", "-p", "stall_recovery.enabled:=true",
                  "-p", f"task.test_max_steps:={CAP}", "-p", "learner_timeout:=3600.0",
                  "-p", "learner_grace:=0.0")))
    with stack.client() as cli:
        actor = cli.node.create_publisher(ActorParameters, "/actor_parameters", LATCHED)
        actor.publish(actor_to_msg(7, tensors))
        episodes = Episodes(cli)
        episodes.wait_for_robot()
        assert cli.spin_until(lambda: actor.get_subscription_count() >= 1, 60.0), stack.logs()
        cli.spin_for(1.0)
        response = episodes.start(mode="test", initial_pose=1, seed=5, reward="dense")
        assert response.success, response.message + stack.logs()
        final = episodes.final(response.episode_id, timeout=600.0)
        mine = [s for s in episodes.statuses if s.episode_id == response.episode_id]
        capsys.readouterr()
        assert wait_for_episode(cli, response.episode_id, 10.0) == 0   # `qgl episode --wait`
        printed = capsys.readouterr().out
    # The recorded actor ran (not the zero residual) and inserted after at least one recovery,
    # each announced while running.
    assert final.state == "done" and not final.degraded and final.actor_version == 7, \
        final.message + stack.logs()
    assert final.success and final.step < CAP, (final.step, stack.logs())
    assert final.recoveries >= 1
    announced = {s.message for s in mine if s.message.startswith("stall recovery")}
    assert any(m.startswith(f"stall recovery {final.recoveries} at step") for m in announced), \
        announced
    # Each recovery perturbs twice as many steps as the one before (stall_recovery.growth 2).
    assert any(m.startswith("stall recovery 1 at step") and m.endswith(": 5 noise steps")
               for m in announced), announced
    assert final.recoveries < 2 or any(m.startswith("stall recovery 2 at step") and m.endswith(
        ": 10 noise steps") for m in announced), announced
    assert [s.recoveries for s in mine] == sorted(s.recoveries for s in mine)   # it only counts up
    assert f"recoveries={final.recoveries} " in printed, printed

    bag = wait_for_bag(Path(stack.env["QG_RUNS_DIR"]) / "episodes", response.episode_id)
    with AnyReader([bag]) as reader:
        (connection,) = [c for c in reader.connections if c.topic == "/episode_status"]
        cls = message_class(connection.msgtype)
        recorded = [deserialize_message(bytes(raw), cls)
                    for _, _, raw in reader.messages(connections=[connection])]
    assert recorded[-1].state == "done" and recorded[-1].recoveries == final.recoveries
    assert any(s.message.startswith("stall recovery 1 at step") for s in recorded)
