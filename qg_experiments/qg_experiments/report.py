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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from qg_experiments import grid, peg, stats
from qg_experiments.figures import pyplot
from qg_experiments.profile import PegBudget, Profile
from qg_experiments.random_baselines import random_bar, summarize_baselines
from qg_experiments.runner import StackSettings
from qg_experiments.tasks import load_results
from qg_experiments.tensorboard_log import export_runs

__all__ = ["write_report", "THESIS"]

#: The thesis's real-robot and peg numbers the page compares against (SPEC 2, thesis ch. 8-9).
THESIS = {"random_steps": 32, "qg_cells": 6, "ddpg_cells": 1, "cells": 8}

_COLORS = {"ddpg": "tab:orange", "qgddpg": "tab:blue"}
_NAMES = {"ddpg": "DDPG", "qgddpg": "QG-DDPG"}


@dataclass(frozen=True)
class Bar:
    """The random bar: the best random setting's mean steps, its episodes cut at the test cap,
    with the 95 % interval over those episodes."""
    label: str
    interval: stats.Interval
    cap: int

    @property
    def mean(self) -> float:
        return self.interval.mean


def random_bar_of(rows: list[dict[str, Any]], cap: int) -> Bar | None:
    """The :class:`Bar` of the random baselines ``rows`` (``random_baselines.random_bar``)."""
    best = random_bar(rows, cap)
    if best is None:
        return None
    row = next(r for r in rows if r["label"] == best[1])
    return Bar(best[1], stats.mean_interval(np.minimum(row["steps"], cap)), cap)


def _bar_text(bar: Bar | None) -> str:
    if bar is None:
        return "no random baseline run: nothing marked"
    return (f"{bar.label}, {stats.format_interval(bar.interval)} steps over "
            f"{bar.interval.n} episodes cut at the test cap of {bar.cap}")


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
def _random_section(rows: list[dict[str, Any]], results: list[dict[str, Any]], cap: int,
                    bar: Bar | None, figures: Path) -> list[str]:
    if not rows:
        return ["## 1. Random baselines", "", "Not run in this profile.", ""]
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.boxplot([np.minimum(r["steps"], cap) for r in rows], showmeans=True)
    ax.set_xticks(range(1, len(rows) + 1), [r["label"] for r in rows], rotation=15)
    ax.axhline(THESIS["random_steps"], color="gray", ls="--", lw=1, label="thesis: 32 (real robot)")
    ax.set_ylabel("steps per episode")
    ax.set_title(f"Random residuals: steps to insertion (failures at the cap {cap})")
    ax.legend()
    fig.tight_layout()
    fig.savefig(figures / "exp1_random_steps.png", dpi=110)
    plt.close(fig)
    seeds = sorted({r["spec"]["seed"] for r in results})
    lines = ["## 1. Random baselines", "",
             f"Base push plus a random residual; OU with theta and dt from `executor.yaml`. "
             f"{rows[0]['episodes']} episodes per setting: the 8 start poses on each of "
             f"{len(seeds)} seeds ({', '.join(map(str, seeds))}), each seed on its own arm; cap "
             f"{rows[0]['max_steps']} steps, a failed episode counts as the cap. The interval is "
             f"over episodes (independent draws). Speed: {_speed(results)}.", ""]
    table = []
    for r in rows:
        capped = stats.mean_interval(np.minimum(r["steps"], cap))
        mark = " (the bar)" if bar is not None and r["label"] == bar.label else ""
        table.append([r["label"] + mark, str(r["episodes"]), f"{r['success_rate']:.0%}",
                      stats.format_interval(capped), _fmt(r["median_steps"]),
                      str(sum(n >= r["max_steps"] for n in r["steps"]))])
    lines += _table(["residual", "episodes", "inserted", "mean steps [95 % CI]",
                     "median", "failures at the cap"], table)
    lines += ["", "![random baselines](figures/exp1_random_steps.png)", ""]
    return lines


# --- experiments 2-4 ---------------------------------------------------------------------------
def _cell(row: dict[str, Any] | None) -> str:
    """``**12.3** [8.1, 17.0] (39/40)``: bold when the whole interval is below the bar."""
    if row is None:
        return "—"
    mark = "**" if row["beats_random"] else ""
    inserted = row["test_episodes"] - row["test_failures"]
    return (f"{mark}{_fmt(row['mean_test_steps'])}{mark} [{_fmt(row['ci_low'])}, "
            f"{_fmt(row['ci_high'])}] ({inserted}/{row['test_episodes']})")


