"""The experiment runs on Ray: a local Ray on this machine, or a cluster of machines.

Each run is one Ray task of one CPU that calls the same ``run_worker.run_one`` as a worker of the
process pool (single-threaded torch, then ``spec.run()``), so a seed gives the same result on
either backend; results come back as the tasks end, and ``tasks.run_specs`` saves each at once.

A run reads the stack's config files where the spec's ``config_dir`` says, else where the
environment says (``$QG_CONFIG_DIR``, or the installed packages found through
``$AMENT_PREFIX_PATH``). Those variables go to every task with the job, and each result's config
digest is compared with this machine's: a cluster node that read other numbers stops the sweep
instead of saving a run of another configuration. A cluster therefore needs the stack set up at
the same path on every node (``scripts/setup.sh``) and a ``config_dir`` that every node can read.

Ray is an optional dependency imported only here, so ``qgl`` and the process pool never load it.
"""
from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from qg_experiments.run_worker import RunnableSpec, run_one
from qg_experiments.runner import config_digest

__all__ = ["CONFIG_ENV", "ray_results"]

#: The environment variables that decide which config files a run reads (``qg_common.params``).
CONFIG_ENV = ("QG_CONFIG_DIR", "AMENT_PREFIX_PATH", "QG_ROS_INSTALL")


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as exc:
        raise RuntimeError("the ray backend needs the ray package (scripts/requirements.txt; "
                           "bash scripts/setup.sh installs it)") from exc
    return ray


def ray_results(todo: Sequence[RunnableSpec], workers: int, address: str | None = None,
                out: Path | None = None) -> Iterator[tuple[RunnableSpec, dict[str, Any]]]:
    """``(spec, result)`` of each run of ``todo`` as its Ray task ends.

    :param workers: CPUs of the local Ray this starts (with ``address`` None): runs at a time.
    :param address: a running Ray cluster to join (``ray://host:10001`` or ``host:6379``);
        its CPUs decide how many runs go at once.
    :param out: the sweep's results folder, where a long run keeps its progress (on the
        machine it runs on: a run that goes to another machine next time starts over).
    :raises RuntimeError: if ray is missing, or a run read config files other than this
        machine's (its digest differs).
    """
    ray = _import_ray()
    expected = {d: config_digest(d) for d in {spec.config_dir for spec in todo}}
    env = {name: os.environ[name] for name in CONFIG_ENV if name in os.environ}
    started = not ray.is_initialized()
    if started:
        local = {} if address else {"num_cpus": workers}
        ray.init(address=address, include_dashboard=False,
                 runtime_env={"env_vars": env}, **local)
    try:
        task = ray.remote(num_cpus=1)(run_one)
        pending = {task.remote(spec, out): spec for spec in todo}
        while pending:
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            spec = pending.pop(ref)
            _, result = ray.get(ref)
            if result.get("config_digest") != expected[spec.config_dir]:
                raise RuntimeError(
                    f"run {spec.experiment}/{spec.name} read config files with digest "
                    f"{result.get('config_digest')}, this machine's are "
                    f"{expected[spec.config_dir]}: the Ray workers see other config files "
                    "(set the stack up at the same path on every node, or pass a --config-dir "
                    "they all read)")
            yield spec, result
    finally:
        if started:
            ray.shutdown()
