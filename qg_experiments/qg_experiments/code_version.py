"""Which code made a run: the git commit of the checkout it ran from, and whether that
checkout's tracked files differed from the commit. Saved with every run (``run_worker``).

Why: a saved run is reused when its spec, its config files' numbers and its task settings match
(``tasks``); a change of code is invisible to that check. A sweep that resumes over days, across
commits, can mix runs that different code made. The report lists the commits its runs came from,
so such a mix shows.
"""
from __future__ import annotations

import subprocess
from importlib.resources import files
from pathlib import Path
from typing import Any

__all__ = ["code_version", "UNRECORDED"]

#: A run saved before runs recorded their code, or run from a copy without git.
UNRECORDED: dict[str, Any] = {"commit": None, "modified": None}


def _git(path: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(path), *args], capture_output=True, text=True,
                          timeout=30, check=True).stdout


def code_version(path: Path | None = None) -> dict[str, Any]:
    """``{"commit": sha, "modified": bool}`` of the git checkout holding ``path`` (default: the
    installed ``qg_experiments``, an editable install's checkout); ``UNRECORDED`` outside a
    checkout or without git."""
    path = Path(str(files("qg_experiments"))) if path is None else Path(path)
    try:
        commit = _git(path, "rev-parse", "HEAD").strip()
        modified = bool(_git(path, "status", "--porcelain", "--untracked-files=no").strip())
    except (OSError, subprocess.SubprocessError):
        return dict(UNRECORDED)
    return {"commit": commit, "modified": modified}
