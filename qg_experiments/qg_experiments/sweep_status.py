"""Where a sweep stands, read from its results folder while it runs (or after it stopped).

A thesis-budget sweep runs for hours; its progress bar counts finished runs only, and it may run
in the background of another terminal or machine. ``python -m qg_experiments --status`` reads
what the sweep leaves in ``<out>/<profile>``: the saved runs (``tasks``: a run is saved only with
its present spec, config digest and task settings) and the progress files of the runs under way
(``run_progress.peek``: episodes done, wall time so far). What is left is estimated from the
saved runs' mean CPU time, per experiment (their wall time where none recorded it).
"""
from __future__ import annotations

from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from qg_experiments.run_progress import peek, progress_path
from qg_experiments.tasks import saved_result

__all__ = ["sweep_status"]


def _time_a_run(saved: Sequence[dict[str, Any]]) -> float:
    """[s] a saved run's mean CPU time, over the runs that recorded it. A run saved before runs
    recorded their CPU, or continued from a progress file without it, has only its wall time,
    which counts every pause of the sweep (for the thesis peg: 36-59 min against 17-25 of CPU),
    so it is counted only when no run recorded its CPU."""
    timed = [r["cpu_time"] for r in saved if r.get("cpu_time")]
    return float(np.mean(timed or [r["wall_time"] for r in saved]))


def sweep_status(specs: Sequence[Any], out: Path, workers: int,
                 rows: Collection[str] = ()) -> list[str]:
    """Per experiment of ``specs``: runs saved, under way (with their episodes) and waiting,
    and the worker time left; last, the time left on ``workers`` workers.

    :param out: the profile's results folder (``<out>/<profile>``).
    :param rows: the names of runs whose episode rows the page already reports
        (``report.peg_block.peg_rows``): of those not saved, how many run again only for what
        rows lack (the final Q, the timing).
    """
    lines, left_total = [], 0.0
    by_experiment: dict[str, list[Any]] = {}
    for spec in specs:
        by_experiment.setdefault(spec.experiment, []).append(spec)
    for experiment, group in by_experiment.items():
        saved = [r for r in (saved_result(out, s) for s in group) if r is not None]
        done = {r["name"] for r in saved}
        under_way = [(s, header) for s in group if s.name not in done
                     for header in [peek(progress_path(out, s))] if header is not None]
        waiting = len(group) - len(saved) - len(under_way)
        lines.append(f"{experiment}: {len(saved)} of {len(group)} runs saved, "
                     f"{len(under_way)} under way, {waiting} waiting")
        reported = sum(s.name in rows for s in group if s.name not in done)
        if reported:
            lines.append(f"  {reported} of the {len(group) - len(saved)} not saved are reported "
                         f"from their episode rows; they run again for their final Q and timing")
        for spec, header in under_way:
            lines.append(f"  {spec.name}: episode {header['done']} of {header['of']}, "
                         f"{header['wall_time'] / 60:.1f} min so far")
        if len(saved) == len(group):
            continue
        if not saved:
            lines.append("  left: unknown until one of its runs is saved")
            continue
        per_run = _time_a_run(saved)
        left = per_run * (waiting + sum(1 - h["done"] / h["of"] for _, h in under_way))
        left_total += left
        lines.append(f"  left: ~{left / 3600:.1f} worker-hours ({per_run / 60:.1f} min a "
                     f"saved run)")
    if left_total:
        lines.append(f"left in all: ~{left_total / 3600 / workers:.1f} h on {workers} "
                     f"worker(s), at the saved runs' pace")
    return lines
