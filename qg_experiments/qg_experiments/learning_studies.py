"""The studies behind docs/learning.md, beside the thesis grid: which lever makes the robot learn.

``python -m qg_experiments.learning_studies`` runs (resumably, on every core) and
summarises, all with the thesis protocol of the ``thesis`` profile (40 training episodes capped at
50 steps, 8 test episodes capped at 200, 3 seeds):

* ``observation``: the thesis's 4-D wrench state at the same cell as the tilt state's runs;
* ``graph``: the critic's error against the Monte-Carlo return of the goal-reaching episodes
  (``runner.MonteCarloCheck``) for DDPG, QG-DDPG on the exact graph and QG-DDPG on a merged
  graph (``graph_resolution``), and how many TD targets each graph bound changes;
* ``housing``: trained at housing yaw 0, tested with the housing turned 90 degrees, and turned
  90 degrees and tilted by 10 degrees (the tilt state then measures against the tilted bore);
* ``schedule``: simulated robot time until a test on all 8 poses (every 4 training episodes,
  50-step cap) first succeeds everywhere: the thesis's train-every-20-steps schedule against
  the ``async`` learner (10 updates per step; in process its deterministic stand-in);
* ``cap``: the thesis's training cap of 1000 steps (the grid's deviation is 50) at the cell the
  grid leaves update-starved, lr 1e-4 with 10 iterations: do longer training episodes, and so
  more updates, let the test actor beat random there?
* ``echo``: the tilt state with and without the wrench components that echo the last action
  (``tilt``, ``tilt_force``, ``tilt_only``), QG-DDPG at lr 1e-3 with 10 iterations, the cell
  whose deterministic test actor stalled with the 6-D tilt state.

The first five studies run with the 6-D ``tilt`` state (``STUDY_OBSERVATION``), the state they
were measured with, whatever the profile's grid now uses.

Results go to ``<out>/<study>/``; ``docs/data/learning_studies.json`` and two figures to
``docs``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from qg_experiments.figures import pyplot
from qg_experiments.grid import grid_specs, test_steps
from qg_experiments.profile import load_profile
from qg_experiments.runner import RunSpec
from qg_experiments.tasks import DEFAULT_WORKERS, run_specs

__all__ = ["study_specs", "summarise", "main"]

#: The cell the studies compare at (the thesis grid's lr 1e-4 with 50 iterations per cycle).
CELL = (1e-4, 50)
#: The ``cap`` study's cell: the thesis grid's cell that gets too few updates at a cap of 50.
STARVED_CELL = (1e-4, 10)
#: [steps] The thesis's training-episode cap (SPEC 2), which the grid cuts to 50.
THESIS_TRAIN_CAP = 1000
#: Merging grid of the ``graph`` study, in scaled state units.
RESOLUTION = 0.1
#: [rad] Fixture tilt of the housing in the second generalisation test.
HOUSING_TILT = math.radians(10.0)
#: The state of the observation, graph, housing, schedule and cap studies.
STUDY_OBSERVATION = "tilt"
#: The ``echo`` study's cell, and the states it compares.
ECHO_CELL = (1e-3, 10)
ECHO_OBSERVATIONS = ("tilt", "tilt_force", "tilt_only")


#: The studies' arm: they were measured on the ideal arm, before the realistic one existed.
STUDY_ARM = "ideal"


def study_specs(profile_name: str = "thesis") -> dict[str, list[RunSpec]]:
    """The runs of every study, built on the grid of ``profile_name`` with three of the tuning
    seeds (studies are where choices are made, never on the report seeds)."""
    profile = load_profile(profile_name)
    grid = dataclasses.replace(profile.grid, observation=STUDY_OBSERVATION,
                               seeds=profile.seeds.tuning[:3])

    def runs(cell: tuple[float, int], algorithms: tuple[str, ...] = grid.algorithms,
             **changes: Any) -> list[RunSpec]:
        """The grid's runs of one cell, for ``algorithms``, with ``changes`` to the grid."""
        return grid_specs(dataclasses.replace(grid, cells=(cell,), algorithms=algorithms,
                                              **changes), arm=STUDY_ARM)

    qgddpg = ("qgddpg",)
    both_at_cell, qgddpg_at_cell = runs(CELL), runs(CELL, qgddpg)
    observation = [dataclasses.replace(s, observation="thesis", experiment="observation")
                   for s in both_at_cell]
    graph = [dataclasses.replace(s, experiment="graph") for s in both_at_cell]
    graph += [dataclasses.replace(s, experiment="graph", graph_resolution=RESOLUTION)
              for s in qgddpg_at_cell]
    housing = [dataclasses.replace(s, experiment="housing", test_housing_yaw=math.pi / 2,
                                   test_housing_tilt=tilt)
               for tilt in (0.0, HOUSING_TILT) for s in qgddpg_at_cell]
    schedule = [dataclasses.replace(s, experiment="schedule", eval_every=4, **extra)
                for extra in ({}, {"schedule": "async", "updates_per_step": 10.0,
                                   "publish_every": 20})
                for s in runs(CELL, qgddpg, test_max_steps=50)]
    cap = [dataclasses.replace(s, experiment="cap", train_max_steps=THESIS_TRAIN_CAP)
           for s in runs(STARVED_CELL, qgddpg)]
    echo = [dataclasses.replace(s, experiment="echo", observation=state)
            for state in ECHO_OBSERVATIONS for s in runs(ECHO_CELL, qgddpg)]
    return {"observation": observation, "graph": graph, "housing": housing,
            "schedule": schedule, "cap": cap, "echo": echo}


