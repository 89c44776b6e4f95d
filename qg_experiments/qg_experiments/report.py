"""``docs/results.md`` with its tables and plots, generated from the saved runs only.

Everything in the page is computed from ``<out>/<profile>/<experiment>/*.json`` and
``timing.json``, so the numbers always belong to an actual run and the page can be regenerated
(``--report-only``) without running anything. Summary CSVs go next to the results; PNG plots go to
``docs/figures/exp*_*.png``.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from qg_experiments import grid, peg  # noqa: E402
from qg_experiments.profile import PegBudget, Profile  # noqa: E402
from qg_experiments.random_baselines import (random_bar,  # noqa: E402
                                             summarize_baselines)
from qg_experiments.runner import StackSettings  # noqa: E402
from qg_experiments.tasks import load_results  # noqa: E402
from qg_experiments.tensorboard_log import export_runs  # noqa: E402

__all__ = ["write_report", "THESIS"]

#: The thesis's real-robot and peg numbers the page compares against (SPEC 2, thesis ch. 8-9).
THESIS = {"random_steps": 32, "qg_cells": 6, "ddpg_cells": 1, "cells": 8}

_COLORS = {"ddpg": "tab:orange", "qgddpg": "tab:blue"}
_NAMES = {"ddpg": "DDPG", "qgddpg": "QG-DDPG"}


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    if not rows:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = [k for k in rows[0] if not isinstance(rows[0][k], (list, np.ndarray))]
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def _episodes_csv(path: Path, results: list[dict[str, Any]]) -> None:
    _write_csv(path, [{"run": r["name"], **e} for r in results for e in r["episodes"]])


def _fmt(x: float, digits: int = 1) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + \
        ["| " + " | ".join(r) + " |" for r in rows]


def _speed(results: list[dict[str, Any]]) -> str:
    steps = sum(r.get("rl_steps", 0) for r in results)
    wall = sum(r["wall_time"] for r in results)
    sim = sum(r.get("sim_time", 0.0) for r in results)
    timeouts = sum(r.get("step_timeouts", 0) for r in results)
    text = f"{steps} RL steps in {wall / 60:.1f} worker-minutes ({steps / wall:.2f} steps/s)"
    if sim:
        text += (f", {sim / max(steps, 1) * 1e3:.0f} ms simulated per step, "
                 f"{timeouts / max(steps, 1):.0%} of steps ended by the step timeout, not at rest")
    return text


# --- experiment 1 ------------------------------------------------------------------------------
def _random_section(rows: list[dict[str, Any]], results: list[dict[str, Any]],
                    figures: Path) -> list[str]:
    if not rows:
        return ["## 1. Random baselines", "", "Not run in this profile.", ""]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.boxplot([r["steps"] for r in rows], showmeans=True)
    ax.set_xticks(range(1, len(rows) + 1), [r["label"] for r in rows], rotation=15)
    ax.axhline(THESIS["random_steps"], color="gray", ls="--", lw=1, label="thesis: 32 (real robot)")
    ax.set_ylabel("steps per episode")
    ax.set_title("Random residuals: steps to insertion (failures at the cap)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(figures / "exp1_random_steps.png", dpi=110)
    plt.close(fig)
    lines = ["## 1. Random baselines", "",
             f"Base push plus a random residual; OU with theta and dt from `executor.yaml`. "
             f"{rows[0]['episodes']} episodes per setting (poses 0..7 in turn), cap "
             f"{rows[0]['max_steps']} steps; a failed episode counts as the cap. "
             f"Speed: {_speed(results)}.", ""]
    lines += _table(["residual", "episodes", "success", "mean steps", "median", "std",
                     "steps per episode"],
                    [[r["label"], str(r["episodes"]), f"{r['success_rate']:.0%}",
                      _fmt(r["mean_steps"]), _fmt(r["median_steps"]), _fmt(r["std_steps"]),
                      " ".join(map(str, r["steps"]))] for r in rows])
    lines += ["", "![random baselines](figures/exp1_random_steps.png)", ""]
    return lines


# --- experiments 2-4 ---------------------------------------------------------------------------
def _grid_section(rows: list[dict[str, Any]], results: list[dict[str, Any]], bar: float | None,
                  bar_label: str) -> list[str]:
    if not rows:
        return ["## 2. The grid", "", "Not run in this profile.", ""]
    spec = results[0]["spec"]
    cells = sorted({(r["critic_lr"], r["iterations"]) for r in rows})
    by_key = {(r["algorithm"], r["critic_lr"], r["iterations"]): r for r in rows}
    algorithms = sorted({r["algorithm"] for r in rows})
    table = []
    for lr, iterations in cells:
        line = [f"{lr:g}", f"{lr / 10:g}", str(iterations)]
        for a in algorithms:
            r = by_key.get((a, lr, iterations))
            line.append("—" if r is None else
                        f"{'**' if r['beats_random'] else ''}{_fmt(r['mean_test_steps'])}"
                        f"{'**' if r['beats_random'] else ''} ({r['test_success_rate']:.0%}, "
                        f"{r['seeds']} seed{'s' if r['seeds'] > 1 else ''})")
        table.append(line)
    wins = {a: sum(r["beats_random"] for r in rows if r["algorithm"] == a) for a in algorithms}
    counts = {a: sum(1 for r in rows if r["algorithm"] == a) for a in algorithms}
    lines = ["## 2. The grid: mean test steps per cell", "",
             f"{spec['train_episodes']} training episodes (cap {spec['train_max_steps']} steps, "
             f"training after every {spec['cycle_steps'] or 20} steps), then "
             f"{spec['test_episodes']} test episodes without noise (cap {spec['test_max_steps']}). "
             "Cell: mean test steps over episodes and seeds (failures count as the cap), test "
             f"success rate in brackets; **bold** = fewer steps than the best random baseline "
             f"({bar_label}). Speed: {_speed(results)}.", ""]
    lines += _table(["critic lr", "actor lr", "iterations/cycle",
                     *[_NAMES[a] for a in algorithms]], table)
    lines += ["", "Cells beating random: " + ", ".join(
        f"{_NAMES[a]} {wins[a]} of {counts[a]}" for a in algorithms) + ".", ""]
    return lines


def _q_runs(results: list[dict[str, Any]], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Best and worst cell of each algorithm (by mean test steps) -> their runs."""
    chosen: dict[str, Any] = {}
    for a in sorted({r["algorithm"] for r in rows}):
        mine = sorted((r for r in rows if r["algorithm"] == a and r["reward"] == "dense"
                       and r["replay_capacity"] is None), key=lambda r: r["mean_test_steps"])
        for tag, row in (("best", mine[0]), ("worst", mine[-1])):
            runs = [x for x in results if x["spec"]["algorithm"] == a
                    and x["spec"]["critic_lr"] == row["critic_lr"]
                    and x["spec"]["iterations"] == row["iterations"]]
            chosen[f"{_NAMES[a]} {tag} (lr {row['critic_lr']:g}, {row['iterations']} it)"] = \
                (a, tag, runs)
    return chosen


