"""Many robots, one learner (``qgl up --robots 2``): two namespaced robot stacks run episodes
at the same time and one learner at the root learns from both and hands both the same actor."""
from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Stack
from test_episodes import ROBOT, Episodes, executor_spec, learner_spec, wait_for_bag

pytestmark = pytest.mark.ros

ROBOTS = ("robot0", "robot1")


def stamp_s(msg) -> float:
    return msg.stamp.sec + msg.stamp.nanosec * 1e-9


@dataclass
class TwoRobots:
    """Two robots' concurrent training episodes into one learner, the stack still up."""
    stack: Stack
    cli: Any
    episodes: dict[str, Episodes]
    started: dict[str, Any]          # robot -> StartEpisode response
    finals: dict[str, Any]           # robot -> final EpisodeStatus
    checkpoints: Path


@pytest.fixture(scope="module")
def two_robots(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TwoRobots]:
    from qg_bringup.fleet import fleet_specs
    from qg_bringup.stack_file import ProcessSpec
    from qg_interfaces.srv import StartEpisode

    tmp_path = tmp_path_factory.mktemp("two_robots")
    stack = Stack(tmp_path)
    try:
        stack.launcher.start(fleet_specs([ProcessSpec(*s) for s in (
            ROBOT, learner_spec(tmp_path / "checkpoints"), executor_spec(max_steps=20))],
            robots=2))
        with stack.client() as cli:
            episodes = {ns: Episodes(cli, ns) for ns in ROBOTS}
            episodes["robot0"].wait_for_learner()
            # robot1's episode by `qgl episode start --robot robot1`, robot0's by a service call
            qgl = subprocess.run([sys.executable, "-m", "qg_bringup.main", "episode",
                                  "start", "--robot", "robot1", "--initial-pose", "1", "--seed",
                                  "5", "--timeout", "60"],
                                 env=stack.env, capture_output=True, text=True, timeout=120)
            assert qgl.returncode == 0, qgl.stdout + qgl.stderr
            started = {"robot1": StartEpisode.Response(
                success=True, message="",
                episode_id=re.search(r"episode_id='(\w+)'", qgl.stdout)[1]),
                "robot0": episodes["robot0"].start(mode="train", initial_pose=0, seed=5)}
            for ns, response in started.items():
                assert response.success, response.message + stack.logs()
            finals = {ns: episodes[ns].final(started[ns].episode_id, timeout=240.0)
                      for ns in ROBOTS}
            yield TwoRobots(stack, cli, episodes, started, finals, tmp_path / "checkpoints")
    finally:
        stack.stop(grace=3.0)


