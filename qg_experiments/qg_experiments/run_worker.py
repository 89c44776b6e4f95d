"""What one experiment run is, and what a worker of either backend does with it.

A leaf that the process pool (``tasks``) and Ray (``ray_backend``) both call, so a seed gives the
same result on either and neither backend module imports the other.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import torch

from qg_experiments.code_version import code_version
from qg_experiments.run_progress import progress_path

__all__ = ["RunnableSpec", "ResumableSpec", "run_one"]


class RunnableSpec(Protocol):
    """A frozen run: its name, its experiment (the results folder), where its config files are
    (None: the installed ones) and the run itself."""
    name: str
    experiment: str
    config_dir: str | None

    def run(self) -> dict[str, Any]: ...


@runtime_checkable
class ResumableSpec(RunnableSpec, Protocol):
    """A run long enough to save its progress between episodes and continue from it
    (``run_progress``)."""

    def run_resuming(self, progress: Path) -> dict[str, Any]: ...


def run_one(spec: RunnableSpec, out: Path | None = None
            ) -> tuple[RunnableSpec, dict[str, Any]]:
    """One run in a worker of either backend: single-threaded torch, as every worker runs; the
    result says which code made it (``code_version``, of the checkout this worker runs from) and
    the CPU time it took (``cpu_time`` [s]: unlike ``wall_time`` it does not count the time the
    worker waited for a core or was paused; a resumed run gives its own, over its sessions).

    :param out: the sweep's results folder: a ``ResumableSpec`` keeps its progress there.
    """
    torch.set_num_threads(1)
    cpu = time.process_time()
    if out is not None and isinstance(spec, ResumableSpec):
        result = spec.run_resuming(progress_path(out, spec))
    else:
        result = spec.run()
    return spec, {"cpu_time": time.process_time() - cpu, **result, "code": code_version()}
