"""The fast experiment runner: determinism per seed, and every experiment path end to end.

Uses the ``tiny`` profile of ``config/experiments.yaml`` (a handful of RL steps per run) with the
real robot loop, EKF, episode logic and learner, so a broken composition fails here in CI.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from qg_common.types import NO_GROUND_TRUTH, GroundTruth, StepResult
from qg_experiments import franka_report, grid, peers_report, peg
from qg_experiments.profile import load_profile
from qg_experiments.runner import RunSpec, StackSettings, run_training
from qg_experiments.suite import run_suite
from qg_learning_node.executor.observation import observation_from_step


def _truth(success: bool) -> GroundTruth:
    return GroundTruth(wrench=np.zeros(6), insertion_depth=0.01, plunger_travel=0.0,
                       success=success, position_error=0.003,
                       orientation_error=np.array([0.3, 0.4]), lateral_offset=0.002, tilt=0.1)


def test_observation_takes_the_estimate_the_measured_pose_and_the_truth_aside() -> None:
    estimate = np.array([1.0, 2.0, -15.0, 0.1, 0.2, 0.0])
    position, rotation = np.array([0.4, 0.1, 0.3]), np.diag([1.0, -1.0, -1.0])
    obs = observation_from_step(StepResult(0.1, False, 0.0, 0.0, _truth(True), estimate),
                                position, rotation)
    np.testing.assert_array_equal(obs.wrench, estimate)
    np.testing.assert_array_equal(obs.tool_position, position)
    np.testing.assert_array_equal(obs.tool_rotation, rotation)
    assert obs.truth is not None and obs.truth.success and obs.truth.position_error == 0.003
    no_truth = observation_from_step(StepResult(0.1, False, 0.0, 0.0, NO_GROUND_TRUTH, estimate),
                                     position, rotation)
    assert no_truth.truth is None                            # a real arm: nothing to evaluate
    with pytest.raises(ValueError, match="estimator"):
        observation_from_step(StepResult(0.1, False, 0.0, 0.0, _truth(False), None), position,
                              rotation)


@pytest.mark.slow
def test_same_seed_gives_identical_steps_and_training() -> None:
    spec = RunSpec(algorithm="qgddpg", critic_lr=1e-2, iterations=3, seed=5, train_episodes=1,
                   test_episodes=1, train_max_steps=4, test_max_steps=1, cycle_steps=2)
    first, second = run_training(spec), run_training(spec)
    assert first["episodes"] == second["episodes"]
    assert [c["mean_q"] for c in first["cycles"]] == [c["mean_q"] for c in second["cycles"]]
    assert len(first["cycles"]) == 2                       # 4 training steps, a cycle every 2
    assert [e["mode"] for e in first["episodes"]] == ["train", "test"]
    assert first["rl_steps"] == sum(e["steps"] for e in first["episodes"])
    other = run_training(dataclasses.replace(spec, seed=6))
    assert [c["mean_q"] for c in other["cycles"]] != [c["mean_q"] for c in first["cycles"]]


def test_a_tilted_housing_test_counts_its_own_steps() -> None:
    """The generalisation test runs on a second robot whose housing is tilted; its steps, time
    and timeouts are part of the run's totals."""
    spec = RunSpec(algorithm="qgddpg", critic_lr=1e-3, iterations=1, seed=0, train_episodes=1,
                   test_episodes=2, train_max_steps=2, test_max_steps=2, cycle_steps=50,
                   test_housing_yaw=1.5707963267948966, test_housing_tilt=0.1745)
    result = run_training(spec)
    assert spec.name.endswith("_yaw1.5708_tilt0.1745_s0")
    assert [e["mode"] for e in result["episodes"]] == ["train", "test", "test"]
    assert result["rl_steps"] == sum(e["steps"] for e in result["episodes"])
    assert result["sim_time"] > 0.0


