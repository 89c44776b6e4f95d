"""The peers' runs and their section of the report: a tiny run of an SB3 algorithm and of ours
under the grid's protocol, counted the runner's way, and the marked block written in place."""
from __future__ import annotations

import json

import pytest
from qg_experiments import peers_report
from qg_experiments.peers import PeerSpec, peer_table
from qg_experiments.runner import config_digest
from qg_experiments.standard_tasks import StandardSpec, goal_found

TINY = {"train_episodes": 2, "train_max_steps": 2, "test_episodes": 2, "test_max_steps": 3}


@pytest.mark.parametrize("algorithm", ["sb3_ddpg", "ddpg"])
@pytest.mark.slow
def test_a_peer_run_trains_its_episodes_then_tests_the_poses(algorithm: str, tmp_path) -> None:
    spec = PeerSpec(algorithm, "defaults", 100, tensorboard_dir=str(tmp_path), **TINY)
    result = spec.run()
    modes = [(e["mode"], e["pose"]) for e in result["episodes"]]
    assert modes == [("train", 0), ("train", 1), ("test", 0), ("test", 1)]
    assert result["train_steps"] == sum(e["steps"] for e in result["episodes"][:2]) <= 4
    assert result["rl_steps"] == sum(e["steps"] for e in result["episodes"])
    assert all(e["steps"] <= 3 for e in result["episodes"][2:])
    assert (tmp_path / spec.name / "progress.csv").exists()
    json.dumps(result)                                            # saved as JSON


def test_peer_specs_refuse_what_the_protocol_does_not_have() -> None:
    with pytest.raises(ValueError, match="grid"):
        PeerSpec("sb3_td3", "grid", 100)                          # a cell needs lr and iterations
    with pytest.raises(ValueError, match="runner"):
        PeerSpec("ddpg", "grid", 100, 1e-3, 50)
    with pytest.raises(ValueError, match="one of"):
        PeerSpec("td3", "defaults", 100)                          # not the registry's key
    assert PeerSpec("sb3_td3", "grid", 100, 1e-3, 50).name == "sb3_td3_lr0.001_it50_s100"


def _fake(algorithm: str, seed: int, tests: list[int], train: int) -> dict:
    episodes = [{"mode": "train", "steps": train, "success": True}]
    episodes += [{"mode": "test", "steps": n, "success": n < 200} for n in tests]
    return {"spec": {"algorithm": algorithm, "setting": "defaults", "seed": seed,
                     "critic_lr": None, "iterations": None}, "episodes": episodes,
            "train_steps": train, "wall_time": 1.0, "config_digest": config_digest()}


def test_the_table_counts_per_seed_means_and_the_section_is_replaced_in_place(tmp_path) -> None:
    results = [_fake("sb3_td3", 100, [4, 200], 500), _fake("sb3_td3", 101, [2, 4], 300)]
    (row,) = peer_table(results)
    assert row["mean_test_steps"]["mean"] == pytest.approx((102 + 3) / 2)
    assert row["solved"] == 3 and row["tests"] == 4 and row["all_solved_seeds"] == 1
    assert row["train_steps"]["mean"] == 400
    out = tmp_path / "runs"
    (out / "peers").mkdir(parents=True)
    stale = {**_fake("sb3_td3", 102, [1, 1], 10), "config_digest": "another arm"}
    for r in (*results, stale):       # a run under other config values is not counted
        (out / "peers" / f"{r['spec']['algorithm']}_{r['spec']['seed']}.json").write_text(
            json.dumps(r))
    results_md = tmp_path / "results.md"
    results_md.write_text("# Results\n\nsection 6\n")
    peers_report.write_section(results_md, out)
    first = results_md.read_text()
    peers_report.write_section(results_md, out)
    assert results_md.read_text() == first and first.startswith("# Results\n\nsection 6\n")
    assert "| SB3 TD3 | defaults | 2 | 52.5 [" in first and "3/4 | 1/2 | 400 [" in first


def _standard_run(algorithm: str, seed: int, final: float) -> dict:
    return {"spec": {"task": "Pendulum-v1", "algorithm": algorithm, "seed": seed},
            "evaluations": [{"steps": 5000, "return": final - 50},
                            {"steps": 10000, "return": final}],
            "final_return": final, "wall_time": 1.0}


def test_the_standard_tasks_block_is_written_alone_and_leaves_the_peers_block_as_it_is(
        tmp_path) -> None:
    """The SB3 shaft runs and the standard tasks' runs are made apart: regenerating one block
    from its runs keeps the other's text, and a block is replaced in place."""
    out = tmp_path / "runs"
    (out / "standard_tasks").mkdir(parents=True)
    finals = {("qgddpg", 100): -150.0, ("qgddpg", 101): -170.0, ("sb3_td3", 100): -160.0,
              ("sb3_td3", 101): -200.0}
    for (algorithm, seed), final in finals.items():
        (out / "standard_tasks" / f"Pendulum_{algorithm}_s{seed}.json").write_text(
            json.dumps(_standard_run(algorithm, seed, final)))
    shaft = f"{peers_report.BEGIN}\n## 8. Peers\n\nthe shaft runs' text\n{peers_report.END}\n"
    results_md = tmp_path / "results.md"
    results_md.write_text(f"# Results\n\n{shaft}\n## 9. The Franka\n")
    peers_report.write_section(results_md, out)
    first = results_md.read_text()
    assert first.startswith(f"# Results\n\n{shaft}\n## 9. The Franka\n")    # untouched
    block = first.split(peers_report.STANDARD_BEGIN, 1)[1].split(peers_report.STANDARD_END)[0]
    assert "| Pendulum-v1 | QG-DDPG (ours) | 10000 | 2 | -160.0 [" in block
    assert "| -150.0, -170.0 | 10000, 10000 | -, - |" in block   # TD3's mean final: -180;
    # Pendulum has no goal to find
    (out / "standard_tasks" / "Pendulum_qgddpg_s101.json").write_text(
        json.dumps(_standard_run("qgddpg", 101, -190.0)))
    peers_report.write_section(results_md, out)
    second = results_md.read_text()
    assert second.count(peers_report.STANDARD_BEGIN) == 1
    assert "| -150.0, -190.0 | 10000, inf | -, - |" in second
    assert second.split(peers_report.STANDARD_BEGIN)[0] == first.split(
        peers_report.STANDARD_BEGIN)[0]


