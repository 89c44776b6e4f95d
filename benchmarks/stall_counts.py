"""How often the deterministic test actor stalls after a run that trained (docs/learning.md
section 15), counted from the saved per-episode data of docs/results.md by
``qg_experiments.stalls`` (results.md section 7 counts them the same way).

A run "trained" when at least ``--trained`` of its last 8 training episodes inserted; a stall is
a test episode of such a run that did not insert (it ran to the test cap). Printed per
experiment (the variants setting by setting) and algorithm: runs, runs trained, runs with a
stall, stalled test episodes of the trained runs, and how many stalled poses the same run had
inserted in training; where runs were saved with stall recovery (names ending in
``_recovery``), their recovery episodes apart: inserted and recoveries.

Usage: python benchmarks/stall_counts.py [--data docs/data/thesis] [--trained 6]
The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import collections
import csv
import json
from pathlib import Path
from typing import Any

from qg_experiments.stalls import TRAINED_AT, stall_counts

EXPERIMENTS = ("grid", "state_grid", "variants")


def setting_of(run: str) -> str:
    """The setting a run's name carries between its cell and its seed (``sparse``, ``g0.99``,
    ``cap300``; empty for the grid): the variants are counted setting by setting. A run tested
    again with stall recovery (``_recovery``) counts in its setting, its recovery apart."""
    return "_".join(part for part in run.split("_")[3:-1] if part != "recovery")


def runs_of(rows: list[dict[str, str]]) -> list[tuple[str, list[dict[str, Any]]]]:
    """The CSV's rows as (algorithm, episodes) per run: the algorithm is the run name's first
    part; pose and success read back from text."""
    runs: dict[str, list[dict[str, Any]]] = collections.defaultdict(list)
    for row in rows:
        runs[row["run"]].append({"mode": row["mode"], "pose": int(row["pose"]),
                                 "success": row["success"] == "True",
                                 "recoveries": int(row.get("recoveries") or 0)})
    return [(name.split("_")[0], episodes) for name, episodes in runs.items()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("docs/data/thesis"))
    parser.add_argument("--trained", type=int, default=TRAINED_AT)
    args = parser.parse_args()
    result = {}
    for experiment in EXPERIMENTS:
        path = args.data / f"{experiment}_episodes.csv"
        if path.exists():
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
            for setting in sorted({setting_of(r["run"]) for r in rows}):
                key = f"{experiment} {setting}".strip()
                result[key] = stall_counts(
                    runs_of([r for r in rows if setting_of(r["run"]) == setting]), args.trained)
                print(f"{key}: {result[key]}")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
