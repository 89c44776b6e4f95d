"""How often the deterministic test actor stalls after a run that trained (docs/learning.md
section 15), counted from the saved per-episode data of docs/results.md.

A run "trained" when at least ``--trained`` of its last 8 training episodes inserted; a stall is
a test episode of such a run that did not insert (it ran to the test cap). Printed per
experiment (the variants setting by setting) and algorithm: runs, runs trained, runs with a
stall, stalled test episodes of the trained runs, and how many stalled poses the same run had
inserted in training.

Usage: python benchmarks/stall_counts.py [--data docs/data/thesis] [--trained 6]
The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import collections
import csv
import json
from pathlib import Path

EXPERIMENTS = ("grid", "state_grid", "variants")


def setting_of(run: str) -> str:
    """The setting a run's name carries between its cell and its seed (``sparse``, ``g0.99``,
    ``cap300``; empty for the grid): the variants are counted setting by setting."""
    return "_".join(run.split("_")[3:-1])


def counts(rows: list[dict[str, str]], trained_at: int) -> dict[str, dict[str, int]]:
    """Per algorithm (the run name's first part), the stall counts of one experiment."""
    runs: dict[str, list[dict[str, str]]] = collections.defaultdict(list)
    for row in rows:
        runs[row["run"]].append(row)
    out: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for name, episodes in runs.items():
        train = [e for e in episodes if e["mode"] == "train"]
        test = [e for e in episodes if e["mode"] == "test"]
        c = out[name.split("_")[0]]
        c["runs"] += 1
        if sum(e["success"] == "True" for e in train[-8:]) < trained_at:
            continue
        stalled = [e for e in test if e["success"] != "True"]
        inserted_in_training = {e["pose"] for e in train if e["success"] == "True"}
        c["trained"] += 1
        c["trained_test_episodes"] += len(test)
        c["stalled_test_episodes"] += len(stalled)
        c["runs_with_a_stall"] += bool(stalled)
        c["stalled_poses_inserted_in_training"] += sum(e["pose"] in inserted_in_training
                                                       for e in stalled)
    return {algorithm: dict(c) for algorithm, c in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("docs/data/thesis"))
    parser.add_argument("--trained", type=int, default=6)
    args = parser.parse_args()
    result = {}
    for experiment in EXPERIMENTS:
        path = args.data / f"{experiment}_episodes.csv"
        if path.exists():
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
            for setting in sorted({setting_of(r["run"]) for r in rows}):
                key = f"{experiment} {setting}".strip()
                result[key] = counts([r for r in rows if setting_of(r["run"]) == setting],
                                     args.trained)
                print(f"{key}: {result[key]}")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