def _paired_line(results: list[dict[str, Any]], what: str) -> tuple[str, Any]:
    """One sentence: QG-DDPG against DDPG on the same (cell, seed) pairs of ``results``."""
    qg, ddpg, keys = grid.pairs(results)
    if not keys:
        return f"No paired runs of both algorithms in {what}.", None
    c = stats.paired_comparison(qg, ddpg)
    verdict = ("QG-DDPG needs significantly fewer test steps" if c.significant() else
               "DDPG needs significantly fewer test steps" if c.wilcoxon_p < 0.05 else
               "no significant difference")
    return (f"QG-DDPG against DDPG on the same {c.n} (cell, seed) pairs of {what}: QG-DDPG "
            f"needs fewer test steps in {c.wins_a}, DDPG in {c.wins_b}, {c.ties} tie(s); DDPG "
            f"minus QG-DDPG {stats.format_interval(c.difference)} steps per test episode; "
            f"Wilcoxon signed-rank p = {c.wilcoxon_p:.3g}, sign test p = {c.sign_p:.3g}: "
            f"**{verdict}** at 5 %.", c)


def _grid_section(title: str, rows: list[dict[str, Any]], results: list[dict[str, Any]],
                  bar: Bar | None) -> list[str]:
    if not rows:
        return [title, "", "Not run in this profile.", ""]
    spec = results[0]["spec"]
    algorithms = sorted({r["algorithm"] for r in rows})
    wins = {a: sum(r["beats_random"] for r in rows if r["algorithm"] == a) for a in algorithms}
    counts = {a: sum(1 for r in rows if r["algorithm"] == a) for a in algorithms}
    seeds = sorted({r["spec"]["seed"] for r in results})
    lines = [title, "",
             (f"State `{spec['observation']}`. " if spec.get("observation") else
              "State: the stack's default (`task.observation`, `config/executor.yaml`). ") +
             f"{spec['train_episodes']} training episodes (cap {spec['train_max_steps']} steps, "
             f"training after every {spec['cycle_steps'] or 20} steps), then "
             f"{spec['test_episodes']} test episodes without noise (cap {spec['test_max_steps']}), "
             f"on {len(seeds)} seeds ({', '.join(map(str, seeds))}); the actor's learning rate is "
             "a tenth of the critic's. Cell: mean test steps over seeds and episodes (failures "
             "count as the cap) with its 95 % bootstrap interval over the per-seed means, test "
             "episodes inserted in brackets; **bold**: the whole interval lies below the random "
             f"bar ({_bar_text(bar)}). Speed: {_speed(results)}.", ""]
    lines += _grid_table(rows, "")[2:]
    lines += ["", "Cells beating random: " + ", ".join(
        f"{_NAMES[a]} {wins[a]} of {counts[a]}" for a in algorithms) + ".", ""]
    lines += [_paired_line(results, "this grid")[0], ""]
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
                     figures: Path, bar: Bar | None) -> list[str]:
    """Steps per episode (training, then test) of the best and worst cell of each algorithm:
    the mean over seeds with the standard deviation of that mean shaded, as in the thesis."""
    if not rows:
        return []
    chosen = _q_runs(results, rows)
    plt = pyplot()
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
            ax.axhline(bar.mean, color="gray", ls="--", lw=1,
                       label=f"random bar ({bar.label}, same seeds), 95 % CI shaded")
            ax.axhspan(bar.interval.low, bar.interval.high, color="gray", alpha=0.15)
        ax.set_xlabel("episode (training, then test)")
        ax.set_title(f"{tag} cell of each algorithm")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("steps per episode (failures at the cap)")
    fig.tight_layout()
    fig.savefig(figures / "exp2_learning_curves.png", dpi=110)
    plt.close(fig)
    return ["Learning curves of the best and worst cell of each algorithm (mean over seeds, "
            "shaded: standard deviation of the mean; grey: the random bar measured on the same "
            "seeds, with its interval):", "",
            "![learning curves](figures/exp2_learning_curves.png)", ""]


