"""Runs independent experiment runs in at most two worker processes, saving each as it ends.

Every run is a frozen spec with ``name``, ``experiment`` and ``run() -> dict``; its result goes
to ``<out>/<experiment>/<name>.json`` the moment it finishes, so an interrupted sweep keeps what
it did, and a second call with the same specs skips runs whose saved spec and config digest
(see ``runner.config_digest``) are identical.
"""
from __future__ import annotations

import dataclasses
import json
import multiprocessing
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import torch
from tqdm import tqdm

from qg_learning_node.experiments.runner import config_digest

__all__ = ["RunnableSpec", "MAX_WORKERS", "result_path", "run_specs", "load_results"]

#: The machine has two cores; more processes only thrash.
MAX_WORKERS = 2


class RunnableSpec(Protocol):
    name: str
    experiment: str
    config_dir: str | None

    def run(self) -> dict[str, Any]: ...


def result_path(out: Path, spec: RunnableSpec) -> Path:
    return Path(out) / spec.experiment / f"{spec.name}.json"


def _saved(out: Path, spec: RunnableSpec) -> dict[str, Any] | None:
    path = result_path(out, spec)
    if not path.exists():
        return None
    result = json.loads(path.read_text())
    # A spec field added after a run was saved, at its default, leaves that run the same run.
    defaults = {f.name: f.default for f in dataclasses.fields(spec)
                if f.default is not dataclasses.MISSING}
    saved_spec = json.loads(json.dumps({**defaults, **result.get("spec", {})}))
    same = (saved_spec == json.loads(json.dumps(dataclasses.asdict(spec)))
            and result.get("config_digest") == config_digest(spec.config_dir))
    return result if same else None


def _run(spec: RunnableSpec) -> tuple[RunnableSpec, dict[str, Any]]:
    torch.set_num_threads(1)
    return spec, spec.run()


def run_specs(specs: Sequence[RunnableSpec], out: Path, workers: int = MAX_WORKERS,
              description: str = "runs") -> list[dict[str, Any]]:
    """Run every spec not already saved under ``out``; results in the order of ``specs``.

    :param workers: processes (1 runs in this process; capped at :data:`MAX_WORKERS`).
    """
    results: dict[str, dict[str, Any]] = {}
    todo = []
    for spec in specs:
        saved = _saved(out, spec)
        if saved is None:
            todo.append(spec)
        else:
            results[f"{spec.experiment}/{spec.name}"] = saved
    workers = max(1, min(workers, MAX_WORKERS, len(todo)))
    bar = tqdm(total=len(specs), initial=len(specs) - len(todo), desc=description, unit="run",
               dynamic_ncols=True)

    def keep(spec: RunnableSpec, result: dict[str, Any]) -> None:
        path = result_path(out, spec)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result))
        results[f"{spec.experiment}/{spec.name}"] = result
        bar.set_postfix_str(f"{spec.name} {result['wall_time']:.0f}s")
        bar.update()

    if workers == 1:
        for spec in todo:
            keep(*_run(spec))
    else:
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            for spec, result in pool.imap_unordered(_run, todo):
                keep(spec, result)
    bar.close()
    return [results[f"{s.experiment}/{s.name}"] for s in specs]


def load_results(out: Path, experiment: str) -> list[dict[str, Any]]:
    """Every saved result of ``experiment`` under ``out`` (sorted by name)."""
    folder = Path(out) / experiment
    return [json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))]