def _label(spec: dict[str, Any]) -> str:
    label = f"{spec['algorithm']} lr {spec['critic_lr']:g} / {spec['iterations']} it"
    if spec.get("observation"):
        label += f", {spec['observation']} state"
    if spec.get("graph_resolution"):
        label += f", merged graph ({spec['graph_resolution']:g})"
    if spec.get("schedule") == "async":
        label += f", async learner ({spec['updates_per_step']:g} updates/step)"
    elif spec.get("eval_every"):
        label += ", thesis schedule (2.5 updates/step)"
    if spec.get("experiment") == "cap":
        label += f", training cap {spec['train_max_steps']}"
    if spec.get("test_housing_yaw"):
        label += f", tested at housing yaw {math.degrees(spec['test_housing_yaw']):.0f} deg"
    if spec.get("test_housing_tilt"):
        label += f" and tilt {math.degrees(spec['test_housing_tilt']):.0f} deg"
    return label


def summarise(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per label (seeds pooled): test success, test steps, MC error, bound effect."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault(_label(r["spec"]), []).append(r)
    rows = []
    for label, group in groups.items():
        steps = np.array([n for r in group for n in test_steps(r)], dtype=float)
        success = [e["success"] for r in group for e in r["episodes"] if e["mode"] == "test"]
        cycles = [c for r in group for c in r["cycles"]]
        mc = [c["critic_mc_error"] for c in cycles if not math.isnan(c.get("critic_mc_error",
                                                                             math.nan))]
        rows.append({"label": label, "seeds": len(group),
                     "test_success": float(np.mean(success)), "mean_test_steps": float(steps.mean()),
                     "median_test_steps": float(np.median(steps)),
                     "per_seed_mean_test_steps": [float(np.mean(test_steps(r))) for r in group],
                     "critic_mc_error_last": float(np.mean([
                         [c["critic_mc_error"] for c in r["cycles"]][-1] for r in group]))
                     if mc else None,
                     "frac_targets_raised": float(np.mean([c.get("frac_raised_lower", 0.0)
                                                           for c in cycles])) if cycles else None,
                     "rl_steps": int(sum(r["rl_steps"] for r in group)),
                     "robot_minutes_to_solve": [_solved_at(r) for r in group]})
    return rows


def _solved_at(result: dict[str, Any]) -> float | None:
    """Simulated robot minutes (training and tests) until every test pose succeeded, if ever."""
    for evaluation in result.get("evaluations", []):
        if evaluation["successes"] == result["spec"]["test_episodes"]:
            return evaluation["sim_time"] / 60.0
    return None


def _mc_figure(results: list[dict[str, Any]], path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault(_label(r["spec"]), []).append(r)
    for label, group in sorted(groups.items()):
        n = min(len(r["cycles"]) for r in group)
        for ax, key in zip(axes, ("critic_mc_error", "frac_raised_lower")):
            curves = np.array([[c.get(key, np.nan) for c in r["cycles"][:n]] for r in group])
            ax.plot(np.arange(1, n + 1), np.nanmean(curves, axis=0), label=label)
    axes[0].set_ylabel("mean |Q(s,a) - MC return|")
    axes[1].set_ylabel("share of TD targets raised by a bound")
    for ax in axes:
        ax.set_xlabel("training cycle (20 steps)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m qg_experiments."
                                     "learning_studies", description=__doc__)
    parser.add_argument("--only", default="observation,graph,housing,schedule,cap,echo")
    parser.add_argument("--out", type=Path, default=Path("runs/experiments/studies"))
    parser.add_argument("--docs", type=Path, default=Path("docs"))
    parser.add_argument("--workers", type=int, default=DEFAULT_WORKERS)
    args = parser.parse_args(argv)
    studies = study_specs()
    summary: dict[str, Any] = {}
    for name in args.only.split(","):
        results = run_specs(studies[name], args.out, args.workers, f"study {name}")
        summary[name] = summarise(results)
        if name == "graph":
            (args.docs / "figures").mkdir(parents=True, exist_ok=True)
            _mc_figure(results, args.docs / "figures" / "learning_critic_vs_mc.png")
    (args.docs / "data").mkdir(parents=True, exist_ok=True)
    path = args.docs / "data" / "learning_studies.json"
    old = json.loads(path.read_text()) if path.exists() else {}
    path.write_text(json.dumps({**old, **summary}, indent=1))
    for name, rows in summary.items():
        for row in rows:
            print(f"{name:12s} {row['label']:60s} success {row['test_success']:.2f} "
                  f"mean steps {row['mean_test_steps']:.1f} MC err {row['critic_mc_error_last']} "
                  f"raised {row['frac_targets_raised']}")


if __name__ == "__main__":
    main()