def _q_section(results: list[dict[str, Any]], rows: list[dict[str, Any]], figures: Path,
               q_range: tuple[float, float], gamma: float) -> list[str]:
    if not rows:
        return []
    chosen = _q_runs(results, rows)
    plt = pyplot()
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
    lines = ["## 3. Mean predicted Q during training", "",
             "Mean of the critic's predictions on each cycle's minibatches (averaged over the "
             "cycle's iterations), best and worst cell of each algorithm by mean test steps. "
             f"The realisable range of the dense and sparse rewards is [{q_range[0]:g}, "
             f"{q_range[1]:g}]. A run's mean Q counts as diverged when it leaves that range by "
             f"more than a tenth of its width, as overshot when by less.", "",
             "![mean Q](figures/exp3_mean_q.png)", ""]
    return lines + [_divergence_text(results, gamma), ""]


def _variant_section(results: list[dict[str, Any]], bar: Bar | None,
                     gamma: float) -> list[str]:
    lines = ["## 4. Where the thesis says the graph matters: sparse reward, a 300-transition "
             "replay memory, the discount 0.99", ""]
    if not results:
        return lines + ["Not run in this profile (see the budget table).", ""]
    cells = sorted({(r["spec"]["critic_lr"], r["spec"]["iterations"]) for r in results})
    lines += ["The grid's protocol with one setting changed, at the fixed cells "
              + ", ".join(f"lr {lr:g} / {it} iterations" for lr, it in cells)
              + ", both algorithms on the same seeds. Cells as in the grid's table.", ""]
    for name, group in _by_variant(results, gamma).items():
        rows = grid.cell_table(group, None if bar is None else bar.mean)
        lines += _grid_table(rows, f"**{name}**")
        lines += ["", _paired_line(group, f"{name}")[0], ""]
    return lines


def _by_variant(results: list[dict[str, Any]], gamma: float) -> dict[str, list[dict[str, Any]]]:
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault(grid.variant_name(r["spec"], gamma), []).append(r)
    return dict(sorted(groups.items()))


def _grid_table(rows: list[dict[str, Any]], caption: str) -> list[str]:
    """The cells of ``rows``, one line per cell, an algorithm per column."""
    cells = sorted({(r["critic_lr"], r["iterations"]) for r in rows})
    algorithms = sorted({r["algorithm"] for r in rows})
    by_key = {(r["algorithm"], r["critic_lr"], r["iterations"]): r for r in rows}
    return [caption, ""] + _table(
        ["critic lr", "iterations/cycle", *[_NAMES[a] for a in algorithms]],
        [[f"{lr:g}", str(it), *[_cell(by_key.get((a, lr, it))) for a in algorithms]]
         for lr, it in cells])


def run_excess(result: dict[str, Any], gamma: float, r_min: float, r_max: float) -> float:
    """How far the run's mean Q went outside its realisable range (its own discount)."""
    g = result["spec"].get("gamma") or gamma
    low, high = min(r_min, r_min / (1 - g)), max(r_max, r_max / (1 - g))
    return max((max(c["mean_q"] - high, low - c["mean_q"]) for c in result["cycles"]),
               default=-math.inf)


def run_divergence(result: dict[str, Any], gamma: float, r_min: float = -1.0,
                   r_max: float = 0.0) -> tuple[bool, bool]:
    """(diverged, overshot) of one run by :func:`split_by_excess`, against the range of its own
    discount."""
    g = result["spec"].get("gamma") or gamma
    q_range = (min(r_min, r_min / (1 - g)), max(r_max, r_max / (1 - g)))
    d, o = split_by_excess({result["name"]: run_excess(result, gamma, r_min, r_max)}, q_range)
    return bool(d), bool(o)


def divergence_counts(results: list[dict[str, Any]], gamma: float, r_min: float = -1.0,
                      r_max: float = 0.0) -> dict[str, tuple[int, int, int]]:
    """Per algorithm: (diverged, overshot, runs) by :func:`run_divergence`."""
    counts = {}
    for a in sorted({r["spec"]["algorithm"] for r in results}):
        runs = [r for r in results if r["spec"]["algorithm"] == a and r["cycles"]]
        flags = [run_divergence(r, gamma, r_min, r_max) for r in runs]
        counts[a] = (sum(d for d, _ in flags), sum(o for _, o in flags), len(runs))
    return counts


