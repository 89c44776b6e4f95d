"""Every saved experiment run as TensorBoard scalars and a ``progress.csv``, SB3's tag names.

The runs save JSON (episodes, training cycles); this module replays each one into a
:class:`~qg_learning_node.learner.training_log.TrainingLog`, the writer the demo uses, so an
experiment and a demo run can be compared in one TensorBoard (and with runs of Stable-Baselines3
code). Scalars are indexed by RL steps: episodes at the step they ended, training cycles at the step
they ran, the test phase (SB3's ``eval/`` tags) at the end of training.
"""
from __future__ import annotations

import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from qg_learning_node.learner.training_log import TrainingLog

__all__ = ["export_run", "export_runs"]


def export_run(result: dict[str, Any], folder: Path) -> None:
    """Write one run's scalars to ``folder`` (replacing what an earlier export wrote there)."""
    folder = Path(folder)
    if folder.exists():
        shutil.rmtree(folder)
    log = TrainingLog(folder)
    try:
        wall = float(result.get("wall_time", 0.0))
        fps = result.get("rl_steps", 0) / wall if wall > 0 else 0.0
        step = 0
        tests = []
        for episode in result["episodes"]:
            step += int(episode["steps"])
            mode = episode.get("mode", "train")
            log.episode(mode, int(episode["steps"]), bool(episode["success"]),
                        float(episode["return"]), step, fps)
            if "mean_q" in episode:          # the peg runs: one training block per episode
                log.training({"mean_q": episode["mean_q"]}, step)
            if mode == "test":
                tests.append(episode)
        for cycle in result.get("cycles", []):
            log.training(cycle, int(cycle["steps"]))
        log.evaluation([int(e["steps"]) for e in tests], [bool(e["success"]) for e in tests],
                       step)
    finally:
        log.close()


def export_runs(results: Iterable[dict[str, Any]], folder: Path) -> Path:
    """Every run to ``<folder>/<experiment>/<run name>/``; returns ``folder``."""
    for result in results:
        export_run(result, Path(folder) / result["experiment"] / result["name"])
    return Path(folder)