@pytest.mark.slow
def test_tiny_suite_writes_results_figures_and_report(tmp_path) -> None:
    profile = load_profile("tiny")
    page = run_suite(profile, tmp_path / "runs", tmp_path / "docs", workers=1,
                     command="test").read_text()
    out = tmp_path / "runs" / "tiny"
    for experiment, count in (("random", 2), ("grid", 2), ("variants", 4), ("state_grid", 2),
                              ("peg", 4), ("peg_random", 4), ("nextage", 4)):
        assert len(list((out / experiment).glob("*.json"))) == count, experiment
        archived = tmp_path / "docs" / "data" / "tiny" / "archived_runs" / experiment
        assert len(list(archived.glob("*.json.gz"))) == count, experiment   # run_archive
    head = next((out / "grid").glob("*.json"))
    commit = json.loads(head.read_text())["code"]["commit"]
    assert len(commit) == 40 and f"**Code.** The commits the runs were made at: `{commit[:10]}`" \
        in page
    settings = StackSettings.load()
    for experiment in ("random", "grid", "variants", "state_grid"):   # the robot's runs
        for saved in (out / experiment).glob("*.json"):   # each says which step it measured
            run = json.loads(saved.read_text())
            assert (run["engine"], run["step_limit"]) == (settings.engine, settings.step_limit)
    for section in ("## 1. Random baselines", "## 2. The grid", "## 2b. The grid with the "
                    "thesis's 4-D wrench state", "## 3. Mean predicted Q", "## 4. Where the "
                    "thesis says the graph matters", "## 5. Clearance-fit peg", "## 6. The peg on "
                    "the simulated Nextage", "## 7. QG-DDPG against DDPG, setting by setting",
                    "## 7b. Over all cells", "TOST p (Holm)", "agree and disagree", "Wilcoxon",
                    "| random (uniform) | - | 2 |", "Each learner against the better random"):
        assert section in page
    for figure in ("exp1_random_steps", "exp3_mean_q", "exp5_peg_learning", "exp5_peg_q_std",
                   "exp6_nextage_learning", "exp7_profiles", "exp7_cell_means"):
        assert (tmp_path / "docs" / "figures" / f"{figure}.png").stat().st_size > 1000
    # The peg's sections written again alone are the page's, and the page around them stays.
    from qg_experiments.peg_report import write_section
    assert write_section(profile, tmp_path / "runs", tmp_path / "docs").read_text() == page
    bar = json.loads((tmp_path / "docs" / "data" / "tiny" / "random_bar.json").read_text())
    assert bar["episodes"] == 1 and bar["seeds"] == [0] and bar["low"] <= bar["mean"] <= bar["high"]
    rows = grid.cell_table([json.loads(p.read_text()) for p in (out / "grid").glob("*.json")], 0.5)
    assert {r["algorithm"] for r in rows} == {"ddpg", "qgddpg"}
    assert all(r["mean_test_steps"] == 1.0 and not r["beats_random"] for r in rows)
    spread = peg.q_spread([json.loads(p.read_text()) for p in (out / "peg").glob("*.json")])
    assert all(s.shape == (27 * 11,) and np.all(s > 0) for s in spread.values())
    progress = next((out / "tensorboard" / "grid").glob("*/progress.csv")).read_text()
    for tag in ("rollout/ep_len_mean", "train/critic_loss", "eval/success_rate"):
        assert f",{tag}," in progress, tag
    assert list((out / "tensorboard" / "nextage").glob("*/events.out.tfevents.*"))
    nextage = [json.loads(p.read_text()) for p in (out / "nextage").glob("*.json")]
    assert all(r["rl_steps"] == 2 and r["sim_time"] > 0.02 for r in nextage)
    # A second call finds every run saved and only rewrites the report.
    before = {p: p.stat().st_mtime_ns for p in out.glob("*/*.json")}
    run_suite(profile, tmp_path / "runs", tmp_path / "docs", workers=1, command="test")
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/*.json")} == before
    # A run of another setting left in the folder (say, another observation) stays there but
    # is not reported: without the filter it would add a cell at critic lr 0.25.
    stale = json.loads(next((out / "grid").glob("ddpg_*.json")).read_text())
    stale["spec"]["critic_lr"] = 0.25
    (out / "grid" / "ddpg_stale_setting.json").write_text(json.dumps(stale))
    # The sections made apart from the page (the peers', the Franka's), whose runs are not
    # under this profile's folder, survive the page being written anew.
    results = tmp_path / "docs" / "results.md"
    apart = [f"{peers_report.BEGIN}\n## 8. Peers\n\nSB3 on the shaft\n{peers_report.END}",
             f"{franka_report.BEGIN}\n## 9. The Franka\n\nfranky-sim\n{franka_report.END}"]
    results.write_text(results.read_text() + "\n\n" + "\n\n".join(apart) + "\n")
    page = run_suite(profile, tmp_path / "runs", tmp_path / "docs", workers=1,
                     command="test").read_text()
    assert "| 0.25 |" not in page and "| 0.001 |" in page
    assert all(page.count(block) == 1 for block in apart)
    assert page.index("## 7b. Over all cells") < page.index(apart[0]) < page.index(apart[1])


def test_monte_carlo_check_uses_exact_returns_of_goal_episodes_only() -> None:
    from qg_experiments.runner import MonteCarloCheck
    from qg_learning_node.executor.episode import TransitionRecord

    def step(i, r, terminal=False, timeout=False):
        return TransitionRecord("e", i, np.full(2, float(i)), np.zeros(2), r, np.zeros(2),
                                terminal, timeout, False)

    class Critic:                                     # Q = 0 everywhere
        def q_values(self, states, actions):
            return np.zeros((len(states), 1))

    check = MonteCarloCheck(gamma=0.5)
    assert np.isnan(check.error(Critic()))
    for record in (step(0, -1.0), step(1, -1.0, timeout=True)):    # cut: no exact return
        check.add(record)
    assert check.returns == []
    for record in (step(0, -1.0), step(1, -1.0), step(2, 0.0, terminal=True)):
        check.add(record)
    # returns from the end: 0, -1 + 0.5 * 0, -1 + 0.5 * -1
    assert sorted(check.returns) == [-1.5, -1.0, 0.0]
    assert check.error(Critic()) == pytest.approx((1.5 + 1.0 + 0.0) / 3)


def test_the_config_digest_is_of_values_not_of_comments_or_node_only_settings(tmp_path) -> None:
    import shutil

    from qg_common.params import config_file
    from qg_experiments.runner import STACK_CONFIG_FILES, config_digest
    for name in STACK_CONFIG_FILES:
        shutil.copy(config_file(name), tmp_path / name)
    digest = config_digest(tmp_path)
    assert digest == config_digest()
    learner = (tmp_path / "learner.yaml").read_text()
    (tmp_path / "learner.yaml").write_text(learner + "# a comment\n")
    executor = (tmp_path / "executor.yaml").read_text()
    (tmp_path / "executor.yaml").write_text(executor.replace("step_timeout: 10.0",
                                                             "step_timeout: 12.0"))
    assert config_digest(tmp_path) == digest        # a comment; a node-only timeout
    (tmp_path / "learner.yaml").write_text(learner.replace("batch_size: 64", "batch_size: 32"))
    assert config_digest(tmp_path) != digest


def test_a_runs_seed_is_its_robot_and_the_ideal_arm_has_no_imperfections() -> None:
    from qg_experiments.runner import StackSettings
    realistic = StackSettings.load().with_arm_seed(103)
    imperfections = realistic.robot["panda_scene"]["imperfections"]
    assert imperfections["seed"] == 103 and imperfections["torque_bias"] > 0
    ideal = StackSettings.load(arm="ideal").with_arm_seed(103)
    zeros = ideal.robot["panda_scene"]["imperfections"]
    assert zeros["seed"] == 103
    assert all(not any(v) if isinstance(v, list) else v == 0.0
               for k, v in zeros.items() if k != "seed")
    with pytest.raises(ValueError, match="arm must be one of"):
        StackSettings.load(arm="perfect")
