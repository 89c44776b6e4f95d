"""Section 7b of ``docs/results.md``: over all cells of each setting, the statistics a reviewer
expects (Agarwal et al. 2021: interquartile mean, probability of improvement, performance
profiles; ``aggregates``), one verdict per setting with Holm's correction over the settings, and
robustness as the thesis frames it (each cell's mean test steps, the cells beating random)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import label

from qg_experiments import aggregates, grid, stats
from qg_experiments.profile import Statistics
from qg_experiments.random_baselines import Bar
from qg_experiments.report import plots
from qg_experiments.report.markdown import table

__all__ = ["Judged", "judge", "verdict_sentence", "aggregate_section"]

#: Thresholds of the performance profiles: this many points from 0 to the test cap.
PROFILE_POINTS = 101
#: The verdicts (``stats.VERDICTS``, A = QG-DDPG, B = DDPG) in the table.
_VERDICT_NAMES = dict(zip(stats.VERDICTS, ("QG-DDPG better", "DDPG better", "equivalent",
                                           "undecided")))


@dataclass(frozen=True)
class Judged:
    """One setting's paired comparison of QG-DDPG (A) against DDPG (B) and its verdict.

    :param comparison: the paired test steps (``stats.paired_comparison``).
    :param equivalence: the TOST p-value at the margin, before adjustment.
    :param difference_p, equivalence_p: the Wilcoxon and TOST p-values after Holm's correction
        over the settings judged together.
    :param verdict: one of ``stats.VERDICTS``.
    :param pairs_needed, spread: the pairs that would detect the observed difference at 80 %
        power and the differences' standard deviation (``stats.pairs_to_detect``).
    """
    setting: str
    comparison: stats.PairedComparison
    equivalence: float
    difference_p: float
    equivalence_p: float
    verdict: str
    pairs_needed: float
    spread: float


def judge(settings: dict[str, list[dict[str, Any]]], statistics: Statistics) -> list[Judged]:
    """The verdict of every setting with paired runs; the Wilcoxon p-values form one Holm
    family, the TOST p-values another."""
    compared = []
    for name, results in settings.items():
        qg, ddpg, keys = grid.pairs(results)
        if keys:
            compared.append((name, stats.paired_comparison(qg, ddpg),
                             stats.equivalence_p(qg, ddpg, statistics.equivalence_margin),
                             stats.pairs_to_detect(qg, ddpg, statistics.level)))
    if not compared:
        return []
    difference = stats.holm([c.wilcoxon_p for _, c, _, _ in compared])
    equivalence = stats.holm([e for _, _, e, _ in compared])
    return [Judged(name, c, e, dp, ep, stats.verdict(c.difference.mean, dp, ep, statistics.level),
                   *needed)
            for (name, c, e, needed), dp, ep in zip(compared, difference, equivalence)]


def verdict_sentence(j: Judged, statistics: Statistics) -> str:
    """The verdict of one setting in one sentence, with the numbers it rests on."""
    c, margin = j.comparison, statistics.equivalence_margin
    numbers = (f"DDPG minus QG-DDPG {stats.format_interval(c.difference)} test steps per episode "
               f"over {c.n} (cell, seed) pairs; Holm-adjusted: Wilcoxon p = {j.difference_p:.2g}, "
               f"TOST p = {j.equivalence_p:.2g} at ±{margin:g} steps")
    if j.verdict == stats.VERDICTS[0]:
        return f"- {j.setting}: **QG-DDPG needs fewer test steps** ({numbers})."
    if j.verdict == stats.VERDICTS[1]:
        return f"- {j.setting}: **DDPG needs fewer test steps** ({numbers})."
    if j.verdict == stats.VERDICTS[2]:
        return f"- {j.setting}: **equivalent within ±{margin:g} test steps** ({numbers})."
    needed = ("no number of pairs would detect a mean difference of 0"
              if math.isinf(j.pairs_needed) else
              f"about {j.pairs_needed:.0f} pairs would detect a difference this large at 80 % "
              f"power")
    return (f"- {j.setting}: **undecided**, neither a difference nor an equivalence within "
            f"±{margin:g} steps at {statistics.level * 100:g} % ({numbers}). The pairs' "
            f"differences spread by {j.spread:.1f} steps (standard deviation): {needed}.")


def aggregate_section(settings: dict[str, list[dict[str, Any]]], bar: Bar | None,
                      statistics: Statistics, figures: Path) -> list[str]:
    """Section 7b: the aggregate table, the verdicts, the profiles and the cells' means."""
    lines = ["## 7b. Over all cells: aggregate statistics and a verdict per setting", ""]
    judged = judge(settings, statistics)
    if not judged:
        return lines + ["No setting has paired runs of both algorithms.", ""]
    rows, counts, profiles, means = [], [], {}, {}
    cap = max(r["spec"]["test_max_steps"] for results in settings.values() for r in results)
    taus = np.linspace(0.0, cap, PROFILE_POINTS)
    for j in judged:
        qg, ddpg, cells, seeds = grid.score_matrices(settings[j.setting])
        if not qg.size:
            continue
        both = {"qgddpg": qg, "ddpg": ddpg}
        iqm = {a: aggregates.stratified_interval(m) for a, m in both.items()}
        better = aggregates.improvement_interval(-qg, -ddpg)    # fewer steps is better
        rows.append([j.setting, f"{len(cells)} x {len(seeds)}",
                     *[stats.format_interval(iqm[a]) for a in both],
                     stats.format_interval(better, 2), f"{j.difference_p:.2g}",
                     f"{j.equivalence_p:.2g}", _VERDICT_NAMES[j.verdict]])
        profiles[j.setting] = {a: aggregates.profile_band(-m, -taus) for a, m in both.items()}
        means[j.setting] = {a: m.mean(axis=0) for a, m in both.items()}
        if bar is not None:
            cell_rows = [r for r in grid.cell_table(settings[j.setting], bar.mean)
                         if (r["critic_lr"], r["iterations"]) in cells]
            counts.append([j.setting, *[
                f"{stats.format_interval(aggregates.count_below(m, bar.mean), 0)} of {len(cells)} "
                f"({sum(r['beats_random'] for r in cell_rows if r['algorithm'] == a)})"
                for a, m in both.items()]])
    if not rows:
        return lines + ["No setting has a seed complete on every cell for both algorithms.", ""]
    plots.performance_profiles(profiles, taus, figures / "exp7_profiles.png")
    plots.cell_means(means, bar, figures / "exp7_cell_means.png")
    lines += [f"Per setting, every run of both algorithms on the cells and seeds both completed "
              f"(cells x seeds). *IQM*: the interquartile mean of the runs' mean test steps "
              f"over all cells and seeds, with its 95 % stratified-bootstrap interval (seeds "
              f"resampled within each cell, {stats.RESAMPLES:,} resamples). *P(QG-DDPG better)*: "
              "the probability that a QG-DDPG run needs fewer test steps than a DDPG run of the "
              "same cell, averaged over cells (ties count half), with its interval. The paired "
              "test is the Wilcoxon signed-rank test over the (cell, seed) pairs; the "
              f"equivalence test is TOST (two one-sided Wilcoxon tests) at a margin of "
              f"±{statistics.equivalence_margin:g} test steps per episode "
              "(`config/experiments.yaml`, `statistics`); both p-values are Holm-corrected over "
              f"the {len(judged)} settings, and a verdict needs p < {statistics.level:g}. "
              "Estimators: `qg_experiments/aggregates.py` (rliable's, on NumPy/SciPy).", ""]
    lines += table(["setting", "cells x seeds", "IQM QG-DDPG [95 % CI]", "IQM DDPG [95 % CI]",
                    "P(QG-DDPG better) [95 % CI]", "Wilcoxon p (Holm)", "TOST p (Holm)",
                    "verdict"], rows)
    lines += ["", "Verdicts:", ""] + [verdict_sentence(j, statistics) for j in judged] + [""]
    lines += ["Performance profiles: the fraction of runs whose mean test steps are at most tau "
              "(higher and further left is better), with pointwise 95 % bands:", "",
              "![performance profiles](figures/exp7_profiles.png)", "",
              "Robustness as the thesis frames it: each cell's mean test steps (over seeds and "
              "test episodes), per setting and algorithm, against the random bar:", "",
              "![cell means](figures/exp7_cell_means.png)", ""]
    if counts:
        lines += ["Cells whose mean test steps lie below the random bar's mean, with the 95 % "
                  "stratified-bootstrap interval of that count (seeds resampled within each "
                  "cell); in brackets the cells whose whole interval lies below the bar (the "
                  "tables' bold cells):", ""]
        lines += table(["setting", f"{label('qgddpg')} cells below the bar",
                        f"{label('ddpg')} cells below the bar"], counts) + [""]
    return lines
