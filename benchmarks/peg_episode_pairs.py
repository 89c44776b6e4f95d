"""The thesis peg's paired numbers per run and seed, from what the repository keeps: archived runs
and episode rows.

results.md section 5 (``python -m qg_experiments.peg_report``) reports the same runs: each one
archived whole (``docs/data/thesis/archived_runs/peg``, ``qg_experiments.run_archive``) or, when
a reset machine took its JSON, read back from its episode rows (``docs/data/thesis/
peg_episodes.csv``, ``qg_experiments.episode_rows``). This script prints, per learning rate, the
paired measures of the section's table (QG-DDPG against DDPG over all episodes and over the last
60: wins, difference with its 95 % interval, Wilcoxon p, Holm over the learning rates with
pairs) and, seed by seed, what the section summarises: each run's first insertion, the share
inserted late and the diverged critics; Fig. 8.3's spread of the final Q (only in whole runs)
over the paired seeds archived whole; then each learner against the better random policy on
the same seeds. Nothing is written. The last line is JSON.

Usage: python benchmarks/peg_episode_pairs.py [--docs docs]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from qg_experiments import stats
from qg_experiments.episode_rows import ROWS, with_rows
from qg_experiments.profile import load_profile
from qg_experiments.report import peg_sections
from qg_experiments.report.peg_block import peg_specs_of
from qg_experiments.run_archive import archive_folder, archived_result

TAIL = 60          # results.md's late window: the last fifth of 300 episodes


def kept_runs(docs: Path, specs: list[Any], csv: str) -> list[dict[str, Any]]:
    """The runs of ``specs`` archived whole under ``docs``, and the others' episode rows."""
    archive = archive_folder(docs, "thesis")
    whole = [run for spec in specs if (run := archived_result(archive, spec)) is not None]
    return with_rows(whole, docs / "data" / "thesis" / csv, specs)


def first_insertion(run: dict[str, Any]) -> int | None:
    """The episode (counted from 1) of the run's first insertion, None if it never inserted."""
    return next((i + 1 for i, e in enumerate(run["episodes"]) if e["success"]), None)


def mean_of(run: dict[str, Any], field: str, first: int = 0) -> float:
    """The mean of ``field`` over the run's episodes from index ``first`` (negative: the last)."""
    return float(np.mean([e[field] for e in run["episodes"][first:]]))


def q_spread_lines(pairs: peg_sections.PegPairs, lr: float) -> list[str]:
    """Fig. 8.3 at ``lr``: the median across points of each algorithm's std of the final Q over
    the paired seeds whose whole runs are kept, and at how many points QG-DDPG's is the
    smaller, for the given actions and for each run's own actor's action."""
    seeds = pairs.spread_seeds[lr]
    lines = []
    for points, label in (("given", "the given actions"), ("pi", "the actor's action")):
        q = pairs.spreads(lr, points)
        if q is None:
            return [f"Q spread: fewer than two paired seeds with their final Q ({len(seeds)})"]
        lines.append(f"Q spread over seeds {', '.join(map(str, seeds))}, {label}: median "
                     f"QG-DDPG / DDPG {np.median(q['qgddpg']):.3g} / {np.median(q['ddpg']):.3g}"
                     f"; QG-DDPG's the smaller at {int(np.sum(q['qgddpg'] < q['ddpg']))} of "
                     f"{q['ddpg'].size} points")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--docs", type=Path, default=Path("docs"))
    args = parser.parse_args()
    learners, random_specs = peg_specs_of(load_profile("thesis"), "peg")
    results = kept_runs(args.docs, learners, "peg_episodes.csv")
    sources = {"csv": sum(r.get("source") == ROWS for r in results)}
    sources["archive"] = len(results) - sources["csv"]
    print(f"{len(results)} runs: {sources['csv']} from the episode CSV, "
          f"{sources['archive']} archived")
    pairs = peg_sections.peg_pairs(results, TAIL)
    assert pairs is not None, "no learning rate has a pair"
    per_run = {"first": peg_sections.per_pair(results, first_insertion),
               "late_inserted": peg_sections.per_pair(
                   results, lambda r: mean_of(r, "success", -TAIL)),
               "diverged": peg_sections.per_pair(results, peg_sections.peg_diverged),
               "all_return": peg_sections.per_pair(results, lambda r: mean_of(r, "return"))}
    summary: dict[str, Any] = {"runs": sources, "learning_rates": {}}
    for lr in pairs.lrs:
        seeds = list(pairs.diverged[lr])
        entry: dict[str, Any] = {"seeds": seeds}
        print(f"lr {lr:g}: {len(seeds)} pairs (seeds {', '.join(map(str, seeds))})")
        for name in ("all", "late"):
            c, holm = pairs.compared[name][lr], pairs.holm[name][lr]
            print(f"  {name}: QG-DDPG higher / DDPG higher / ties {c.wins_a} / {c.wins_b} / "
                  f"{c.ties}; QG-DDPG - DDPG {stats.format_interval(c.difference, 2)}; "
                  f"Wilcoxon p {c.wilcoxon_p:.3g}, Holm {holm:.3g}")
            entry[name] = {"wins": [c.wins_a, c.wins_b, c.ties],
                           "difference": c.difference.mean, "low": c.difference.low,
                           "high": c.difference.high, "p": c.wilcoxon_p, "holm": holm}
        for algorithm in ("qgddpg", "ddpg"):
            row = {key: [values[lr][s][algorithm] for s in seeds]
                   for key, values in per_run.items()}
            print(f"  {algorithm}: first insertion {row['first']}; late inserted "
                  f"{100 * np.mean(row['late_inserted']):.0f} %; diverged "
                  f"{sum(row['diverged'])} of {len(seeds)}; mean return over all episodes "
                  f"{np.mean(row['all_return']):.1f}")
            entry[algorithm] = row
        entry["q_spread"] = q_spread_lines(pairs, lr)
        print("\n".join(f"  {line}" for line in entry["q_spread"]))
        summary["learning_rates"][f"{lr:g}"] = entry
    randoms = kept_runs(args.docs, random_specs, "peg_random_episodes.csv")
    print("\n".join(peg_sections.peg_against_random(results, randoms, TAIL)))
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
