"""Runs read back from the episode rows the report keeps beside the page.

The report writes every episode of every run to ``docs/data/<profile>/<experiment>_episodes.csv``
(``report.tables.episodes_csv``); the runs' own JSON stays in the runs' folder, outside version
control. A peg run's learning curve, first insertion, returns and divergence (the mean Q after
each episode's updates) are all in its rows; only its final Q (thesis Fig. 8.3's spread across
seeds), its timing and its commit are not. So a peg run whose JSON a reset machine took is read
back from its rows rather than run again for twenty minutes of a core: runs are deterministic
per seed (the rerun of ``ddpg_lr0.0001_s102`` gave its 300 rows again to the last digit).

Such a run is marked ``source: ROWS``; only a run of the profile's specs with every one of its
episodes in the rows is read back.
"""
from __future__ import annotations

import csv
import dataclasses
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["ROWS", "runs_from_rows", "with_rows"]

#: A run's ``source`` when it was read back from its episode rows.
ROWS = "episode rows"


def _value(text: str) -> Any:
    """A CSV cell as the episode dict had it: a bool, an int, a float, else the text."""
    if text in ("True", "False"):
        return text == "True"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def runs_from_rows(path: Path, specs: Iterable[Any]) -> list[dict[str, Any]]:
    """The runs of ``specs`` whose every episode the CSV at ``path`` holds, shaped as a saved
    run (``experiment``, ``name``, ``spec``, a random policy's ``label``, ``episodes``), with
    none of what rows do not keep; none without the file.

    :param specs: run specs with ``name``, ``experiment`` and ``episodes`` (``peg.PegRunSpec``,
        ``peg.PegRandomSpec``).
    """
    by_name = {spec.name: spec for spec in specs}
    if not Path(path).is_file():
        return []
    episodes: dict[str, list[dict[str, Any]]] = {}
    with open(path, newline="") as rows:
        for row in csv.DictReader(rows):
            if row["run"] in by_name:
                episodes.setdefault(row["run"], []).append(
                    {key: _value(text) for key, text in row.items() if key != "run" and text})
    runs = []
    for name, kept in sorted(episodes.items()):
        spec = by_name[name]
        kept.sort(key=lambda e: e["episode"])
        if [e["episode"] for e in kept] != list(range(spec.episodes)):
            continue                                 # a run cut short is not a run
        run = {"experiment": spec.experiment, "name": name, "spec": dataclasses.asdict(spec),
               "episodes": kept, "source": ROWS}
        if hasattr(spec, "label"):
            run["label"] = spec.label
        runs.append(run)
    return runs


def with_rows(results: list[dict[str, Any]], path: Path, specs: Iterable[Any]
              ) -> list[dict[str, Any]]:
    """``results`` and, for each of ``specs`` without a saved run there, the run read back from
    its episode rows at ``path`` (``runs_from_rows``), sorted by name as saved runs are."""
    saved = {r["name"] for r in results}
    missing = [spec for spec in specs if spec.name not in saved]
    return sorted([*results, *runs_from_rows(path, missing)], key=lambda r: r["name"])