def test_two_robots_run_concurrent_episodes_into_one_learner(two_robots: TwoRobots):
    from qg_learning_node.learner.offline import iter_transitions

    run, cli = two_robots, two_robots.cli
    episodes, started, finals, stack = run.episodes, run.started, run.finals, run.stack
    learner = episodes["robot0"]
    for ns, response in started.items():
        assert response.episode_id.startswith(f"{ns}_"), response.episode_id
    for ns, final in finals.items():
        assert final.state == "done" and 1 <= final.step <= 20, final.message + stack.logs()
    # Concurrent: each episode was running before the other one ended.
    for ns, other in (ROBOTS, ROBOTS[::-1]):
        running = min(stamp_s(s) for s in episodes[ns].statuses
                      if s.episode_id == started[ns].episode_id and s.state == "running")
        assert running < stamp_s(finals[other]), (ns, running, stamp_s(finals[other]))

    total = sum(f.step for f in finals.values())
    assert cli.spin_until(lambda: learner.learner_heartbeats[-1].transitions == total, 30.0), \
        (learner.learner_heartbeats[-1], total)
    # A heartbeat can go out while the last cycle trains (every transition in, its actor not
    # yet): give that cycle its time.
    cli.spin_until(lambda: learner.learner_heartbeats[-1].actor_version == total // 10, 10.0)
    version = learner.learner_heartbeats[-1].actor_version
    assert version == total // 10      # cycle_steps 10: one new actor per 10 transitions
    # Both executors hold the learner's latest actor (their status heartbeat says which).
    assert cli.spin_until(lambda: all(e.statuses[-1].actor_version == version
                                      for e in episodes.values()), 10.0), \
        {ns: e.statuses[-1].actor_version for ns, e in episodes.items()}

    # Each robot's recorder heard only its own namespace: its bag holds its own transitions.
    runs = Path(stack.env["QG_RUNS_DIR"]) / "episodes"
    for ns in ROBOTS:
        episode_id = started[ns].episode_id
        recorded = list(iter_transitions([wait_for_bag(runs, episode_id)]))
        assert {t.episode_id for t in recorded} == {episode_id}
        assert sorted(t.step for t in recorded) == list(range(finals[ns].step))
    assert stack.launcher.poll() == [], stack.logs()


def test_offline_rebuild_of_both_robots_bags_gives_the_learners_memory(two_robots: TwoRobots):
    """The learner checkpoints after every training episode: then its memory holds both
    robots' transitions, one trajectory chain per robot. The rebuild from the two robots' bags
    (`qgl replay --into-learner`) must hold the same transitions, chains and graph."""
    from qg_common.params import config_file, load_ros_params
    from qg_learning_node.learner.learner_core import LearnerCore
    from qg_learning_node.learner.learner_params import learner_config_from_params
    from qg_learning_node.learner.offline import rebuild_from_bags

    run = two_robots
    total = sum(f.step for f in run.finals.values())
    checkpoint = run.checkpoints / "learner.pt"
    # the checkpoint after the later episode's end, once all its transitions are in
    assert run.cli.spin_until(lambda: checkpoint.exists()
                              and LearnerCore.load(checkpoint).steps == total, 15.0), \
        run.stack.logs()
    online = LearnerCore.load(checkpoint)
    runs = Path(run.stack.env["QG_RUNS_DIR"]) / "episodes"
    bags = [wait_for_bag(runs, run.started[ns].episode_id) for ns in ROBOTS]
    params = load_ros_params(config_file("learner.yaml"), "learner")["learner"]
    params["cycle_steps"] = 10
    result = rebuild_from_bags(bags, config=learner_config_from_params(params))

    assert result.transitions == online.steps == total
    assert result.robots == {ns: run.finals[ns].step for ns in ROBOTS}
    assert result.census == online.graph.census()
    rebuilt, expected = result.learner_core.replay.state_dict(), online.replay.state_dict()
    assert rebuilt["chain_ends"].keys() == expected["chain_ends"].keys() == set(ROBOTS)
    for robot, (_, next_state) in expected["chain_ends"].items():   # where each chain goes on
        assert np.array_equal(rebuilt["chain_ends"][robot][1], next_state), robot
    assert chains(rebuilt) == chains(expected)


def chains(replay: dict) -> list[tuple[bytes, ...]]:
    """Every trajectory chain of a replay memory, as the bytes of its states in order (a
    transition outside every chain, such as a synthetic one, is a chain of one)."""
    n = replay["added"]
    slot = {int(s): i for i, s in enumerate(replay["serial"][:n])}
    found = []
    for i in range(n):
        if replay["prev"][i] >= 0:
            continue
        chain, j = [], i
        while j is not None:
            chain.append(replay["states"][j].tobytes())
            j = slot.get(int(replay["next"][j]))
        found.append(tuple(chain))
    assert sum(len(c) for c in found) == n
    return sorted(found)


@pytest.mark.parametrize("namespaces, word", [("[robot0,robot0]", "twice"),
                                              ("[robot0,2robot]", "not a ROS namespace")])
def test_learner_refuses_bad_robot_namespaces_with_a_message(stack, namespaces, word):
    stack.start(("learner", "qg_learning_node", "learner",
                 ("--ros-args", "-p", f"robot_namespaces:={namespaces}")))
    (_, code), = [stack.launcher.wait_any()]
    assert code == 2 and word in stack.logs(), stack.logs()
