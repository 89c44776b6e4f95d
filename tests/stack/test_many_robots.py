"""Many robots, one learner (``qgl up --robots 2``): two namespaced robot stacks run episodes
at the same time and one learner at the root learns from both and hands both the same actor."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_episodes import ROBOT, Episodes, executor_spec, learner_spec, wait_for_bag

pytestmark = pytest.mark.ros


def stamp_s(msg) -> float:
    return msg.stamp.sec + msg.stamp.nanosec * 1e-9


def test_two_robots_run_concurrent_episodes_into_one_learner(stack, tmp_path):
    from qg_interfaces.srv import StartEpisode

    from qg_learning_node.cli.fleet import fleet_specs
    from qg_learning_node.cli.launcher import ProcessSpec
    from qg_learning_node.offline import iter_transitions

    stack.launcher.start(fleet_specs([ProcessSpec(*s) for s in (
        ROBOT, learner_spec(tmp_path / "checkpoints"), executor_spec(max_steps=20))], robots=2))
    robots = ("robot0", "robot1")
    with stack.client() as cli:
        episodes = {ns: Episodes(cli, ns) for ns in robots}
        learner = episodes["robot0"]
        learner.wait_for_learner()
        # robot1's episode by `qgl episode start --robot robot1`, robot0's by a service call
        qgl = subprocess.run([sys.executable, "-m", "qg_learning_node.cli.main", "episode",
                              "start", "--robot", "robot1", "--initial-pose", "1", "--seed", "5",
                              "--timeout", "60"],
                             env=stack.env, capture_output=True, text=True, timeout=120)
        assert qgl.returncode == 0, qgl.stdout + qgl.stderr
        started = {"robot1": StartEpisode.Response(
            success=True, message="", episode_id=re.search(r"episode_id='(\w+)'", qgl.stdout)[1]),
            "robot0": episodes["robot0"].start(mode="train", initial_pose=0, seed=5)}
        for ns, response in started.items():
            assert response.success, response.message + stack.logs()
            assert response.episode_id.startswith(f"{ns}_"), response.episode_id
        finals = {ns: episodes[ns].final(started[ns].episode_id, timeout=240.0) for ns in robots}
        for ns, final in finals.items():
            assert final.state == "done" and 1 <= final.step <= 20, final.message + stack.logs()
        # Concurrent: each episode was running before the other one ended.
        for ns, other in (robots, robots[::-1]):
            running = min(stamp_s(s) for s in episodes[ns].statuses
                          if s.episode_id == started[ns].episode_id and s.state == "running")
            assert running < stamp_s(finals[other]), (ns, running, stamp_s(finals[other]))

        total = sum(f.step for f in finals.values())
        assert cli.spin_until(lambda: learner.learner_heartbeats[-1].transitions == total, 30.0), \
            (learner.learner_heartbeats[-1], total)
        version = learner.learner_heartbeats[-1].actor_version
        assert version == total // 10      # cycle_steps 10: one new actor per 10 transitions
        # Both executors hold the learner's latest actor (their status heartbeat says which).
        assert cli.spin_until(lambda: all(e.statuses[-1].actor_version == version
                                          for e in episodes.values()), 10.0), \
            {ns: e.statuses[-1].actor_version for ns, e in episodes.items()}

    # Each robot's recorder heard only its own namespace: its bag holds its own transitions.
    runs = Path(stack.env["QG_RUNS_DIR"]) / "episodes"
    for ns in robots:
        episode_id = started[ns].episode_id
        recorded = list(iter_transitions([wait_for_bag(runs, episode_id)]))
        assert {t.episode_id for t in recorded} == {episode_id}
        assert sorted(t.step for t in recorded) == list(range(finals[ns].step))
    assert stack.launcher.poll() == [], stack.logs()


@pytest.mark.parametrize("namespaces, word", [("[robot0,robot0]", "twice"),
                                              ("[robot0,2robot]", "not a ROS namespace")])
def test_learner_refuses_bad_robot_namespaces_with_a_message(stack, namespaces, word):
    stack.start(("learner", "qg_learning_node", "learner",
                 ("--ros-args", "-p", f"robot_namespaces:={namespaces}")))
    (_, code), = [stack.launcher.wait_any()]
    assert code == 2 and word in stack.logs(), stack.logs()
