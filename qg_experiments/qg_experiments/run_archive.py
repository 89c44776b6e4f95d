"""Finished runs kept in the repository, beside the report: a sweep that outlives its machine.

A run's result is saved under ``--out`` (``tasks.result_path``), a folder outside version
control, with the run's progress files. A machine that is reset takes that folder with it: one
reset took the 34 finished runs of the thesis's peg (about 10 hours of two cores) and left only
their episode CSVs, which hold no final Q and cannot rebuild the report. So each finished run
is also kept, gzipped, in ``docs/data/<profile>/archived_runs/<experiment>/<name>.json.gz``
(tens of kB; versioned like the report's CSVs; not ``runs/``, a name ``.gitignore`` leaves
out at any depth), and a sweep or a report on a fresh clone first restores into ``--out``
every archived run it would otherwise miss (``tasks.restore_archived``). An archived run is
restored only while it is the same run (``run_identity``: spec, config digest, task settings),
as a saved one is reused.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path
from typing import Any

from qg_experiments.run_identity import is_run_of
from qg_experiments.run_worker import RunnableSpec

__all__ = ["archive_folder", "archived_path", "archive_result", "archived_result"]


def archive_folder(docs: Path, profile: str) -> Path:
    """Where the runs of ``profile`` are archived, beside its report's data."""
    return Path(docs) / "data" / profile / "archived_runs"


def archived_path(archive: Path, spec: RunnableSpec) -> Path:
    return Path(archive) / spec.experiment / f"{spec.name}.json.gz"


def archive_result(archive: Path, spec: RunnableSpec, result: dict[str, Any]) -> Path:
    """Keep ``result`` of ``spec`` in ``archive``; the same result gives the same bytes (no
    time in the gzip header), so a rerun that changes nothing changes no file."""
    path = archived_path(archive, spec)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(gzip.compress(json.dumps(result).encode(), mtime=0))
    return path


def archived_result(archive: Path, spec: RunnableSpec) -> dict[str, Any] | None:
    """The result of ``spec`` archived in ``archive``, or None: none archived, or one of
    another run (``run_identity``)."""
    path = archived_path(archive, spec)
    if not path.exists():
        return None
    result = json.loads(gzip.decompress(path.read_bytes()))
    return result if is_run_of(result, spec) else None
