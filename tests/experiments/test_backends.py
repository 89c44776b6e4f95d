"""Where experiment runs execute: the process pool and Ray give the same saved results.

The Ray test starts a real local Ray of one CPU (several seconds on this machine) and runs a
learning run of the ``tiny`` grid and a peg run through it and through a spawn pool of two.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from qg_experiments import grid, peg
from qg_experiments.__main__ import main
from qg_experiments.profile import load_profile
from qg_experiments.runner import STACK_CONFIG_FILES
from qg_experiments.tasks import DEFAULT_WORKERS, result_path, run_specs


def _small_specs() -> list:
    profile = load_profile("tiny")
    return [grid.grid_specs(profile.grid, profile.estimator, None)[0],
            peg.peg_specs(profile.peg, None)[0]]


def _without_wall_time(path: Path) -> dict:
    result = json.loads(path.read_text())
    del result["wall_time"], result["cpu_time"]
    return result


@pytest.mark.ros                     # full tier only: starts a local Ray (its own processes)
@pytest.mark.slow                    # 22-33 s on the 2 loaded cores, most of it starting Ray
def test_ray_runs_give_the_pools_results_and_resume(tmp_path: Path) -> None:
    specs = _small_specs()
    pooled = run_specs(specs, tmp_path / "pool", workers=2)
    on_ray = run_specs(specs, tmp_path / "ray", workers=1, backend="ray")
    for spec in specs:
        assert (_without_wall_time(result_path(tmp_path / "ray", spec))
                == _without_wall_time(result_path(tmp_path / "pool", spec))), spec.name
    assert [r["spec"] for r in on_ray] == [r["spec"] for r in pooled]
    assert len(on_ray[0]["cycles"]) > 0 and on_ray[0]["rl_steps"] > 0   # a run that learned
    # The peg run kept its progress where the Ray worker ran, and removed it at its end.
    assert not list(tmp_path.glob("*/*/*.progress.pt*"))
    # A second call finds both runs saved: nothing runs, nothing is rewritten.
    saved = {p: p.stat().st_mtime_ns for p in (tmp_path / "ray").glob("*/*.json")}
    assert len(saved) == 2
    run_specs(specs, tmp_path / "ray", workers=1, backend="ray")
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "ray").glob("*/*.json")} == saved


@pytest.mark.ros                     # full tier only: starts a local Ray (its own processes)
@pytest.mark.slow                    # about 21 s on the loaded cores: a second local Ray
def test_a_ray_worker_that_reads_other_config_files_saves_nothing(tmp_path: Path) -> None:
    """A cluster whose workers see other config files than this machine: the sweep stops."""
    import ray
    from qg_common.params import config_file
    edited = tmp_path / "config"
    edited.mkdir()
    for name in STACK_CONFIG_FILES:
        shutil.copy(config_file(name), edited / name)
    learner = (edited / "learner.yaml").read_text()
    assert "batch_size: 64" in learner
    (edited / "learner.yaml").write_text(learner.replace("batch_size: 64", "batch_size: 32"))
    spec = peg.peg_specs(load_profile("tiny").peg, None)[0]
    ray.init(num_cpus=1, include_dashboard=False,
             runtime_env={"env_vars": {"QG_CONFIG_DIR": str(edited)}})
    try:
        with pytest.raises(RuntimeError, match="Ray workers see other config files"):
            run_specs([spec], tmp_path / "runs", workers=1, backend="ray")
    finally:
        ray.shutdown()
    assert not list(tmp_path.glob("runs/*/*.json"))


@pytest.mark.slow
def test_qgl_and_the_pool_never_import_ray(tmp_path: Path) -> None:
    """Ray is optional: the CLI, the suite and a pool run work without loading it."""
    code = ("import sys\n"
            "import qg_bringup.main, qg_experiments.__main__\n"
            "from qg_experiments.tasks import run_specs\n"
            "from qg_experiments import peg\n"
            "from qg_experiments.profile import load_profile\n"
            "spec = peg.peg_specs(load_profile('tiny').peg, None)[0]\n"
            f"run_specs([spec], {str(tmp_path)!r}, workers=1)\n"
            "print(sorted(m for m in sys.modules if m == 'ray' or m.startswith('ray.')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"
    assert len(list(tmp_path.glob("peg/*.json"))) == 1


def test_the_pool_uses_every_core_and_bad_dispatch_is_refused(tmp_path: Path) -> None:
    assert DEFAULT_WORKERS == os.cpu_count()
    specs = _small_specs()
    with pytest.raises(ValueError, match="backend must be one of"):
        run_specs(specs, tmp_path, backend="dask")
    with pytest.raises(ValueError, match="needs the ray backend"):
        run_specs(specs, tmp_path, address="head:6379")
    for argv in (["--address", "head:6379"], ["--workers", "0"], ["--backend", "dask"]):
        with pytest.raises(SystemExit):
            main(["--profile", "tiny", "--out", str(tmp_path), *argv])
    assert not list(tmp_path.iterdir())                   # refused before anything ran