def _divergence_pairs(results: list[dict[str, Any]], gamma: float) -> str:
    """One sentence: how often the critic diverged in QG-DDPG's run and not in DDPG's on the
    same (setting, cell, seed), and the reverse, over every setting, with McNemar's test."""
    qg, ddpg, keys = grid.paired_values(
        results, lambda r: run_divergence(r, gamma)[0] if r["cycles"] else None)
    if not keys:
        return ""
    e = stats.paired_events(qg, ddpg)
    return (f"Divergence over every setting above, on the same {len(keys)} (setting, cell, "
            f"seed) pairs: only DDPG's critic diverged in {e.only_b}, only QG-DDPG's in "
            f"{e.only_a}, both in {e.both}, neither in {e.neither}; exact McNemar test "
            f"p = {e.p:.2g}.")


def _divergence_text(results: list[dict[str, Any]], gamma: float) -> str:
    counts = divergence_counts(results, gamma)
    return "Diverged (overshot) runs: " + "; ".join(
        f"{_NAMES[a]} {d} ({o}) of {n}" for a, (d, o, n) in counts.items()) + "."


def _graph_section(settings: dict[str, list[dict[str, Any]]], bar: Bar | None,
                   gamma: float) -> list[str]:
    """One row per setting: the paired comparison, the cells beating random, divergence, and
    what the graph did (targets raised, critic error against the Monte-Carlo return)."""
    table = []
    for name, results in settings.items():
        if not results:
            continue
        _, comparison = _paired_line(results, name)
        rows = grid.cell_table(results, None if bar is None else bar.mean)
        wins = {a: (sum(r["beats_random"] for r in rows if r["algorithm"] == a),
                    sum(1 for r in rows if r["algorithm"] == a)) for a in ("qgddpg", "ddpg")}
        counts = divergence_counts(results, gamma)
        diag = {a: grid.graph_diagnostics([r for r in results if r["spec"]["algorithm"] == a])
                for a in ("qgddpg", "ddpg")}
        table.append([
            name, "—" if comparison is None else str(comparison.n),
            "—" if comparison is None else f"{comparison.wins_a} / {comparison.wins_b} / "
                                           f"{comparison.ties}",
            "—" if comparison is None else stats.format_interval(comparison.difference),
            "—" if comparison is None else f"{comparison.wilcoxon_p:.3g}",
            *[f"{wins[a][0]} of {wins[a][1]}" for a in ("qgddpg", "ddpg")],
            *[f"{counts.get(a, (0, 0, 0))[0]} of {counts.get(a, (0, 0, 0))[2]}"
              for a in ("qgddpg", "ddpg")],
            f"{diag['qgddpg']['targets_raised']:.1%}",
            f"{_fmt(diag['qgddpg']['critic_mc_error'], 2)} / "
            f"{_fmt(diag['ddpg']['critic_mc_error'], 2)}"])
    lines = ["## 7. QG-DDPG against DDPG, setting by setting", "",
             "Per setting: the (cell, seed) pairs of both algorithms; QG-DDPG better / DDPG "
             "better / ties; DDPG minus QG-DDPG in mean test steps with its 95 % interval "
             "(positive: QG-DDPG needs fewer); the two-sided Wilcoxon signed-rank p; the cells "
             "whose interval lies below the random bar; the runs whose mean Q diverged; the "
             "share of TD targets the graph's lower bound raised (mean over training cycles); "
             "the critic's mean |Q - Monte-Carlo return| on the goal-reaching training "
             "episodes at the end of training (QG-DDPG / DDPG).", ""]
    lines += _table(["setting", "pairs", "QG / DDPG / ties", "DDPG - QG [95 % CI]",
                     "Wilcoxon p", "QG-DDPG beats random", "DDPG beats random",
                     "QG-DDPG diverged", "DDPG diverged", "targets raised",
                     "critic error vs MC"], table)
    divergence = _divergence_pairs([r for results in settings.values() for r in results], gamma)
    return lines + ([""] + [divergence] if divergence else []) + [""]


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
    plt = pyplot()
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