def _learning_curves(results: list[dict[str, Any]], rows: list[dict[str, Any]],
                     figures: Path, bar: float | None) -> list[str]:
    """Steps per episode (training, then test) of the best and worst cell of each algorithm:
    the mean over seeds with the standard deviation of that mean shaded, as in the thesis."""
    if not rows:
        return []
    chosen = _q_runs(results, rows)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for ax, tag in zip(axes, ("best", "worst")):
        for label, (a, run_tag, runs) in chosen.items():
            if run_tag != tag or not runs:
                continue
            steps = np.array([[e["steps"] for e in r["episodes"]] for r in runs], dtype=float)
            mean = steps.mean(axis=0)
            sem = steps.std(axis=0) / math.sqrt(len(runs))
            x = np.arange(1, steps.shape[1] + 1)
            ax.plot(x, mean, color=_COLORS[a], label=f"{label}, {len(runs)} seeds")
            ax.fill_between(x, mean - sem, mean + sem, color=_COLORS[a], alpha=0.2)
        n_train = results[0]["spec"]["train_episodes"]
        ax.axvline(n_train + 0.5, color="k", lw=1)
        ax.text(n_train + 0.7, 0.97, "test", transform=ax.get_xaxis_transform(), fontsize=8,
                va="top")
        if bar is not None:
            ax.axhline(bar, color="gray", ls="--", lw=1, label="best random (cut at test cap)")
        ax.set_xlabel("episode (training, then test)")
        ax.set_title(f"{tag} cell of each algorithm")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("steps per episode (failures at the cap)")
    fig.tight_layout()
    fig.savefig(figures / "exp2_learning_curves.png", dpi=110)
    plt.close(fig)
    return ["Learning curves of the best and worst cell of each algorithm (mean over seeds, "
            "shaded: standard deviation of the mean):", "",
            "![learning curves](figures/exp2_learning_curves.png)", ""]


