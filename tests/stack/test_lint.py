"""The project's sources pass ruff (``ruff.toml``): pyflakes (an undefined name, a dead import),
isort (import blocks in order) and pyupgrade (the Python 3.11 spelling).

A misspelt or undefined name in a rarely taken branch (a loop thread's error path, say) only
shows when that branch runs; in a node it then kills the process. Ruff finds it by reading the
source, in about a second for the whole project.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RUFF = Path(sys.executable).parent / "ruff"


def ruff(*args: str) -> subprocess.CompletedProcess[str]:
    """``ruff check`` in the repository with its config, no cache written."""
    return subprocess.run([str(RUFF), "check", "--no-cache", "--output-format", "concise", *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_ruff_finds_nothing_in_the_project():
    listed = ruff("--show-files", ".")
    assert listed.returncode == 0, listed.stderr
    files = [Path(line.strip()) for line in listed.stdout.splitlines() if line.strip()]
    # every package, the benchmarks and the tests; nothing of the venv or the colcon folders
    assert len(files) >= 250, len(files)
    checked = {p.relative_to(ROOT).parts[0] for p in files}
    assert {"qg_experiments", "qg_learning_node", "robot_bridge_node", "sim_robot_node",
            "ros_ws", "benchmarks", "tests"} <= checked
    assert not [p for p in files if {".venv", "build", "install"} & set(p.relative_to(ROOT).parts)]
    result = ruff(".")
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]


def test_ruff_flags_each_kind_of_finding(tmp_path: Path):
    """The check can fail: a module with one finding of each selected kind is refused."""
    module = tmp_path / "sloppy.py"
    module.write_text("import sys\n"
                      "import os\n"
                      "from typing import List\n\n\n"
                      "def f() -> List[int]:\n"
                      "    return [len(sys.argv), undefined_name]\n")
    result = ruff("--config", str(ROOT / "ruff.toml"), str(module))
    assert result.returncode == 1
    codes = {line.split()[1] for line in result.stdout.splitlines() if str(module) in line}
    assert {"F401", "F821", "I001", "UP006", "UP035"} <= codes, result.stdout


def test_no_file_is_exempt_from_pyflakes():
    """Files may wait for the mechanical fixes (import order, spellings), never for a pyflakes
    finding: an undefined name or a dead import is a bug, not a style."""
    import tomllib
    config = tomllib.loads((ROOT / "ruff.toml").read_text())
    exempt = config["lint"].get("per-file-ignores", {})
    assert {path: codes for path, codes in exempt.items()
            if any(code.startswith("F") for code in codes)} == {}
    assert set(config["lint"]["select"]) == {"F", "I", "UP"}
