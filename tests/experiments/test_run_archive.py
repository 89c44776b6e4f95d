"""Finished runs archived beside the report (``run_archive``) come back on a fresh machine.

The thesis's peg lost 34 finished runs (about 10 hours of two cores) when its machine was reset:
the results folder is not versioned. A run is now kept in the report's data folder too, and a
sweep, a report or ``--status`` on a fresh clone restores it first.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

from qg_experiments.peg import PegRunSpec
from qg_experiments.run_archive import archive_folder, archive_result, archived_path
from qg_experiments.tasks import restore_archived, result_path, run_specs, saved_result

ROOT = Path(__file__).resolve().parents[2]
SPEC = PegRunSpec(algorithm="qgddpg", lr=1e-3, seed=5, episodes=2, train_iterations=3,
                  episode_steps=20)
OTHER = PegRunSpec(algorithm="ddpg", lr=1e-3, seed=5, episodes=2, train_iterations=3,
                   episode_steps=20)


def test_a_finished_run_is_archived_and_a_fresh_machine_restores_it_without_running_it(
        tmp_path: Path) -> None:
    archive = archive_folder(tmp_path / "docs", "thesis")
    run_specs([SPEC], tmp_path / "machine1", workers=1, archive=archive)
    result = saved_result(tmp_path / "machine1", SPEC)
    path = archived_path(archive, SPEC)
    assert path == archive / "peg" / f"{SPEC.name}.json.gz"
    assert json.loads(gzip.decompress(path.read_bytes())) == result
    before = path.read_bytes()
    archive_result(archive, SPEC, result)
    assert path.read_bytes() == before          # the same result, the same bytes

    fresh = tmp_path / "machine2"
    assert restore_archived([SPEC, OTHER], fresh, archive) == [SPEC.name]  # OTHER never ran
    assert saved_result(fresh, SPEC) == result
    assert restore_archived([SPEC], fresh, archive) == []     # already there
    (again,) = run_specs([SPEC], fresh, workers=1)
    assert again["wall_time"] == result["wall_time"]         # reused, not run again


def test_an_archived_run_of_another_setting_is_not_restored(tmp_path: Path) -> None:
    archive = tmp_path / "archived_runs"
    run_specs([SPEC], tmp_path / "machine1", workers=1, archive=archive)
    path = archived_path(archive, SPEC)
    result = json.loads(gzip.decompress(path.read_bytes()))
    path.write_bytes(gzip.compress(json.dumps({**result, "config_digest": "other"}).encode()))
    assert restore_archived([SPEC], tmp_path / "machine2", archive) == []
    assert not result_path(tmp_path / "machine2", SPEC).exists()


def test_the_status_of_a_fresh_clone_counts_the_archived_runs(tmp_path: Path, capsys) -> None:
    from qg_experiments.__main__ import main
    from qg_experiments.profile import load_profile
    from qg_experiments.suite import all_specs

    docs = tmp_path / "docs"
    first = all_specs(load_profile("tiny"), ("peg",))[0]
    run_specs([first], tmp_path / "machine1" / "tiny", workers=1,
              archive=archive_folder(docs, "tiny"))
    main(["--profile", "tiny", "--only", "peg", "--status", "--out", str(tmp_path / "fresh"),
          "--docs", str(docs)])
    printed = capsys.readouterr().out
    assert "tiny: 1 finished run(s) restored from" in printed
    assert "peg: 1 of 4 runs saved" in printed, printed


def test_the_archive_is_versioned() -> None:
    """``.gitignore`` leaves ``runs/`` out at any depth: the archive must not be one."""
    import subprocess
    path = archived_path(archive_folder(Path("docs"), "thesis"), SPEC)
    ignored = subprocess.run(["git", "check-ignore", "-q", str(path)], cwd=ROOT)
    assert ignored.returncode == 1, f"{path} is git-ignored"
