"""Sections 1-4 of ``docs/results.md``: the random baselines, the grid (and the grid with the
thesis's state), the mean predicted Q, and the variants where the thesis says the graph matters.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import label

from qg_experiments import grid, stats
from qg_experiments.random_baselines import Bar
from qg_experiments.report import plots
from qg_experiments.report.divergence import divergence_counts
from qg_experiments.report.markdown import bar_text, fmt, grid_table, speed, table

__all__ = ["THESIS", "random_section", "paired_line", "grid_section", "learning_curves_section",
           "q_section", "variant_section", "divergence_text"]

#: The thesis's real-robot and peg numbers the page compares against (SPEC 2, thesis ch. 8-9).
THESIS = {"random_steps": 32, "qg_cells": 6, "ddpg_cells": 1, "cells": 8}


# --- experiment 1 ------------------------------------------------------------------------------
def random_section(rows: list[dict[str, Any]], results: list[dict[str, Any]], cap: int,
                   bar: Bar | None, figures: Path) -> list[str]:
    """Section 1: the random residuals' steps per setting, the bar marked."""
    if not rows:
        return ["## 1. Random baselines", "", "Not run in this profile.", ""]
    plots.random_steps(rows, cap, THESIS["random_steps"], figures / "exp1_random_steps.png")
    seeds = sorted({r["spec"]["seed"] for r in results})
    lines = ["## 1. Random baselines", "",
             f"Base push plus a random residual; OU with theta and dt from `executor.yaml`. "
             f"{rows[0]['episodes']} episodes per setting: the 8 start poses on each of "
             f"{len(seeds)} seeds ({', '.join(map(str, seeds))}), each seed on its own arm; cap "
             f"{rows[0]['max_steps']} steps, a failed episode counts as the cap. The interval is "
             f"over episodes (independent draws). Speed: {speed(results)}.", ""]
    rows_text = []
    for r in rows:
        capped = stats.mean_interval(np.minimum(r["steps"], cap))
        mark = " (the bar)" if bar is not None and r["label"] == bar.label else ""
        rows_text.append([r["label"] + mark, str(r["episodes"]), f"{r['success_rate']:.0%}",
                          stats.format_interval(capped), fmt(r["median_steps"]),
                          str(sum(n >= r["max_steps"] for n in r["steps"]))])
    lines += table(["residual", "episodes", "inserted", "mean steps [95 % CI]",
                    "median", "failures at the cap"], rows_text)
    lines += ["", "![random baselines](figures/exp1_random_steps.png)", ""]
    return lines


# --- experiments 2-4 ---------------------------------------------------------------------------
def paired_line(results: list[dict[str, Any]], what: str
                ) -> tuple[str, stats.PairedComparison | None]:
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


def grid_section(title: str, rows: list[dict[str, Any]], results: list[dict[str, Any]],
                 bar: Bar | None) -> list[str]:
    """Section 2 (or 2b): mean test steps per cell and algorithm, the cells beating random and
    the paired comparison."""
    if not rows:
        return [title, "", "No runs saved (the budget above says what the profile plans).", ""]
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
             f"bar ({bar_text(bar)}). Speed: {speed(results)}.", ""]
    lines += grid_table(rows, "")[2:]
    lines += ["", "Cells beating random: " + ", ".join(
        f"{label(a)} {wins[a]} of {counts[a]}" for a in algorithms) + ".", ""]
    lines += [paired_line(results, "this grid")[0], ""]
    return lines


def _best_and_worst(results: list[dict[str, Any]], rows: list[dict[str, Any]]
                    ) -> dict[str, tuple[str, str, list[dict[str, Any]]]]:
    """Best and worst cell of each algorithm (by mean test steps) -> their runs."""
    chosen: dict[str, tuple[str, str, list[dict[str, Any]]]] = {}
    for a in sorted({r["algorithm"] for r in rows}):
        mine = sorted((r for r in rows if r["algorithm"] == a and r["reward"] == "dense"
                       and r["replay_capacity"] is None), key=lambda r: r["mean_test_steps"])
        for tag, row in (("best", mine[0]), ("worst", mine[-1])):
            runs = [x for x in results if x["spec"]["algorithm"] == a
                    and x["spec"]["critic_lr"] == row["critic_lr"]
                    and x["spec"]["iterations"] == row["iterations"]]
            chosen[f"{label(a)} {tag} (lr {row['critic_lr']:g}, {row['iterations']} it)"] = \
                (a, tag, runs)
    return chosen


