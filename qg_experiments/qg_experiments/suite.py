"""The whole experiment set of one profile: run what is missing, then write the report.

Random baselines, the grid, the variants of experiment 4 (at fixed cells), the grid with the
thesis's state and the peg runs (free and on the Nextage) are independent and share one pool of
workers (a process per core, or Ray: ``tasks.BACKENDS``).
Results land in ``<out>/<profile>/<experiment>/`` and wall times in ``timing.json`` there; each
is kept as well in ``<docs>/data/<profile>/archived_runs/`` (``run_archive``), from which a
fresh clone restores them before it runs or reports anything.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from qg_experiments import grid, random_baselines, report
from qg_experiments.profile import Profile
from qg_experiments.report.peg_block import peg_specs_of
from qg_experiments.run_archive import archive_folder
from qg_experiments.tasks import DEFAULT_WORKERS, restore_archived, run_specs, unsaved

__all__ = ["EXPERIMENTS", "run_suite", "all_specs", "planned_runs", "current_runs", "restore"]

EXPERIMENTS = ("random", "grid", "variants", "state_grid", "peg", "nextage")


def all_specs(profile: Profile, only: tuple[str, ...] = EXPERIMENTS,
              config_dir: str | None = None) -> list[Any]:
    """The runs of ``profile`` selected by ``only``, longest first (the workers then finish
    closer together)."""
    specs: list[Any] = []
    arm = profile.arm
    if "state_grid" in only and profile.state_grid is not None:  # failures run to the caps
        specs += grid.grid_specs(profile.state_grid, profile.estimator, config_dir, arm,
                                 experiment="state_grid")
    if "grid" in only:
        specs += grid.grid_specs(profile.grid, profile.estimator, config_dir, arm)
    if "variants" in only:
        specs += grid.variant_specs(profile.grid, profile.variants, profile.estimator,
                                    config_dir, arm)
    for experiment in ("nextage", "peg"):     # the Nextage is slower per step than the free peg
        if experiment in only:
            learners, randoms = peg_specs_of(profile, experiment, config_dir)
            specs += learners + randoms
    if "random" in only:
        specs += random_baselines.baseline_specs(profile.random, profile.estimator, config_dir,
                                                 arm)
    return specs


def _record_time(out: Path, key: str, seconds: float, command: str) -> None:
    path = out / "timing.json"
    timing = json.loads(path.read_text()) if path.exists() else {}
    timing[key] = {"wall_time": seconds, "command": command,
                   "finished": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    path.write_text(json.dumps(timing, indent=1))


def run_suite(profile: Profile, out: Path, docs: Path, only: tuple[str, ...] = EXPERIMENTS,
              workers: int = DEFAULT_WORKERS, command: str = "",
              config_dir: str | None = None, backend: str = "process",
              address: str | None = None) -> Path:
    """Run the selected experiments of ``profile`` (resuming saved runs) and write the report.

    :param workers, backend, address: where the runs execute (``tasks.run_specs``).
    :returns: the written ``results.md``.
    """
    out = Path(out) / profile.name
    out.mkdir(parents=True, exist_ok=True)
    archive = archive_folder(Path(docs), profile.name)
    restore(profile, out, archive, config_dir)
    start = time.perf_counter()
    specs = all_specs(profile, only, config_dir)
    step = "+".join(only)
    # A step whose runs are all saved keeps the time recorded when they ran.
    if specs and unsaved(specs, out):
        run_specs(specs, out, workers, f"{profile.name}: {step}", backend, address, archive)
        _record_time(out, step, time.perf_counter() - start, command)
    return report.write_report(profile, out, Path(docs), config_dir, planned_runs(profile),
                               current_runs(profile, config_dir))


def restore(profile: Profile, out: Path, archive: Path, config_dir: str | None = None) -> None:
    """Restore into ``out`` the archived runs of ``profile`` it lacks (``run_archive``), and
    say how many."""
    restored = restore_archived(all_specs(profile, EXPERIMENTS, config_dir), out, archive)
    if restored:
        print(f"{profile.name}: {len(restored)} finished run(s) restored from {archive}",
              flush=True)


def current_runs(profile: Profile, config_dir: str | None = None) -> dict[str, set[str]]:
    """Names of the runs ``profile`` makes now, per experiment: what the report shows.

    A saved run of an earlier setting (another observation, say) stays in ``out`` for reference
    but is not one of these, so it does not mix into a cell.
    """
    names: dict[str, set[str]] = {}
    for spec in all_specs(profile, EXPERIMENTS, config_dir):
        names.setdefault(spec.experiment, set()).add(spec.name)
    return names


def planned_runs(profile: Profile) -> dict[str, int]:
    """How many runs each experiment of ``profile`` has when it is complete."""
    counts: dict[str, int] = {}
    for spec in all_specs(profile):
        counts[spec.experiment] = counts.get(spec.experiment, 0) + 1
    return counts
