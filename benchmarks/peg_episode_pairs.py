"""The thesis peg's paired numbers from what the repository keeps: episode rows and archived runs.

results.md section 5 is computed from the runs' JSON under ``runs/experiments/thesis``, a folder
outside version control; a reset machine took with it the 34 runs finished by the end of
2026-11-29's fourth session. What survived is their per-episode table (``docs/data/thesis/peg_episodes.csv``: steps,
insertion, return and mean Q of every episode) and, since, every finished run archived whole
(``docs/data/thesis/archived_runs/peg``, ``qg_experiments.run_archive``). This script joins the
two (an archived run wins over its CSV rows) and prints, per learning rate, the measures of
results.md's paired table that episode rows give: QG-DDPG against DDPG over all episodes and
over the last 60 (wins, difference with its 95 % interval, Wilcoxon p, Holm over the learning
rates with pairs), each run's first insertion, the share inserted late and the diverged critics;
then results.md's table of each learner against the better random policy on the same seeds
(``peg_random_episodes.csv``, all 20 runs of the random bar). The final Q (Fig. 8.3's
spread across seeds) is only in whole runs: it is printed over the paired seeds whose runs are
archived, with their number. The last line is JSON.

Usage: python benchmarks/peg_episode_pairs.py [--docs docs]
"""
from __future__ import annotations

import argparse
import csv
import gzip
import json
from pathlib import Path
from typing import Any

import numpy as np
from qg_experiments import stats
from qg_experiments.peg import PegRandomSpec
from qg_experiments.report import peg_sections
from qg_experiments.run_archive import archive_folder

TAIL = 60          # results.md's late window: the last fifth of 300 episodes


def _run_of(name: str, gamma: float) -> dict[str, Any]:
    """An empty run named ``name``: a learner's ``<algorithm>_lr<lr>_s<seed>`` or a random
    policy's ``random_<kind>_s<seed>`` (``PegRunSpec.name``, ``PegRandomSpec.name``)."""
    first, middle, seed = name.split("_")
    if first == "random":
        spec = PegRandomSpec(kind=middle, seed=int(seed[1:]))
        return {"spec": {"kind": middle, "seed": spec.seed}, "label": spec.label, "episodes": []}
    return {"spec": {"algorithm": first, "lr": float(middle[2:]), "seed": int(seed[1:]),
                     "gamma": gamma}, "episodes": []}


def csv_runs(path: Path, gamma: float = 0.99) -> dict[str, dict[str, Any]]:
    """The runs of an episodes CSV (``run,episode,steps,success,return[,mean_q]``), by name."""
    runs: dict[str, dict[str, Any]] = {}
    with open(path) as rows:
        for row in csv.DictReader(rows):
            run = runs.setdefault(row["run"], _run_of(row["run"], gamma))
            run["episodes"].append({"episode": int(row["episode"]), "steps": int(row["steps"]),
                                    "success": row["success"] == "True",
                                    "return": float(row["return"]),
                                    **({"mean_q": float(row["mean_q"])} if "mean_q" in row
                                       else {})})
    for run in runs.values():
        run["episodes"].sort(key=lambda e: e["episode"])
    return runs


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
    runs = {name: {**run, "source": "csv"}
            for name, run in csv_runs(args.docs / "data" / "thesis" / "peg_episodes.csv").items()}
    for path in sorted((archive_folder(args.docs, "thesis") / "peg").glob("*.json.gz")):
        run = json.loads(gzip.decompress(path.read_bytes()))
        runs[run["name"]] = {**run, "source": "archive"}
    results = list(runs.values())
    sources = {s: sum(r["source"] == s for r in results) for s in ("csv", "archive")}
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
    randoms = list(csv_runs(args.docs / "data" / "thesis" / "peg_random_episodes.csv").values())
    print("\n".join(peg_sections.peg_against_random(results, randoms, TAIL)))
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
