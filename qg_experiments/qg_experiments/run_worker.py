"""What one experiment run is, and what a worker of either backend does with it.

A leaf that the process pool (``tasks``) and Ray (``ray_backend``) both call, so a seed gives the
same result on either and neither backend module imports the other.
"""
from __future__ import annotations

from typing import Any, Protocol

import torch

from qg_experiments.code_version import code_version

__all__ = ["RunnableSpec", "run_one"]


class RunnableSpec(Protocol):
    """A frozen run: its name, its experiment (the results folder), where its config files are
    (None: the installed ones) and the run itself."""
    name: str
    experiment: str
    config_dir: str | None

    def run(self) -> dict[str, Any]: ...


def run_one(spec: RunnableSpec) -> tuple[RunnableSpec, dict[str, Any]]:
    """One run in a worker of either backend: single-threaded torch, as every worker runs; the
    result says which code made it (``code_version``, of the checkout this worker runs from)."""
    torch.set_num_threads(1)
    return spec, {**spec.run(), "code": code_version()}