def _q_section(results: list[dict[str, Any]], rows: list[dict[str, Any]], figures: Path,
               q_range: tuple[float, float]) -> list[str]:
    if not rows:
        return []
    chosen = _q_runs(results, rows)
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, (a, tag, runs) in chosen.items():
        for i, run in enumerate(runs):
            q = [c["mean_q"] for c in run["cycles"]]
            ax.plot(range(1, len(q) + 1), q, color=_COLORS[a], ls="-" if tag == "best" else ":",
                    label=label if i == 0 else None)
    ax.axhline(q_range[0], color="gray", lw=1, ls="--")
    ax.axhline(q_range[1], color="gray", lw=1, ls="--")
    ax.set_xlabel("training cycle")
    ax.set_ylabel("mean predicted Q of the cycle's minibatches")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_title(f"Mean Q; dashed: realisable range [{q_range[0]:g}, {q_range[1]:g}]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(figures / "exp3_mean_q.png", dpi=110)
    plt.close(fig)
    table = []
    for r in results:
        q = np.array([c["mean_q"] for c in r["cycles"]]) if r["cycles"] else np.array([np.nan])
        outside = int(np.sum((q < q_range[0]) | (q > q_range[1])))
        table.append([_NAMES[r["spec"]["algorithm"]], f"{r['spec']['critic_lr']:g}",
                      str(r["spec"]["iterations"]), str(r["spec"]["seed"]), str(len(r["cycles"])),
                      _fmt(float(np.nanmin(q)), 2), _fmt(float(np.nanmax(q)), 2),
                      _fmt(float(q[-1]), 2), str(outside)])
    lines = ["## 3. Mean predicted Q during training", "",
             "Mean of the critic's predictions on each cycle's minibatches (averaged over the "
             "cycle's iterations), best and worst cell of each algorithm by mean test steps. "
             f"The realisable range of the dense and sparse rewards is [{q_range[0]:g}, "
             f"{q_range[1]:g}].", "", "![mean Q](figures/exp3_mean_q.png)", ""]
    lines += _table(["algorithm", "critic lr", "it", "seed", "cycles", "min mean Q",
                     "max mean Q", "last", "cycles outside range"], table)
    return lines + [""]


def _variant_section(rows: list[dict[str, Any]], bar: float | None) -> list[str]:
    lines = ["## 4. Sparse reward and a 300-transition replay memory", ""]
    if not rows:
        return lines + ["Not run in this profile (see the budget table).", ""]
    lines += ["Each algorithm at its best grid cell; same episode budget as the grid.", ""]
    lines += _table(["algorithm", "critic lr", "it", "reward", "replay", "mean test steps",
                     "test success", "beats random"],
                    [[_NAMES[r["algorithm"]], f"{r['critic_lr']:g}", str(r["iterations"]),
                      r["reward"], str(r["replay_capacity"] or "unbounded"),
                      _fmt(r["mean_test_steps"]), f"{r['test_success_rate']:.0%}",
                      "yes" if r["beats_random"] else "no"] for r in rows])
    return lines + [""]


def _smooth(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing moving average (``window`` = 1 leaves the values as they are)."""
    return np.convolve(values, np.ones(window) / window, mode="valid")


# --- experiment 5 ------------------------------------------------------------------------------
#: Per peg experiment: section heading, figure-name prefix, what moved the peg.
_PEG_PAGES = {
    "peg": ("## 5. Clearance-fit peg (free peg)", "exp5_peg",
            "Free peg (a drive constraint moves it; no arm)"),
    "nextage": ("## 6. The peg on the simulated Nextage, through the stack's cores", "exp6_nextage",
                "The Nextage arm (`robot:=sim_nextage`) through the stack's cores in one process "
                "(`experiments/nextage_peg.py`): the robot plugin, the bridge's 1 kHz position "
                "loop with its task-space IK and rest detector, and the executor's `PegTask`, "
                "read from the ROS nodes' config files; the same start positions as the free peg"),
}


def _peg_section(results: list[dict[str, Any]], figures: Path,
                 experiment: str = "peg") -> tuple[list[str], dict]:
    heading, prefix, robot = _PEG_PAGES[experiment]
    lines = [heading, ""]
    if not results:
        return lines + ["Not run in this profile.", ""], {}
    curves = peg.learning_curves(results)
    spread = peg.q_spread(results)
    spec = results[0]["spec"]
    lrs = sorted({k[1] for k in curves}, reverse=True)
    window = 5 if spec["episodes"] >= 20 else 1
    fig, axes = plt.subplots(1, len(lrs), figsize=(4 * len(lrs), 3.4), sharey=True, squeeze=False)
    for ax, lr in zip(axes[0], lrs):
        for (a, l), c in curves.items():
            if l != lr:
                continue
            mean, sem = _smooth(c["return_mean"], window), _smooth(c["return_sem"], window)
            x = np.arange(len(mean)) + window
            ax.plot(x, mean, color=_COLORS[a], label=f"{_NAMES[a]}, {c['seeds']} seeds")
            ax.fill_between(x, mean - sem, mean + sem, color=_COLORS[a], alpha=0.2)
        ax.set_title(f"lr {lr:g}")
        ax.set_xlabel("episode")
    axes[0][0].set_ylabel("episode return (mean ± s.e.)" + (
        f"\nmoving average of {window}" if window > 1 else ""))
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(figures / f"{prefix}_learning.png", dpi=110)
    plt.close(fig)
    if spread:
        keys = sorted(spread, key=lambda k: (-k[1], k[0]))
        fig, ax = plt.subplots(figsize=(7, 3.5))
        ax.boxplot([spread[k] for k in keys])
        ax.set_xticks(range(1, len(keys) + 1), [f"{_NAMES[a]}\nlr {lr:g}" for a, lr in keys],
                      fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("std of Q across seeds")
        ax.set_title("Spread of predicted Q on 27 states x 11 actions")
        fig.tight_layout()
        fig.savefig(figures / f"{prefix}_q_std.png", dpi=110)
        plt.close(fig)
    tail = max(1, spec["episodes"] // 5)
    table = []
    for (a, lr), c in curves.items():
        s = spread.get((a, lr))
        table.append([_NAMES[a], f"{lr:g}", str(c["seeds"]),
                      _fmt(float(np.mean(c["return_mean"][-tail:])), 1),
                      f"{float(np.mean(c['success_mean'][-tail:])):.0%}",
                      _fmt(float(np.mean(c["steps_mean"][-tail:])), 0),
                      "n/a" if s is None else _fmt(float(np.median(s)), 3)])
    lines += [f"{robot}. {spec['episodes']} episodes of at most {spec['episode_steps']} steps "
              f"per run, {spec['train_iterations']} minibatch updates after each episode (thesis: "
              "50 epochs x up to 15 minibatches, 300 episodes, 10 seeds). Networks 3 x 200, no "
              f"target networks, actor lr = critic lr. Speed: {_speed(results)}.", "",
              f"![{experiment} learning curves](figures/{prefix}_learning.png)", ""]
    if spread:
        lines += [f"![{experiment} Q spread](figures/{prefix}_q_std.png)", ""]
    lines += _table(["algorithm", "lr", "seeds", f"mean return, last {tail} episodes",
                     "success, last episodes", "steps, last episodes",
                     "median std of Q (27 x 11)"], table)
    return lines + [""], {"curves": curves, "spread": spread, "tail": tail, "robot": experiment}


def _peg_budget(budget: PegBudget) -> str:
    return (f"{budget.episodes} episodes x {len(budget.seeds)} seeds, {len(budget.lrs)} lrs, "
            f"{budget.train_iterations} updates/episode")


# --- the page ----------------------------------------------------------------------------------
#: Mean Q counts as diverged beyond the realisable range by more than this share of its width.
#: Predictions are not clipped (only the TD targets are), so fitting noise overshoots the range
#: by a few hundredths of it; the thesis's soft divergence runs away by many widths (Fig. 9.6).
DIVERGENCE_FRACTION = 0.1


def divergence_margin(q_range: tuple[float, float]) -> float:
    """How far outside ``q_range`` a mean Q must go to count as diverged."""
    return DIVERGENCE_FRACTION * (q_range[1] - q_range[0])


def split_by_excess(excess: dict[str, float], q_range: tuple[float, float]
                    ) -> tuple[list[str], list[str]]:
    """Runs whose mean Q left ``q_range``: (diverged, overshot) names, each by growing excess.

    :param excess: per run, the largest distance of its mean Q outside the range (<= 0: inside).
    :param q_range: the realisable Q range of the rewards (lowest, highest).
    """
    margin = divergence_margin(q_range)
    ordered = sorted((n for n, e in excess.items() if e > 0), key=excess.get)
    return ([n for n in ordered if excess[n] > margin], [n for n in ordered if excess[n] <= margin])


def _comparison(random_rows: list[dict[str, Any]], grid_rows: list[dict[str, Any]],
                grid_results: list[dict[str, Any]], variant_rows: list[dict[str, Any]],
                peg_data: list[dict], q_range: tuple[float, float]) -> list[str]:
    notes = ["## Where our numbers agree and disagree with the thesis", ""]
    if random_rows:
        uniform = [r for r in random_rows if r["kind"] == "uniform"]
        if uniform:
            u = uniform[0]
            notes.append(f"- Random baseline: uniform residuals needed {u['mean_steps']:.1f} steps "
                         f"on average (median {u['median_steps']:.0f}, {u['success_rate']:.0%} "
                         f"success) against 32 on the real robot: "
                         + ("about the same." if abs(u["mean_steps"] - 32) <= 8 else
                            "the simulated task is " + ("easier" if u["mean_steps"] < 32
                                                        else "harder") + " for random search."))
    if grid_rows:
        for a, thesis in (("qgddpg", THESIS["qg_cells"]), ("ddpg", THESIS["ddpg_cells"])):
            mine = [r for r in grid_rows if r["algorithm"] == a]
            if mine:
                wins = sum(r["beats_random"] for r in mine)
                notes.append(f"- {_NAMES[a]} beat the best random baseline in {wins} of "
                             f"{len(mine)} cells run (thesis, real robot: {thesis} of 8).")
        for a in ("ddpg", "qgddpg"):
            runs = [r for r in grid_results if r["spec"]["algorithm"] == a and r["cycles"]]
            if runs:
                excess = {r["name"]: max(max(c["mean_q"] - q_range[1], q_range[0] - c["mean_q"])
                                         for c in r["cycles"]) for r in runs}
                diverged, overshot = split_by_excess(excess, q_range)
                margin = divergence_margin(q_range)
                text = (f"- {_NAMES[a]}: mean Q diverged (left the realisable range "
                        f"[{q_range[0]:g}, {q_range[1]:g}] by more than {margin:.3g}, a tenth of "
                        f"its width) in {len(diverged)} of {len(runs)} runs")
                if diverged:
                    text += f", by up to {excess[diverged[-1]]:.3g} ({diverged[-1]})"
                if overshot:
                    text += (f"; {len(overshot)} run(s) overshot it by less, at most "
                             f"{excess[overshot[-1]]:.3g} ({overshot[-1]})")
                notes.append(text + (" (thesis: DDPG diverges under bad hyperparameters)."
                                     if a == "ddpg" else " (thesis: QG-DDPG never diverges)."))
    if variant_rows:
        for r in variant_rows:
            notes.append(f"- {_NAMES[r['algorithm']]} with "
                         + (f"the {r['reward']} reward" if r["reward"] != "dense"
                            else f"a replay of {r['replay_capacity']}")
                         + f": {'beat' if r['beats_random'] else 'did not beat'} random "
                         "(thesis: QG-DDPG did, DDPG did not).")
    for data in peg_data:
        if not data.get("curves"):
            continue
        curves, spread, tail = data["curves"], data["spread"], data["tail"]
        label = "Peg" if data["robot"] == "peg" else "Nextage peg"
        for lr in sorted({k[1] for k in curves}, reverse=True):
            d, q = curves.get(("ddpg", lr)), curves.get(("qgddpg", lr))
            if d is None or q is None:
                continue
            rd = float(np.mean(d["return_mean"][-tail:]))
            rq = float(np.mean(q["return_mean"][-tail:]))
            sd, sq = spread.get(("ddpg", lr)), spread.get(("qgddpg", lr))
            text = (f"- {label}, lr {lr:g}: late-episode return QG-DDPG {rq:.1f} vs DDPG {rd:.1f} ("
                    + ("about equal" if abs(rq - rd) < 0.02 * max(abs(rq), abs(rd))
                       else "QG-DDPG better" if rq > rd else "DDPG better")
                    + "; thesis: QG never worse, largest gain at poor learning rates)")
            if sd is not None and sq is not None:
                text += (f"; median Q spread across seeds QG-DDPG {np.median(sq):.3g} vs DDPG "
                         f"{np.median(sd):.3g} (thesis at lr 1e-4: clearly smaller with QG)")
            notes.append(text + ".")
    seeds = sorted({r["spec"]["seed"] for r in grid_results})
    notes.append(f"- Budgets are far below the thesis's (see the budget table), with "
                 f"{len(seeds)} seed(s) per grid cell: differences of a few steps between cells "
                 "are within seed noise.")
    return notes + [""]


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

    random_results = saved("random")
    grid_results = saved("grid")
    variant_results = saved("variants")
    peg_results = saved("peg")
    nextage_results = saved("nextage")
    random_rows = summarize_baselines(random_results) if random_results else []
    test_cap = (grid_results[0]["spec"]["test_max_steps"] if grid_results
                else profile.grid.test_max_steps)
    best = random_bar(random_rows, test_cap)
    bar = best[0] if best else None
    bar_label = (f"{best[1]}, {bar:.1f} steps with its episodes cut at the test cap of "
                 f"{test_cap}" if best else "no random baseline run: nothing marked")
    grid_rows = grid.cell_table(grid_results, bar)
    variant_rows = grid.cell_table(variant_results, bar)
    # The tables' data beside the page (small, versioned); the per-run JSON stays under ``out``.
    data = docs / "data" / profile.name
    data.mkdir(parents=True, exist_ok=True)
    _write_csv(data / "random_summary.csv", random_rows)
    _write_csv(data / "grid_summary.csv", grid_rows)
    _write_csv(data / "variants_summary.csv", variant_rows)
    for name, results in (("random", random_results), ("grid", grid_results),
                          ("variants", variant_results), ("peg", peg_results),
                          ("nextage", nextage_results)):
        if results:
            _episodes_csv(data / f"{name}_episodes.csv", results)
    tensorboard = export_runs((*grid_results, *variant_results, *peg_results, *nextage_results),
                              out / "tensorboard")
    settings = StackSettings.load(config_dir)
    g = settings.learner.ddpg.gamma
    q_range = (settings.learner.ddpg.r_min / (1 - g), settings.learner.ddpg.r_max)
    digests = sorted({r.get("config_digest", "?") for r in
                      (*random_results, *grid_results, *variant_results, *peg_results,
                       *nextage_results)})
    timing_path = out / "timing.json"
    timing = json.loads(timing_path.read_text()) if timing_path.exists() else {}
    estimator = {"ekf": "the EKF wrench estimator (as in the ROS stack)",
                 "ground_truth": "the simulator's true contact wrench (perfect sensor)"}
    lines = ["# Results: the thesis's experiments in simulation", "",
             "Generated by `qg_experiments.report` from the saved runs; do not edit "
             "by hand. Regenerate with", "", "```",
             f"scripts/experiments.sh --profile {profile.name}",
             f".venv/bin/python -m qg_experiments --profile {profile.name} "
             "--report-only", "```", "",
             f"Profile **{profile.name}** of `config/experiments.yaml`; every run used the "
             f"fast in-process runner (the ROS stack's cores and config files, no DDS) with "
             f"{estimator[profile.estimator]}. Stack config files: "
             f"`{config_dir or 'config/'}`, digest(s) {', '.join(f'`{d}`' for d in digests)} "
             f"(`runner.config_digest`). Every episode and every table row as CSV: "
             f"[`data/{profile.name}/`](data/{profile.name}/); per-run JSON: `{out}`; "
             f"TensorBoard scalars of every learning run (Stable-Baselines3's tag names): "
             f"`tensorboard --logdir {tensorboard}`.", "",
             "| step | command | wall time | finished |", "|---|---|---|---|"]
    lines += [f"| {k} | `{v['command']}` | {v['wall_time'] / 60:.1f} min | {v['finished']} |"
              for k, v in timing.items()]
    lines += ["", "Budget of this profile against the thesis:", ""]
    pg, pr, pp, pv = profile.grid, profile.random, profile.peg, profile.variants
    results_by = {"random": random_results, "grid": grid_results, "variants": variant_results,
                  "peg": peg_results, "nextage": nextage_results}
    budget = {
        "random": ("random baselines", "several noises, 1000-step cap, up to 3000 steps each",
                   f"{len(pr.noises)} settings x {pr.episodes} episodes, cap {pr.max_steps}"),
        "grid": ("grid", "8 cells x 2 algorithms x 3 seeds, 40 train + 8 test episodes (cap 200)",
                 f"{len(pg.cells)} cells x {len(pg.algorithms)} algorithms x {len(pg.seeds)} "
                 f"seed(s), {pg.train_episodes} train (cap {pg.train_max_steps}) + "
                 f"{pg.test_episodes} test episodes (cap {pg.test_max_steps})"),
        "variants": ("variants", "sparse reward; replay 300",
                     ", ".join([*pv.rewards, *(f"replay {c}" for c in pv.replay_capacities)])
                     or "none"),
        "peg": ("peg", "300 episodes x 10 seeds, 3 lrs, 750 updates/episode",
                _peg_budget(pp))}
    if profile.nextage is not None:
        budget["nextage"] = ("Nextage peg", "(the real Nextage: ch. 8.3)", _peg_budget(profile.nextage))
    planned = planned or {}
    lines += _table(["experiment", "thesis", f"profile {profile.name}", "runs finished"],
                    [[*row, f"{len(results_by[k])} of {planned.get(k, '?')}"]
                     for k, row in budget.items()])
    noise = settings.noise
    lines += ["", "How the runs were made: each run builds the simulated Panda, the bridge's 1 kHz "
              "loop and the wrench estimator (`RobotLoop`), and drives it with the executor's "
              "`Episode`/`ResidualTask` and the learner's `LearnerCore`, exactly as the ROS nodes "
              "do, but synchronously (training happens at the end of each cycle, then the "
              "executor's actor is replaced). Start poses rotate 0..7. Vanilla DDPG: no bounds "
              "and no zero-action loops (as in the thesis); QG-DDPG: Q-Graph plus a-priori "
              f"bounds, zero action (0, 0) whose self-loops go into graph and replay. Exploration "
              f"in training: {noise.kind} noise, sigma {noise.sigma:g} (actor units). State: "
              f"the `{pg.observation or settings.task.observation}` observation "
              "(`residual_task.OBSERVATIONS`; why, and the thesis's 4-D state beside it: "
              "[learning.md](learning.md)). Runs are deterministic per seed (tested in "
              "`tests/experiments/test_runner.py`).", ""]
    lines += _random_section(random_rows, random_results, figures)
    lines += _grid_section(grid_rows, grid_results, bar, bar_label)
    lines += _learning_curves(grid_results, grid_rows, figures, bar)
    lines += _q_section(grid_results, grid_rows, figures, q_range)
    lines += _variant_section(variant_rows, bar)
    peg_data = []
    for experiment, results in (("peg", peg_results), ("nextage", nextage_results)):
        if experiment == "nextage" and profile.nextage is None and not results:
            continue
        section, data = _peg_section(results, figures, experiment)
        lines += section
        peg_data.append(data)
    lines += _comparison(random_rows, grid_rows, grid_results, variant_rows, peg_data, q_range)
    path = docs / "results.md"
    path.write_text("\n".join(lines))
    return path