def learning_curves_section(results: list[dict[str, Any]], rows: list[dict[str, Any]],
                            figures: Path, bar: Bar | None) -> list[str]:
    """The learning curves of the best and worst cell of each algorithm (figure and caption)."""
    if not rows:
        return []
    plots.learning_curves(_best_and_worst(results, rows), results[0]["spec"]["train_episodes"],
                          bar, figures / "exp2_learning_curves.png")
    return ["Learning curves of the best and worst cell of each algorithm (mean over seeds, "
            "shaded: standard deviation of the mean; grey: the random bar measured on the same "
            "seeds, with its interval):", "",
            "![learning curves](figures/exp2_learning_curves.png)", ""]


def divergence_text(results: list[dict[str, Any]], gamma: float) -> str:
    """``Diverged (overshot) runs: DDPG 5 (0) of 40; ...``."""
    counts = divergence_counts(results, gamma)
    return "Diverged (overshot) runs: " + "; ".join(
        f"{label(a)} {d} ({o}) of {n}" for a, (d, o, n) in counts.items()) + "."


def q_section(results: list[dict[str, Any]], rows: list[dict[str, Any]], figures: Path,
              q_range: tuple[float, float], gamma: float) -> list[str]:
    """Section 3: the mean predicted Q of the best and worst cells, and the diverged runs."""
    if not rows:
        return []
    plots.mean_q(_best_and_worst(results, rows), q_range, figures / "exp3_mean_q.png")
    lines = ["## 3. Mean predicted Q during training", "",
             "Mean of the critic's predictions on each cycle's minibatches (averaged over the "
             "cycle's iterations), best and worst cell of each algorithm by mean test steps. "
             f"The realisable range of the dense and sparse rewards is [{q_range[0]:g}, "
             f"{q_range[1]:g}]. A run's mean Q counts as diverged when it leaves that range by "
             f"more than a tenth of its width, as overshot when by less.", "",
             "![mean Q](figures/exp3_mean_q.png)", ""]
    return lines + [divergence_text(results, gamma), ""]


def variant_section(results: list[dict[str, Any]], bar: Bar | None,
                    gamma: float) -> list[str]:
    """Section 4: each variant's cells and its paired comparison."""
    lines = ["## 4. Where the thesis says the graph matters: sparse reward, a 300-transition "
             "replay memory, the discount 0.99", ""]
    if not results:
        return lines + ["Not run in this profile (see the budget table).", ""]
    cells = sorted({(r["spec"]["critic_lr"], r["spec"]["iterations"]) for r in results})
    lrs, its = sorted({lr for lr, _ in cells}), sorted({it for _, it in cells})
    if len(cells) > 1 and len(cells) == len(lrs) * len(its):      # every cell of a grid
        where = (f"on all {len(cells)} cells (critic lr {', '.join(f'{lr:g}' for lr in lrs)}; "
                 f"{', '.join(map(str, its))} iterations per cycle)")
    else:
        where = "at the fixed cells " + ", ".join(f"lr {lr:g} / {it} iterations"
                                                  for lr, it in cells)
    lines += [f"The grid's protocol with one setting changed, {where}, both algorithms on the "
              "same seeds. Cells as in the grid's table.", ""]
    for name, group in grid.by_variant(results, gamma).items():
        rows = grid.cell_table(group, None if bar is None else bar.mean)
        lines += grid_table(rows, f"**{name}**")
        lines += ["", paired_line(group, f"{name}")[0], ""]
    return lines