def _peg_paired(results: list[dict[str, Any]], tail: int) -> str:
    """QG-DDPG against DDPG on the same seeds of a peg experiment: late-episode return."""
    late: dict[tuple[float, int], dict[str, float]] = {}
    for r in results:
        s = r["spec"]
        late.setdefault((s["lr"], s["seed"]), {})[s["algorithm"]] = float(
            np.mean([e["return"] for e in r["episodes"][-tail:]]))
    keys = sorted(k for k, v in late.items() if {"qgddpg", "ddpg"} <= set(v))
    if not keys:
        return ""
    # Lower is better in paired_comparison: compare the negated returns.
    c = stats.paired_comparison([-late[k]["qgddpg"] for k in keys],
                                [-late[k]["ddpg"] for k in keys])
    return (f"QG-DDPG against DDPG on the same {c.n} (lr, seed) pairs, mean return of the last "
            f"{tail} episodes: QG-DDPG higher in {c.wins_a}, DDPG in {c.wins_b}, {c.ties} "
            f"tie(s); QG-DDPG minus DDPG {stats.format_interval(c.difference, 2)}; Wilcoxon "
            f"p = {c.wilcoxon_p:.3g} (with 5 pairs the smallest two-sided p is 0.0625).")


def _comparison(random_rows: list[dict[str, Any]], bar: Bar | None,
                grids: dict[str, list[dict[str, Any]]], variant_results: list[dict[str, Any]],
                peg_data: list[dict], gamma: float) -> list[str]:
    notes = ["## Where our numbers agree and disagree with the thesis", ""]
    uniform = [r for r in random_rows if r["kind"] == "uniform"]
    if uniform and bar is not None:
        u = uniform[0]
        interval = stats.mean_interval(np.minimum(u["steps"], bar.cap))
        notes.append(f"- Random baseline: uniform residuals needed "
                     f"{stats.format_interval(interval)} steps ({u['episodes']} episodes, "
                     f"{u['success_rate']:.0%} inserted) against 32 on the real robot: "
                     + ("32 lies inside the interval." if interval.low <= 32 <= interval.high
                        else "the simulated task is " + ("easier" if interval.high < 32
                                                         else "harder") + " for random search."))
    for title, results in grids.items():
        rows = grid.cell_table(results, None if bar is None else bar.mean)
        for a, thesis in (("qgddpg", THESIS["qg_cells"]), ("ddpg", THESIS["ddpg_cells"])):
            mine = [r for r in rows if r["algorithm"] == a]
            if mine:
                notes.append(f"- {title}: {_NAMES[a]} beat the random bar (whole interval "
                             f"below it) in {sum(r['beats_random'] for r in mine)} of "
                             f"{len(mine)} cells (thesis, real robot: {thesis} of 8).")
        if results:
            notes.append(f"- {title}: {_divergence_text(results, gamma)} (thesis: DDPG "
                         "diverges under bad hyperparameters, QG-DDPG never).")
    for name, group in _by_variant(variant_results, gamma).items():
        rows = grid.cell_table(group, None if bar is None else bar.mean)
        text = "; ".join(f"{_NAMES[a]} beat random in "
                         f"{sum(r['beats_random'] for r in rows if r['algorithm'] == a)} of "
                         f"{sum(1 for r in rows if r['algorithm'] == a)} cells"
                         for a in ("qgddpg", "ddpg"))
        notes.append(f"- {name}: {text} (thesis: QG-DDPG did, DDPG did not).")
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
            text = (f"- {label}, lr {lr:g}: late-episode return QG-DDPG {rq:.1f} vs DDPG {rd:.1f}"
                    " (thesis: QG never worse, largest gain at poor learning rates)")
            if sd is not None and sq is not None:
                text += (f"; median Q spread across seeds QG-DDPG {np.median(sq):.3g} vs DDPG "
                         f"{np.median(sd):.3g} (thesis at lr 1e-4: clearly smaller with QG)")
            notes.append(text + ".")
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

    results_by = {name: saved(name) for name in
                  ("random", "grid", "variants", "state_grid", "peg", "nextage")}
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
    _write_csv(data / "random_summary.csv", random_rows)
    if bar is not None:        # the demo's learning curve draws this bar (qgl demo)
        (data / "random_bar.json").write_text(json.dumps(
            {"label": bar.label, "mean": bar.mean, "low": bar.interval.low,
             "high": bar.interval.high, "episodes": bar.interval.n, "cap": bar.cap,
             "seeds": sorted({r["spec"]["seed"] for r in random_results})}, indent=1))
    _write_csv(data / "grid_summary.csv", grid_rows)
    _write_csv(data / "state_grid_summary.csv", state_rows)
    _write_csv(data / "variants_summary.csv", grid.cell_table(variant_results, bar_mean))
    for name, results in results_by.items():
        if results:
            _episodes_csv(data / f"{name}_episodes.csv", results)
    tensorboard = export_runs((*grid_results, *variant_results, *state_results,
                               *results_by["peg"], *results_by["nextage"]), out / "tensorboard")
    settings = StackSettings.load(config_dir)
    gamma = settings.learner.ddpg.gamma
    q_range = (settings.learner.ddpg.r_min / (1 - gamma), settings.learner.ddpg.r_max)
    digests = sorted({r.get("config_digest", "?") for results in results_by.values()
                      for r in results})
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
             f"{estimator[profile.estimator]}, on the **{profile.arm}** simulated Panda "
             f"(`panda_scene.imperfections`; each seed is its own robot: its biases, housing "
             f"error and noise). Stack config files: "
             f"`{config_dir or 'config/'}`, digest(s) {', '.join(f'`{d}`' for d in digests)} "
             f"(`runner.config_digest`). Every episode and every table row as CSV: "
             f"[`data/{profile.name}/`](data/{profile.name}/); per-run JSON: `{out}`; "
             f"TensorBoard scalars of every learning run (Stable-Baselines3's tag names): "
             f"`tensorboard --logdir {tensorboard}`.", "",
             f"**Seeds.** Every table below is computed on the report seeds "
             f"{', '.join(map(str, profile.seeds.report))}; every choice of the setup (the state, "
             f"the discount, the variants' cells) was made on the tuning seeds "
             f"{', '.join(map(str, profile.seeds.tuning))} ([learning.md](learning.md)). "
             "**Statistics** (`qg_experiments/stats.py`): 95 % BCa bootstrap intervals (SciPy, "
             "10,000 resamples) over the per-seed means of a cell, over episodes for the random "
             "baselines; a cell beats random only when its whole interval lies below the random "
             "bar; QG-DDPG against DDPG is a paired comparison over the same (cell, seed) runs "
             "with the Wilcoxon signed-rank test and the sign test.", "",
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
                _peg_budget(pp))}
    if profile.state_grid is not None:
        budget["state_grid"] = ("grid, thesis's 4-D state", "the grid above (the thesis's state)",
                                f"the grid with `observation: {profile.state_grid.observation}`")
    if profile.nextage is not None:
        budget["nextage"] = ("Nextage peg", "(the real Nextage: ch. 8.3)",
                             _peg_budget(profile.nextage))
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
              f"(`residual_task.OBSERVATIONS`), discount {gamma:g}, both chosen on the tuning "
              "seeds ([learning.md](learning.md)); the thesis's 4-D state in section 2b. Runs are "
              "deterministic per seed (tested in `tests/experiments/test_runner.py`).", ""]
    lines += _random_section(random_rows, random_results, test_cap, bar, figures)
    lines += _grid_section("## 2. The grid: mean test steps per cell", grid_rows, grid_results,
                           bar)
    lines += _learning_curves(grid_results, grid_rows, figures, bar)
    if profile.state_grid is not None or state_results:
        lines += _grid_section("## 2b. The grid with the thesis's 4-D wrench state", state_rows,
                               state_results, bar)
    lines += _q_section(grid_results, grid_rows, figures, q_range, gamma)
    lines += _variant_section(variant_results, bar, gamma)
    peg_data = []
    for experiment in ("peg", "nextage"):
        results = results_by[experiment]
        if experiment == "nextage" and profile.nextage is None and not results:
            continue
        section, data = _peg_section(results, figures, experiment)
        lines += section
        if data:
            lines += [_peg_paired(results, data["tail"]), ""]
        peg_data.append(data)
    grids = {f"grid (`{pg.observation or settings.task.observation}`, the default)": grid_results,
             "grid with the thesis's 4-D state": state_results}
    lines += _graph_section({**grids, **_by_variant(variant_results, gamma)}, bar, gamma)
    lines += _comparison(random_rows, bar, grids, variant_results, peg_data, gamma)
    path = docs / "results.md"
    path.write_text("\n".join(lines))
    if (out / "peers").is_dir() or (out / "standard_tasks").is_dir():
        # The peers' runs come from their own benchmarks; their section follows ours.
        from qg_experiments import peers_report
        peers_report.write_section(path, out)
    return path
