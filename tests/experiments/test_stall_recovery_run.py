"""Stall recovery in process: a recorded stalling actor inserts with it, counted; a run saved
with recovery keeps its test episodes the thesis protocol's and counts recovery apart.

The actor is the one of ``tests/fixtures/stalled_tilt_motion_seed0.npz`` (the stall probe's
learning on seed 0 at critic lr 1e-4, 10 iterations, in the default ``tilt_motion`` state), run
on the real in-process robot of seed 0 (sim, bridge loop, EKF).
"""
from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from qg_experiments import grid
from qg_experiments.profile import GridBudget
from qg_experiments.runner import (
    InsertionRobot,
    RunSpec,
    StackSettings,
    config_digest,
    recovery_seed,
    run_episode,
    run_training,
    stall_recovery_config,
)
from qg_experiments.stalls import run_recoveries, stall_counts
from qg_experiments.tasks import result_path, unsaved
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_learning_node.executor.stall_recovery import StallRecovery
from qg_learning_node.learner.actor_mlp import ActorMLP

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "stalled_tilt_motion_seed0.npz"
POSE = 1          # a jam in the recording


def _stalling_actor() -> ActorMLP:
    data = np.load(FIXTURE)
    return ActorMLP.from_tensors([(str(name), data[f"actor_{i}"])
                                  for i, name in enumerate(data["actor_names"])])


@pytest.mark.slow
def test_recovery_turns_a_stalled_test_pose_into_an_inserted_one_counted() -> None:
    settings = StackSettings.load().with_arm_seed(0)
    settings = dataclasses.replace(settings, task=dataclasses.replace(
        settings.task, test_max_steps=60))
    assert settings.task.observation == "tilt_motion"             # the recorded actor's state
    env = InsertionRobot(settings)
    actor = _stalling_actor()
    records: list = []
    plain = run_episode(env, Episode("test", "test", POSE, "dense", env.residual), actor,
                        records.append)
    assert not plain["success"] and plain["steps"] == 60          # the deterministic actor stalls
    assert "recoveries" not in plain
    config = stall_recovery_config()
    tail = np.array([r.state for r in records[-config.window:]])
    # ... jammed: no step of the last window moved 0.1 mm along the bore
    assert np.abs(tail[:, 2]).max() <= config.progress_tolerance
    watch = StallRecovery(config, ACTION_DIM, recovery_seed(0, POSE), settings.noise,
                          env.residual.progress_dims)
    recovered = run_episode(env, Episode("recovery", "test", POSE, "dense", env.residual),
                            actor, recovery=watch)
    assert recovered["success"] and recovered["steps"] < 60
    assert recovered["recoveries"] >= 1 and recovered["recoveries"] == len(
        recovered["recovered_at"])
    # The first recovery starts once a whole window of no progress has passed.
    assert recovered["recovered_at"][0] >= config.window - 1


def test_a_profile_grid_can_ask_every_run_for_recovery() -> None:
    cells = ((1e-2, 50), (1e-3, 10))
    plain = grid.grid_specs(GridBudget(cells=cells, seeds=(100, 101)))
    recovered = grid.grid_specs(GridBudget(cells=cells, seeds=(100, 101), stall_recovery=True))
    assert not any(s.stall_recovery for s in plain)
    assert all(s.stall_recovery and s.name.endswith(f"_recovery_s{s.seed}") for s in recovered)
    # The same runs otherwise: saved apart by name, never mixed into the grid without it.
    assert [dataclasses.replace(s, stall_recovery=False) for s in recovered] == plain
    assert not {s.name for s in plain} & {s.name for s in recovered}


@pytest.mark.slow
def test_a_run_with_recovery_counts_it_apart_from_its_test_episodes() -> None:
    spec = RunSpec(algorithm="qgddpg", critic_lr=1e-2, iterations=2, seed=4, train_episodes=1,
                   test_episodes=2, train_max_steps=4, test_max_steps=3, cycle_steps=2)
    plain, with_recovery = run_training(spec), run_training(
        dataclasses.replace(spec, stall_recovery=True))
    assert with_recovery["name"] == "qgddpg_lr0.01_it2_recovery_s4" != plain["name"]
    modes = [e["mode"] for e in with_recovery["episodes"]]
    assert modes == ["train", "test", "test", "recovery", "recovery"]
    # The thesis protocol's episodes are those of the run without recovery, bit for bit, and
    # the test numbers read only them.
    assert with_recovery["episodes"][:3] == plain["episodes"]
    assert grid.test_steps(with_recovery) == grid.test_steps(plain)
    recovery = with_recovery["episodes"][3:]
    assert all("recoveries" in e for e in recovery)
    assert with_recovery["stall_recovery"]["enabled"] is True
    assert "stall_recovery" not in plain
    # The recovery's numbers are the run's identity too: saved, and compared when resuming.
    assert with_recovery["task_settings"] == {"stall_recovery": with_recovery["stall_recovery"]}
    assert spec.task_settings == {} and "task_settings" not in plain
    # Counted apart: a run that trained shows its recovery episodes beside its stalls.
    trained = [{"mode": "train", "pose": p, "success": True} for p in range(8)]
    episodes = trained + with_recovery["episodes"][1:]
    assert run_recoveries(episodes) == {
        "recovery_episodes": 2, "inserted_with_recovery": sum(e["success"] for e in recovery),
        "recoveries": sum(e["recoveries"] for e in recovery)}
    counts = stall_counts([("qgddpg", episodes)])["qgddpg"]
    assert counts["trained_test_episodes"] == 2 and counts["recovery_episodes"] == 2


def test_a_saved_run_with_recovery_is_reused_only_under_the_same_recovery(tmp_path: Path) -> None:
    config = tmp_path / "config"
    shutil.copytree(Path(__file__).resolve().parents[2] / "config", config)
    spec = RunSpec(algorithm="qgddpg", critic_lr=1e-2, iterations=2, seed=4,
                   config_dir=str(config), stall_recovery=True)
    path = result_path(tmp_path / "runs", spec)
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps({"spec": dataclasses.asdict(spec),
                                "config_digest": config_digest(str(config)),
                                "task_settings": spec.task_settings}))
    assert unsaved([spec], tmp_path / "runs") == []
    executor = config / "executor.yaml"
    executor.write_text(executor.read_text().replace("      steps: 5 ", "      steps: 8 "))
    assert spec.task_settings["stall_recovery"]["steps"] == 8
    assert config_digest(str(config)) == json.loads(path.read_text())["config_digest"]
    assert unsaved([spec], tmp_path / "runs") == [spec]     # the recovery changed: run again
