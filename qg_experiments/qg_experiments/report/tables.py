"""The report's data beside the page: every table row and every episode as CSV, and the random
bar as JSON (``docs/data/<profile>/``; small and versioned, while the per-run JSON stays under
the runs' folder)."""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np

from qg_experiments.episode_rows import identities_path
from qg_experiments.random_baselines import Bar
from qg_experiments.run_identity import result_identity

__all__ = ["write_csv", "episodes_csv", "write_bar"]


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """``rows`` as CSV, their list-valued columns left out; the columns are every row's keys in
    order of appearance (a key only later rows have, as a recovery episode's ``recoveries``,
    is kept; other rows leave it empty). Without rows there is no file, and one left by earlier
    runs goes: the data beside the page is the page's, never an older step's."""
    if not rows:
        path.unlink(missing_ok=True)
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for row in rows for k, v in row.items()
                              if not isinstance(v, (list, np.ndarray))))
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def episodes_csv(path: Path, results: list[dict[str, Any]]) -> None:
    """Every episode of ``results``, one row each, with its run's name; beside it, each run's
    identity (``episode_rows``: what lets a run whose JSON is gone be read back)."""
    write_csv(path, [{"run": r["name"], **e} for r in results for e in r["episodes"]])
    identities = identities_path(path)
    if path.exists():
        identities.write_text(json.dumps({r["name"]: result_identity(r) for r in results
                                          if "spec" in r}, indent=1, sort_keys=True) + "\n")
    else:
        identities.unlink(missing_ok=True)


def write_bar(path: Path, bar: Bar, seeds: list[int]) -> None:
    """The random bar as JSON: the demo's learning curve draws it (``qgl demo``)."""
    path.write_text(json.dumps(
        {"label": bar.label, "mean": bar.mean, "low": bar.interval.low,
         "high": bar.interval.high, "episodes": bar.interval.n, "cap": bar.cap,
         "seeds": seeds}, indent=1))
