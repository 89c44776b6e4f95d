"""Section 7 and the closing comparison of ``docs/results.md``: QG-DDPG against DDPG setting by
setting (paired tests, the random bar, divergence, what the graph did), and where our numbers
agree and disagree with the thesis."""
from __future__ import annotations

from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import COMPARED, label

from qg_experiments import grid, stats
from qg_experiments.random_baselines import Bar
from qg_experiments.report.divergence import divergence_counts, run_divergence
from qg_experiments.report.grid_sections import THESIS, divergence_text, paired_line
from qg_experiments.report.markdown import fmt, table
from qg_experiments.stalls import LAST_TRAINING, TRAINED_AT, recovery_text, stall_counts

__all__ = ["graph_section", "comparison"]

#: The columns' order: QG-DDPG first, as the page compares it against DDPG.
_PAIR = tuple(reversed(COMPARED))


def graph_section(settings: dict[str, list[dict[str, Any]]], bar: Bar | None,
                  gamma: float) -> list[str]:
    """One row per setting: the paired comparison, the cells beating random, divergence, and
    what the graph did (targets raised, critic error against the Monte-Carlo return)."""
    rows_text = []
    for name, results in settings.items():
        if not results:
            continue
        _, comparison = paired_line(results, name)
        rows = grid.cell_table(results, None if bar is None else bar.mean)
        wins = {a: (sum(r["beats_random"] for r in rows if r["algorithm"] == a),
                    sum(1 for r in rows if r["algorithm"] == a)) for a in _PAIR}
        counts = divergence_counts(results, gamma)
        diag = {a: grid.graph_diagnostics([r for r in results if r["spec"]["algorithm"] == a])
                for a in _PAIR}
        stalls = stall_counts((r["spec"]["algorithm"], r["episodes"]) for r in results)
        rows_text.append([
            name, "—" if comparison is None else str(comparison.n),
            "—" if comparison is None else f"{comparison.wins_a} / {comparison.wins_b} / "
                                           f"{comparison.ties}",
            "—" if comparison is None else stats.format_interval(comparison.difference),
            "—" if comparison is None else f"{comparison.wilcoxon_p:.3g}",
            *[f"{wins[a][0]} of {wins[a][1]}" for a in _PAIR],
            *[f"{counts.get(a, (0, 0, 0))[0]} of {counts.get(a, (0, 0, 0))[2]}"
              for a in _PAIR],
            f"{diag['qgddpg']['targets_raised']:.1%}",
            f"{fmt(diag['qgddpg']['critic_mc_error'], 2)} / "
            f"{fmt(diag['ddpg']['critic_mc_error'], 2)}",
            " / ".join(f"{stalls.get(a, {}).get('stalled_test_episodes', 0)} of "
                       f"{stalls.get(a, {}).get('trained_test_episodes', 0)}" for a in _PAIR),
            " / ".join(recovery_text(stalls.get(a, {})) for a in _PAIR)])
    lines = ["## 7. QG-DDPG against DDPG, setting by setting", "",
             "Per setting: the (cell, seed) pairs of both algorithms; QG-DDPG better / DDPG "
             "better / ties; DDPG minus QG-DDPG in mean test steps with its 95 % interval "
             "(positive: QG-DDPG needs fewer); the two-sided Wilcoxon signed-rank p; the cells "
             "whose interval lies below the random bar; the runs whose mean Q diverged; the "
             "share of TD targets the graph's lower bound raised (mean over training cycles); "
             "the critic's mean |Q - Monte-Carlo return| on the goal-reaching training "
             "episodes at the end of training (QG-DDPG / DDPG); the stalls of the deterministic "
             f"test actor, the test episodes that failed in runs that trained ({TRAINED_AT} of "
             f"their last {LAST_TRAINING} training episodes inserted), of those runs' test "
             "episodes (QG-DDPG / DDPG; `qg_experiments/stalls.py`, "
             "[learning.md](learning.md) sections 15 and 16); apart from every other number "
             "here, the same runs' test poses once more with stall recovery "
             "(`executor/stall_recovery.py`; only runs saved with `RunSpec.stall_recovery`, "
             "episodes of mode `recovery` that no test number reads): inserted of those "
             "episodes, and the recoveries applied (a dash: no run with recovery).", ""]
    lines += table(["setting", "pairs", "QG / DDPG / ties", "DDPG - QG [95 % CI]",
                    "Wilcoxon p", "QG-DDPG beats random", "DDPG beats random",
                    "QG-DDPG diverged", "DDPG diverged", "targets raised",
                    "critic error vs MC", "stalled test episodes (deterministic actor)",
                    "inserted with stall recovery"], rows_text)
    divergence = _divergence_pairs([r for results in settings.values() for r in results], gamma)
    return lines + ([""] + [divergence] if divergence else []) + [""]


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


def comparison(random_rows: list[dict[str, Any]], bar: Bar | None,
               grids: dict[str, list[dict[str, Any]]], variant_results: list[dict[str, Any]],
               gamma: float) -> list[str]:
    """The closing list: where our numbers agree and disagree with the thesis."""
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
        for a, thesis in zip(_PAIR, (THESIS["qg_cells"], THESIS["ddpg_cells"])):
            mine = [r for r in rows if r["algorithm"] == a]
            if mine:
                notes.append(f"- {title}: {label(a)} beat the random bar (whole interval "
                             f"below it) in {sum(r['beats_random'] for r in mine)} of "
                             f"{len(mine)} cells (thesis, real robot: {thesis} of 8).")
        if results:
            notes.append(f"- {title}: {divergence_text(results, gamma)} (thesis: DDPG "
                         "diverges under bad hyperparameters, QG-DDPG never).")
    for name, group in grid.by_variant(variant_results, gamma).items():
        rows = grid.cell_table(group, None if bar is None else bar.mean)
        text = "; ".join(f"{label(a)} beat random in "
                         f"{sum(r['beats_random'] for r in rows if r['algorithm'] == a)} of "
                         f"{sum(1 for r in rows if r['algorithm'] == a)} cells"
                         for a in _PAIR)
        notes.append(f"- {name}: {text} (thesis: QG-DDPG did, DDPG did not).")
    return notes + [""]
