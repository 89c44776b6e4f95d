"""Runs read back from the episode rows the report keeps beside the page.

The report writes every episode of every run to ``docs/data/<profile>/<experiment>_episodes.csv``
(``report.tables.episodes_csv``); the runs' own JSON stays in the runs' folder, outside version
control. A peg run's learning curve, first insertion, returns and divergence (the mean Q after
each episode's updates) are all in its rows; only its final Q (thesis Fig. 8.3's spread across
seeds), its timing and its commit are not. So a peg run whose JSON a reset machine took is read
back from its rows rather than run again for twenty minutes of a core: runs are deterministic
per seed (the rerun of ``ddpg_lr0.0001_s102`` gave its 300 rows again to the last digit).

Rows alone do not say which run made them, and a profile edited since (another number of
updates, another config file) names its runs alike. So beside the CSV the report keeps each
run's identity (``<csv>.runs.json``: its spec, config digest and task settings, the
``run_identity`` test saved runs meet), and a run is read back only where that is the identity
of the profile's spec on this machine and every one of its episodes is in the rows. It is marked
``source: ROWS``.
"""
from __future__ import annotations

import csv
import dataclasses
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from qg_experiments.run_identity import is_run_of

__all__ = ["ROWS", "identities_path", "runs_from_rows", "with_rows"]

#: A run's ``source`` when it was read back from its episode rows.
ROWS = "episode rows"


def identities_path(rows: Path) -> Path:
    """Where the identities of the runs of the episode rows at ``rows`` are kept."""
    return Path(rows).with_suffix(".runs.json")


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
    """The runs of ``specs`` whose every episode the CSV at ``path`` holds, made by that spec
    on this machine's config (``identities_path``), shaped as a saved run (``experiment``,
    ``name``, ``spec``, ``config_digest``, ``task_settings``, a random policy's ``label``,
    ``episodes``), with none of what rows do not keep; none without the files.

    :param specs: run specs with ``name``, ``experiment`` and ``episodes`` (``peg.PegRunSpec``,
        ``peg.PegRandomSpec``).
    """
    ids = identities_path(path)
    if not Path(path).is_file() or not ids.is_file():
        return []
    identities = json.loads(ids.read_text())
    by_name = {spec.name: spec for spec in specs
               if spec.name in identities and is_run_of(identities[spec.name], spec)}
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
        identity = identities[name]
        run = {"experiment": spec.experiment, "name": name, "spec": dataclasses.asdict(spec),
               "config_digest": identity["config_digest"],
               "task_settings": identity["task_settings"], "episodes": kept, "source": ROWS}
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
