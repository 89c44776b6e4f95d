"""``qgl demo --robots 2``: two robots train at once into one learner, then the test runs on
robot0."""
from __future__ import annotations

import json
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import SHORT_STEP, Stack

pytestmark = pytest.mark.ros

TRAIN_MAX_STEPS, TEST_MAX_STEPS = 8, 4


@dataclass
class DemoRun:
    run_dir: Path
    outcomes: list[dict]
    summary: str
    output: str


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> DemoRun:
    """One short demo: 2 training episodes (one per robot) of at most 8 steps, 1 test pose."""
    tmp = tmp_path_factory.mktemp("fleet_demo")
    env = Stack(tmp).env                 # the private domain and the stack's environment
    (tmp / "stack.yaml").write_text(
        "processes:\n"
        # The 0.25 s step: the subject is the fleet, not the step.
        "  - {name: robot, package: robot_bridge_node, executable: robot,\n"
        f"     args: [--ros-args, {', '.join(SHORT_STEP)}]}}\n"
        "  - {name: learner, package: qg_learning_node, executable: learner}\n"
        "  - {name: executor, package: qg_learning_node, executable: executor,\n"
        f"     args: [--ros-args, -p, 'task.test_max_steps:={TEST_MAX_STEPS}']}}\n")
    demo = subprocess.run(
        [sys.executable, "-m", "qg_bringup.main", "demo", "--robots", "2",
         "--train-episodes", "2", "--train-max-steps", str(TRAIN_MAX_STEPS), "--test-poses", "1",
         "--episode-timeout", "120", "--config", str(tmp / "stack.yaml"),
         "--runs-dir", str(tmp / "runs")],
        env=env, capture_output=True, text=True, timeout=240)
    output = demo.stdout + demo.stderr
    (run_dir,) = (tmp / "runs").glob("demo_*")
    assert demo.returncode == 0, output + "".join(
        f"\n--- {p.name}\n{p.read_text()}" for p in sorted((run_dir / "logs").glob("*.log")))
    summary = [line for line in demo.stdout.splitlines() if line.startswith("[qgl demo] test:")]
    assert summary, output
    return DemoRun(run_dir, json.loads((run_dir / "episodes.json").read_text()), summary[-1],
                   output)


def test_two_robots_train_at_once_into_one_learner_then_robot0_tests(demo_run: DemoRun) -> None:
    from qg_learning_node.learner.offline import iter_transitions

    train = [o for o in demo_run.outcomes if o["mode"] == "train"]
    tests = [o for o in demo_run.outcomes if o["mode"] == "test"]
    assert [o["robot"] for o in train] == ["robot0", "robot1"]
    assert [(o["robot"], o["initial_pose"]) for o in tests] == [("robot0", 0)]
    for o in demo_run.outcomes:
        assert o["episode_id"].startswith(o["robot"] + "_"), o
        assert 1 <= o["steps"] <= (TRAIN_MAX_STEPS if o["mode"] == "train" else TEST_MAX_STEPS)
    # Concurrent: each robot's training episode started before the other one's ended.
    for a, b in (train, train[::-1]):
        assert a["started"] < b["started"] + b["wall_time"], (a, b)
    # Each robot's bags hold its own episodes, step by step.
    for o in demo_run.outcomes:
        bag = demo_run.run_dir / "episodes" / o["episode_id"]
        recorded = list(iter_transitions([bag]))
        assert sorted(t.step for t in recorded) == list(range(o["steps"])), o
    train_steps = sum(o["steps"] for o in train)
    total = train_steps + sum(o["steps"] for o in tests)
    assert f"training: {train_steps} RL steps, " in demo_run.summary, demo_run.summary
    assert f"the learner received {total} transitions" in demo_run.summary, demo_run.summary
    assert "on 2 robot(s)" in demo_run.summary and "3 MCAP episodes (robot0 2, robot1 1)" \
        in demo_run.summary, demo_run.summary
    assert (demo_run.run_dir / "learning_curve.png").stat().st_size > 0
    assert (demo_run.run_dir / "last_test_episode.mp4").stat().st_size > 0    # qgl render
    assert list((demo_run.run_dir / "tensorboard").glob("events.out.tfevents.*"))
    # the progress line showed both robots' steps (r0 ... step k, r1 ... step k)
    assert re.search(r"r0 train 1/3 step \d+, r1 train 2/3 step \d+", demo_run.output)