def test_goal_found_counts_the_training_episodes_that_reached_each_cars_goal() -> None:
    """Sparse car: -1 per step, 0 on the goal step, so only a goal episode returns more than
    minus its steps (999 steps at -999: the time limit). MountainCar: +100 at the goal against
    at most 99.9 of action cost, so only a goal episode returns more than 0."""
    def run(task: str, episodes: list[tuple[int, float]]) -> dict:
        return {"spec": {"task": task}, "train_episodes": [
            {"steps": steps, "return": ret} for steps, ret in episodes]}
    sparse = run("qg_experiments:QGSparseMountainCar-v0",
                 [(999, -999.0), (162, -161.0), (497, -497.0), (1, 0.0)])
    dense = run("MountainCarContinuous-v0", [(999, -99.9), (120, 88.5), (999, -0.01)])
    assert goal_found(sparse) == (2, 4) and goal_found(dense) == (1, 3)
    assert goal_found(run("Pendulum-v1", [(200, -1200.0)])) is None


def test_a_standard_task_run_evaluates_along_the_way(tmp_path) -> None:
    result = StandardSpec("Pendulum-v1", "qgddpg", 100, steps=250).run()
    assert [e["steps"] for e in result["evaluations"]] == [250]
    assert [e["steps"] for e in result["train_episodes"]] == [200]     # one finished episode
    assert -2000 < result["final_return"] <= 0


def test_sb3_models_take_action_noise_where_the_registry_says_and_the_sparse_car_is_named(
        ) -> None:
    import gymnasium
    from qg_experiments.sb3_models import sb3_model
    env = gymnasium.make("qg_experiments:QGSparseMountainCar-v0")
    sac = sb3_model("sb3_sac", env, 0, ("ou", 0.5, 0.15))
    td3 = sb3_model("sb3_td3", env, 0, ("ou", 0.5, 0.15))
    assert type(sac).__name__ == "SAC" and sac.action_noise is None       # its policy explores
    assert type(td3.action_noise).__name__ == "OrnsteinUhlenbeckActionNoise"
    spec = StandardSpec("qg_experiments:QGSparseMountainCar-v0", "sb3_sac", 100, steps=250)
    assert spec.name == "QGSparseMountainCar_sb3_sac_250_s100"


def _save_run(out, spec: StandardSpec, digest: str, **extra) -> None:
    """A saved run of ``spec`` under ``out``, as ``run_specs`` leaves it (its spec and the
    config digest it was made under), with ``extra`` fields."""
    import dataclasses

    from qg_experiments.tasks import result_path
    path = result_path(out, spec)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"spec": dataclasses.asdict(spec), "config_digest": digest,
                                **extra}))


def test_a_saved_standard_run_without_its_tasks_settings_of_ours_is_not_reused(tmp_path) -> None:
    """MountainCar gives our agents the actor's pre-tanh penalty: a run saved before that (no
    ``task_settings``) is another run, SB3's and the other tasks' runs are unaffected."""
    from qg_experiments.tasks import unsaved

    ours = StandardSpec("MountainCarContinuous-v0", "qgddpg", 100)
    sb3 = StandardSpec("MountainCarContinuous-v0", "sb3_td3", 100)
    pendulum = StandardSpec("Pendulum-v1", "qgddpg", 100)
    assert ours.task_settings == {"actor_preact_penalty": 0.1}
    assert sb3.task_settings == {} and pendulum.task_settings == {}
    for spec in (ours, sb3, pendulum):                 # saved as before the settings existed
        _save_run(tmp_path, spec, config_digest(None))
    assert unsaved([ours, sb3, pendulum], tmp_path) == [ours]
    _save_run(tmp_path, ours, config_digest(None), task_settings={"actor_preact_penalty": 0.1})
    assert unsaved([ours, sb3, pendulum], tmp_path) == []


def test_a_run_saved_from_a_frozen_copy_of_the_config_is_the_same_run_until_a_number_differs(
        tmp_path) -> None:
    """A long sweep reads a copy of config/ (``--config-dir``): its runs are resumed from
    config/ itself, whose numbers they were made with, and are rerun from the copy once a number
    there is edited."""
    import shutil

    from qg_common.params import config_file
    from qg_experiments.runner import STACK_CONFIG_FILES
    from qg_experiments.tasks import unsaved

    copy = tmp_path / "config"
    copy.mkdir()
    for name in STACK_CONFIG_FILES:
        shutil.copy(config_file(name), copy / name)
    frozen = StandardSpec("Pendulum-v1", "qgddpg", 100, config_dir=str(copy))
    _save_run(tmp_path / "runs", frozen, config_digest(copy))
    here = StandardSpec("Pendulum-v1", "qgddpg", 100)
    assert unsaved([here, frozen], tmp_path / "runs") == []
    learner = (copy / "learner.yaml").read_text()
    assert "batch_size: 64" in learner
    (copy / "learner.yaml").write_text(learner.replace("batch_size: 64", "batch_size: 32"))
    assert unsaved([here, frozen], tmp_path / "runs") == [frozen]
