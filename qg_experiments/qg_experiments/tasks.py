"""Runs independent experiment runs on a pool of worker processes or on Ray, saving each as it ends.

Every run is a frozen spec with ``name``, ``experiment`` and ``run() -> dict``; its result goes
to ``<out>/<experiment>/<name>.json`` the moment it finishes, so an interrupted sweep keeps what
it did, and a second call with the same specs skips runs whose saved spec and config digest
(``run_identity``: spec, config digest, task settings) are identical. A long run
(``run_worker.ResumableSpec``) also saves its progress there between episodes and continues from
it (``run_progress``). With an ``archive`` (``run_archive``: beside the report's data,
versioned) each result is kept there too, and ``restore_archived`` brings it back into ``out``
on a fresh machine. Only where a run executes depends on the backend: ``process`` (the default)
is a pool of one process per core on this machine (``worker_pool``), ``ray`` hands the runs to a
Ray cluster (``ray_backend``); a worker of either calls ``run_worker.run_one``.
Skipping, saving, the progress bar and the results are the same code for both.
"""
from __future__ import annotations

import functools
import json
import os
from collections.abc import Collection, Iterable, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from qg_experiments.run_archive import archive_result, archived_path, archived_result
from qg_experiments.run_identity import is_run_of
from qg_experiments.run_progress import progress_path
from qg_experiments.run_worker import RunnableSpec, run_one
from qg_experiments.worker_pool import pool_results

__all__ = ["RunnableSpec", "BACKENDS", "DEFAULT_WORKERS", "result_path", "run_specs",
           "run_one", "load_results", "saved_result", "unsaved", "restore_archived"]

#: Where runs execute: a process pool on this machine, or a Ray cluster (local or remote).
BACKENDS = ("process", "ray")
#: One single-threaded run per core: more processes only thrash.
DEFAULT_WORKERS = os.cpu_count() or 1


def result_path(out: Path, spec: RunnableSpec) -> Path:
    return Path(out) / spec.experiment / f"{spec.name}.json"


def saved_result(out: Path, spec: RunnableSpec) -> dict[str, Any] | None:
    """The saved result of ``spec`` under ``out``, or None: none saved, or one of another
    run (``run_identity``)."""
    path = result_path(out, spec)
    if not path.exists():
        return None
    result = json.loads(path.read_text())
    return result if is_run_of(result, spec) else None


def restore_archived(specs: Sequence[RunnableSpec], out: Path, archive: Path) -> list[str]:
    """Save under ``out`` the archived result (``run_archive``) of each of ``specs`` that has
    none there, when it is of the same run; the names of the runs restored."""
    restored = []
    for spec in specs:   # a stat first: a sweep starts with every run of its profile here
        if not archived_path(archive, spec).exists() or saved_result(out, spec) is not None:
            continue
        result = archived_result(archive, spec)
        if result is not None:
            _save(out, spec, result)
            restored.append(spec.name)
    return restored


def _save(out: Path, spec: RunnableSpec, result: dict[str, Any]) -> None:
    path = result_path(out, spec)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result))


def _pool_results(todo: Sequence[RunnableSpec], workers: int, out: Path
                  ) -> Iterable[tuple[RunnableSpec, dict[str, Any]]]:
    """``(spec, result)`` of each run of ``todo`` as it ends, on ``workers`` local processes
    (``worker_pool``: a worker that dies stops the sweep, naming its run)."""
    run = functools.partial(run_one, out=out)
    yield from map(run, todo) if workers == 1 else pool_results(run, todo, workers)


def unsaved(specs: Sequence[RunnableSpec], out: Path) -> list[RunnableSpec]:
    """The specs that have no saved result under ``out`` (or only one of another setting)."""
    return [spec for spec in specs if saved_result(out, spec) is None]


def run_specs(specs: Sequence[RunnableSpec], out: Path, workers: int = DEFAULT_WORKERS,
              description: str = "runs", backend: str = "process",
              address: str | None = None, archive: Path | None = None) -> list[dict[str, Any]]:
    """Run every spec not already saved under ``out``; results in the order of ``specs``.

    :param workers: runs at a time on this machine: processes of the pool (1 runs in this
        process), or the CPUs of the local Ray; a Ray cluster at ``address`` uses its own CPUs.
    :param backend: one of :data:`BACKENDS`.
    :param address: the Ray cluster to join (``ray`` backend only; None starts a local one).
    :param archive: where each finished result is kept as well (``run_archive``); None: not.
    :raises ValueError: for an unknown backend, or an address without the ``ray`` backend.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if address is not None and backend != "ray":
        raise ValueError(f"a cluster address needs the ray backend, got backend {backend!r}")
    results: dict[str, dict[str, Any]] = {}
    todo = []
    for spec in specs:
        saved = saved_result(out, spec)
        if saved is None:
            todo.append(spec)
        else:
            results[f"{spec.experiment}/{spec.name}"] = saved
    workers = max(1, min(workers, len(todo)))
    continuing = [spec.name for spec in todo if progress_path(out, spec).exists()]
    if continuing:
        print(f"{description}: {len(continuing)} run(s) continue from saved progress "
              f"({', '.join(continuing)})", flush=True)
    bar = tqdm(total=len(specs), initial=len(specs) - len(todo), desc=description, unit="run",
               dynamic_ncols=True)

    def keep(spec: RunnableSpec, result: dict[str, Any]) -> None:
        _save(out, spec, result)
        if archive is not None:
            archive_result(archive, spec, result)
        results[f"{spec.experiment}/{spec.name}"] = result
        bar.set_postfix_str(f"{spec.name} {result['wall_time']:.0f}s")
        bar.update()

    if not todo:
        finished: Iterable[tuple[RunnableSpec, dict[str, Any]]] = ()
    elif backend == "ray":          # imported here: the pool and `qgl` never import ray
        from qg_experiments.ray_backend import ray_results
        finished = ray_results(todo, workers, address, Path(out).resolve())
    else:
        finished = _pool_results(todo, workers, Path(out).resolve())
    for spec, result in finished:
        keep(spec, result)
    bar.close()
    return [results[f"{s.experiment}/{s.name}"] for s in specs]


def load_results(out: Path, experiment: str,
                 names: Collection[str] | None = None) -> list[dict[str, Any]]:
    """The saved results of ``experiment`` under ``out`` (sorted by name).

    :param names: only the runs of these names (``spec.name``), e.g. a profile's current runs,
        so that runs of an earlier setting left in the folder do not mix in; ``None``: all.
    """
    folder = Path(out) / experiment
    return [json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))
            if names is None or p.stem in names]
