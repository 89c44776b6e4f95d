"""A long run's progress, saved between its episodes, so that a stopped sweep continues a run.

A sweep saves each run when it ends (``tasks``), so stopping it loses only the runs under way;
but a thesis-budget peg run is 300 episodes and ~15 min of a core, and a sweep of 60 of them
spans hours and sessions. Such a run saves its state (the learner's ``state_dict``, the episodes
so far, its wall time) to ``<out>/<experiment>/<name>.progress.pt`` every ``PROGRESS_EVERY`` s of
wall time, between two episodes, and starts from there when it runs again. Its episodes are
seeded by their index (``runner.episode_noise_seed``), so a resumed run is the run to the bit
(``tests/experiments/test_run_progress.py``).

A progress file is used only by the run it was written for (``run_identity``: the same spec,
config digest and task settings, as ``tasks`` reuses a saved run). Anything else there (another
setting's run, a file that does not load) is started over, with a warning, and overwritten. The
file is replaced whole (written beside, then renamed), so a run killed while it saves leaves the
previous one, and it is removed when the run ends.

On Ray, a run saves where its worker runs: a run resumed on another machine starts over.
"""
from __future__ import annotations

import os
import pickle
import time
import warnings
from pathlib import Path
from typing import Any

from qg_experiments.code_version import code_version
from qg_experiments.run_identity import run_identity

__all__ = ["PROGRESS_EVERY", "PROGRESS_SUFFIX", "RunProgress", "peek", "progress_path"]

#: [s] of wall time between two saves. A save of the peg's learner at its largest (60,000
#: transitions in replay and graph) takes ~0.87 s and 34 MB: at most 0.7 % of the run's time
#: (``benchmarks/progress_save_bench.py``).
PROGRESS_EVERY = 120.0
#: What a progress file's name ends with (not ``.json``: ``tasks.load_results`` reads those).
PROGRESS_SUFFIX = ".progress.pt"


def progress_path(out: Path, spec: Any) -> Path:
    """Where the run ``spec`` of a sweep saving under ``out`` keeps its progress."""
    return Path(out) / spec.experiment / f"{spec.name}{PROGRESS_SUFFIX}"


class RunProgress:
    """The progress file of one run.

    :param path: the file (``progress_path``).
    :param spec: the run; only its own progress is loaded.
    :param every: [s] of wall time between two saves (None: ``PROGRESS_EVERY``).
    """

    def __init__(self, path: Path, spec: Any, every: float | None = None) -> None:
        self.path = Path(path)
        self.every = PROGRESS_EVERY if every is None else every
        self._identity = run_identity(spec)
        self._last_save = time.monotonic()

    def load(self) -> dict[str, Any] | None:
        """The saved state of this run (``save``'s ``state``, plus ``code``: the code that saved
        it, and ``wall_time``), or None: no file, or one that is not this run's (a warning says
        which)."""
        if not self.path.exists():
            return None
        try:
            with self.path.open("rb") as file:
                header = pickle.load(file)
                state = pickle.load(file)
        except Exception as exc:      # a truncated or foreign file: the run starts over
            warnings.warn(f"{self.path} does not load ({exc!r}); the run starts over",
                          stacklevel=2)
            return None
        if header.get("identity") != self._identity:
            warnings.warn(f"{self.path} is the progress of another setting; the run starts over",
                          stacklevel=2)
            return None
        return {"code": header["code"], "wall_time": header["wall_time"], **state}

    def save(self, state: dict[str, Any], done: int, of: int, wall_time: float,
             force: bool = False) -> bool:
        """Save ``state``, the run's ``done`` of ``of`` episodes after ``wall_time`` s, if
        ``every`` seconds have passed since the last save (or ``force``); True if it saved.

        The file holds two pickles: a small header (``peek`` reads it alone: which run, how
        far, on which code) and the state."""
        if not force and time.monotonic() - self._last_save < self.every:
            return False
        self.path.parent.mkdir(parents=True, exist_ok=True)
        partial = self.path.with_name(self.path.name + ".tmp")
        header = {"identity": self._identity, "code": code_version(), "done": done, "of": of,
                  "wall_time": wall_time}
        # pickle's protocol 5, not torch.save's 2: the graph's lists save 7 times as fast.
        with partial.open("wb") as file:
            pickle.dump(header, file, protocol=5)
            pickle.dump(state, file, protocol=5)
        os.replace(partial, self.path)
        self._last_save = time.monotonic()
        return True

    def remove(self) -> None:
        """The run has ended: its result is what stays."""
        self.path.unlink(missing_ok=True)


def peek(path: Path) -> dict[str, Any] | None:
    """A progress file's header without its state (``done`` of ``of`` episodes, ``wall_time``,
    ``code``), for a sweep's status; None if there is none or it does not read."""
    try:
        with Path(path).open("rb") as file:
            header = pickle.load(file)
    except (OSError, pickle.UnpicklingError, EOFError):
        return None
    return header if isinstance(header, dict) and "done" in header else None
