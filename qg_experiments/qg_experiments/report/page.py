"""The page ``docs/results.md``: its header, the budget, and its sections in order, with the
CSVs and figures beside it, all from the saved runs (see the package docstring)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from qg_experiments import grid
from qg_experiments.core import StackSettings
from qg_experiments.peg import random_experiment
from qg_experiments.profile import Profile
from qg_experiments.random_baselines import random_bar_of, summarize_baselines
from qg_experiments.report.aggregate_section import aggregate_section
from qg_experiments.report.comparison import comparison, graph_section
from qg_experiments.report.grid_sections import (
    grid_section,
    learning_curves_section,
    q_section,
    random_section,
    variant_section,
)
from qg_experiments.report.markdown import (
    APART_BLOCKS,
    code_label,
    marked_blocks,
    step_label,
    table,
)
from qg_experiments.report.peg_sections import (
    peg_against_random,
    peg_budget,
    peg_paired,
    peg_section,
)
from qg_experiments.report.tables import episodes_csv, write_bar, write_csv
from qg_experiments.tasks import load_results
from qg_experiments.tensorboard_log import export_runs

__all__ = ["write_report"]


def _state_note(observation: str) -> str:
    """What a state other than the thesis's changes: the MDP's state, not its actions or rewards,
    and so not the random bar (a random policy reads no state)."""
    if observation == "thesis":
        return ""
    return (f"The `{observation}` state changes the thesis's MDP in its state only (actions and "
            "rewards are the thesis's); a random policy reads no state, so the random bar is the "
            "same process in either MDP. ")


def write_report(profile: Profile, out: Path, docs: Path, config_dir: str | None = None,
                 planned: dict[str, int] | None = None,
                 current: dict[str, set[str]] | None = None) -> Path:
    """Write the CSVs, the figures and ``docs/results.md`` for the runs saved under ``out``.

    :param planned: runs per experiment of the complete profile, to show what is unfinished.
    :param current: per experiment, the names of the runs to report (``suite.current_runs``);
        ``None`` reports every saved run.
    """
    out, docs = Path(out), Path(docs)
    figures = docs / "figures"
    figures.mkdir(parents=True, exist_ok=True)

    def saved(experiment: str) -> list[dict[str, Any]]:
        return load_results(out, experiment, None if current is None else
                            current.get(experiment, set()))

    results_by = {name: saved(name) for name in
                  ("random", "grid", "variants", "state_grid", "peg", "nextage",
                   random_experiment("peg"), random_experiment("nextage"))}
    random_results, grid_results = results_by["random"], results_by["grid"]
    variant_results, state_results = results_by["variants"], results_by["state_grid"]
    random_rows = summarize_baselines(random_results) if random_results else []
    test_cap = (grid_results[0]["spec"]["test_max_steps"] if grid_results
                else profile.grid.test_max_steps)
    bar = random_bar_of(random_rows, test_cap)
    bar_mean = None if bar is None else bar.mean
    grid_rows = grid.cell_table(grid_results, bar_mean)
    state_rows = grid.cell_table(state_results, bar_mean)
    # The tables' data beside the page (small, versioned); the per-run JSON stays under ``out``.
    data = docs / "data" / profile.name
    data.mkdir(parents=True, exist_ok=True)
    write_csv(data / "random_summary.csv", random_rows)
    if bar is not None:
        write_bar(data / "random_bar.json", bar,
                  sorted({r["spec"]["seed"] for r in random_results}))
    write_csv(data / "grid_summary.csv", grid_rows)
    write_csv(data / "state_grid_summary.csv", state_rows)
    write_csv(data / "variants_summary.csv", grid.cell_table(variant_results, bar_mean))
    for name, results in results_by.items():      # none without runs (``write_csv``)
        episodes_csv(data / f"{name}_episodes.csv", results)
    tensorboard = export_runs((*grid_results, *variant_results, *state_results,
                               *results_by["peg"], *results_by["nextage"]), out / "tensorboard")
    settings = StackSettings.load(config_dir)
    gamma = settings.learner.ddpg.gamma
    q_range = (settings.learner.ddpg.r_min / (1 - gamma), settings.learner.ddpg.r_max)
    digests = sorted({r.get("config_digest", "?") for results in results_by.values()
                      for r in results})
    timing_path = out / "timing.json"
    timing = json.loads(timing_path.read_text()) if timing_path.exists() else {}
    robot_runs = [r for name, results in results_by.items()
                  if name not in ("peg", random_experiment("peg")) for r in results]
    estimator = {"ekf": "the EKF wrench estimator (as in the ROS stack)",
                 "ground_truth": "the simulator's true contact wrench (perfect sensor)"}
    lines = ["# Results: the thesis's experiments in simulation", "",
             "Generated by `qg_experiments.report` from the saved runs; do not edit "
             "by hand. Regenerate with", "", "```",
             f"scripts/experiments.sh --profile {profile.name}",
             f"scripts/experiments.sh --profile {profile.name} --report-only", "```", "",
             f"Profile **{profile.name}** of `config/experiments.yaml`; every run used the "
             f"fast in-process runner (the ROS stack's cores and config files, no DDS) with "
             f"{estimator[profile.estimator]}, on the **{profile.arm}** simulated Panda "
             f"(`panda_scene.imperfections`; each seed is its own robot: its biases, housing "
             f"error and noise). Stack config files: "
             f"`{config_dir or 'config/'}`, digest(s) {', '.join(f'`{d}`' for d in digests)} "
             f"(`runner.config_digest`). Every episode and every table row as CSV: "
             f"[`data/{profile.name}/`](data/{profile.name}/); per-run JSON: `{out}`; "
             f"TensorBoard scalars of every learning run (Stable-Baselines3's tag names): "
             f"`tensorboard --logdir {tensorboard}`.", "",
             f"**Physics and step.** The robot runs' engine and RL step: "
             f"{step_label(robot_runs) or 'none run'} (each section's speed line names its "
             f"own; a step ends at rest or at its limit).", "",
             f"**Code.** The commits the runs were made at: "
             f"{code_label([r for rs in results_by.values() for r in rs]) or 'none run'} (a "
             f"saved run is reused while its spec and config numbers match, whatever the code; "
             f"`code_version`).", "",
             f"**Seeds.** Every table below is computed on the report seeds "
             f"{', '.join(map(str, profile.seeds.report))}; every choice of the setup (the state, "
             f"the discount, the variants' cells) was made on the tuning seeds "
             f"{', '.join(map(str, profile.seeds.tuning))} and on further seeds that are none "
             f"of the report's ([learning.md](learning.md) names each study's seeds). "
             "**Statistics** (`qg_experiments/stats.py`): 95 % BCa bootstrap intervals (SciPy, "
             "10,000 resamples) over the per-seed means of a cell, over episodes for the random "
             "baselines; a cell beats random only when its whole interval lies below the random "
             "bar; QG-DDPG against DDPG is a paired comparison over the same (cell, seed) runs "
             "with the Wilcoxon signed-rank test and the sign test; over all cells of a setting, "
             "the interquartile mean, the probability of improvement and performance profiles "
             "with stratified-bootstrap intervals (Agarwal et al. 2021), and a verdict per "
             "setting with Holm's correction and an equivalence test (section 7b).", "",
             "| step | command | wall time | finished |", "|---|---|---|---|"]
    lines += [f"| {k} | `{v['command']}` | {v['wall_time'] / 60:.1f} min | {v['finished']} |"
              for k, v in timing.items()]
    lines += ["", "Budget of this profile against the thesis:", ""]
    pg, pr, pp, pv = profile.grid, profile.random, profile.peg, profile.variants
    budget = {
        "random": ("random baselines", "several noises, 1000-step cap, up to 3000 steps each",
                   f"{len(pr.noises)} settings x {len(pr.seeds)} seeds x {pr.episodes} episodes, "
                   f"cap {pr.max_steps}"),
        "grid": ("grid", "8 cells x 2 algorithms x 3 seeds, 40 train + 8 test episodes (cap 200)",
                 f"{len(pg.cells)} cells x {len(pg.algorithms)} algorithms x {len(pg.seeds)} "
                 f"seed(s), {pg.train_episodes} train (cap {pg.train_max_steps}) + "
                 f"{pg.test_episodes} test episodes (cap {pg.test_max_steps})"),
        "variants": ("variants", "sparse reward; replay 300 (each algorithm's best cell)",
                     ", ".join(n for n, _ in pv.overrides()) + f" at {len(pv.cells)} cell(s) x "
                     f"{len(pv.seeds)} seeds" if pv.settings else "none"),
        "peg": ("peg", "300 episodes x 10 seeds, 3 lrs, 750 updates/episode",
                peg_budget(pp))}
    if profile.state_grid is not None:
        budget["state_grid"] = ("grid, thesis's 4-D state", "the grid above (the thesis's state)",
                                f"the grid with `observation: {profile.state_grid.observation}`")
    if profile.nextage is not None:
        budget["nextage"] = ("Nextage peg", "(the real Nextage: ch. 8.3)",
                             peg_budget(profile.nextage))
    planned = planned or {}
    lines += table(["experiment", "thesis", f"profile {profile.name}", "runs finished"],
                   [[*row, f"{len(results_by[k])} of {planned.get(k, '?')}"]
                    for k, row in budget.items()])
    earlier = sorted(path.name for path in docs.glob("results_*.md"))
    if earlier:      # pages of another setup, kept for the experiments not run again since
        lines += ["", "Earlier pages, kept as they were generated under another setup (each says "
                  "which): " + ", ".join(f"[{name}]({name})" for name in earlier) + "."]
    noise = settings.noise
    lines += ["", "How the runs were made: each run builds the simulated Panda, the bridge's 1 kHz "
              "loop and the wrench estimator (`RobotLoop`), and drives it with the executor's "
              "`Episode`/`ResidualTask` and the learner's `LearnerCore`, exactly as the ROS nodes "
              "do, but synchronously (training happens at the end of each cycle, then the "
              "executor's actor is replaced). Start poses rotate 0..7. Vanilla DDPG: no bounds "
              "and no zero-action loops (as in the thesis); QG-DDPG: Q-Graph plus a-priori "
              f"bounds, zero action (0, 0) whose self-loops go into graph and replay. Exploration "
              f"in training: {noise.kind} noise, sigma {noise.sigma:g} (actor units), on "
              f"{1 - noise.clean_fraction:.0%} of the training steps; the others send the "
              f"actor's own action without noise (`noise.clean_fraction` "
              f"{noise.clean_fraction:g}; the thesis: every step noisy; [learning.md](learning.md) "
              "section 17). The random baselines add noise on every step. State: "
              f"the `{pg.observation or settings.task.observation}` observation "
              f"(`residual_task.OBSERVATIONS`), discount {gamma:g}, both chosen on the tuning "
              "seeds ([learning.md](learning.md)); the thesis's 4-D state in section 2b. "
              f"{_state_note(pg.observation or settings.task.observation)}Runs are "
              "deterministic per seed (tested in `tests/experiments/test_runner.py`).", ""]
    lines += random_section(random_rows, random_results, test_cap, bar, figures)
    lines += grid_section("## 2. The grid: mean test steps per cell", grid_rows, grid_results,
                          bar)
    lines += learning_curves_section(grid_results, grid_rows, figures, bar)
    if profile.state_grid is not None or state_results:
        lines += grid_section("## 2b. The grid with the thesis's 4-D wrench state", state_rows,
                              state_results, bar)
    lines += q_section(grid_results, grid_rows, figures, q_range, gamma)
    lines += variant_section(variant_results, bar, gamma)
    peg_data = []
    for experiment in ("peg", "nextage"):
        results = results_by[experiment]
        if experiment == "nextage" and profile.nextage is None and not results:
            continue
        randoms = results_by[random_experiment(experiment)]
        section, data = peg_section(results, figures, experiment, randoms)
        lines += section
        if data:
            budget = profile.peg if experiment == "peg" else profile.nextage
            data["planned_lrs"] = budget.lrs if budget is not None else ()
            lines += [*peg_paired(data["pairs"], data["tail"]), ""]
            against = peg_against_random(results, randoms, data["tail"])
            lines += [*against, ""] if against else []
        peg_data.append(data)
    grids = {f"grid (`{pg.observation or settings.task.observation}`, the default)": grid_results,
             "grid with the thesis's 4-D state": state_results}
    settings_runs = {**grids, **grid.by_variant(variant_results, gamma)}
    lines += graph_section(settings_runs, bar, gamma)
    lines += aggregate_section(settings_runs, bar, profile.statistics, figures)
    lines += comparison(random_rows, bar, grids, variant_results, peg_data, gamma)
    path = docs / "results.md"
    # The peers' runs come from their own benchmarks, the Franka's are whole qgl runs (realtime,
    # franky-sim): their sections follow ours, kept from the old page unless their runs are here.
    kept = marked_blocks(path.read_text() if path.exists() else "", APART_BLOCKS)
    path.write_text("\n".join(lines) + (f"\n\n{kept}\n" if kept else ""))
    if (out / "peers").is_dir() or (out / "standard_tasks").is_dir():
        from qg_experiments import peers_report  # imports the Gym side and its messages
        peers_report.write_section(path, out)
    from qg_experiments import franka_report
    franka_report.write_section(path, docs / "data" / franka_report.DATA.name)
    return path
