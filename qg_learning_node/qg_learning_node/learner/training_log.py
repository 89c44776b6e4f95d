"""Training scalars for TensorBoard and a CSV, under Stable-Baselines3's tag names.

Why SB3's names: users compare runs of this stack with runs of other RL code in one TensorBoard,
and SB3's ``rollout/ep_len_mean``, ``train/critic_loss`` ... are what their dashboards already
show. The CSV (``progress.csv``, as SB3's CSV logger names it) holds the same rows for plotting
without TensorBoard. Everything is indexed by the number of RL steps taken so far.
"""
from __future__ import annotations

import csv
import time
from collections import deque
from pathlib import Path
from typing import Any

__all__ = ["TrainingLog", "EPISODE_WINDOW"]

#: Episodes in the rolling means: one full rotation of the 8 start poses (SB3 uses 100).
EPISODE_WINDOW = 8


class TrainingLog:
    """Writes scalars to ``<folder>`` (TensorBoard event file) and ``<folder>/progress.csv``.

    :param folder: created if missing.
    """

    def __init__(self, folder: Path) -> None:
        # TensorBoard's own event writer, not PyTorch's ``SummaryWriter`` (which writes the same
        # records through it): ``qgl run`` and ``qgl demo`` log here and need no PyTorch, which
        # took 1.1 s to load while the stack it had just launched was starting.
        from tensorboard.summary.writer.event_file_writer import EventFileWriter
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.writer = EventFileWriter(str(self.folder))
        self._csv = (self.folder / "progress.csv").open("w", newline="")
        self._rows = csv.writer(self._csv)
        self._rows.writerow(["step", "tag", "value"])
        self._lengths: deque[int] = deque(maxlen=EPISODE_WINDOW)
        self._successes: deque[bool] = deque(maxlen=EPISODE_WINDOW)
        self._returns: deque[float] = deque(maxlen=EPISODE_WINDOW)

    def scalar(self, tag: str, value: float, step: int) -> None:
        from tensorboard.compat.proto.event_pb2 import Event
        from tensorboard.compat.proto.summary_pb2 import Summary
        summary = Summary(value=[Summary.Value(tag=tag, simple_value=float(value))])
        self.writer.add_event(Event(wall_time=time.time(), step=int(step), summary=summary))
        self._rows.writerow([int(step), tag, float(value)])

    def episode(self, mode: str, length: int, success: bool, episode_return: float,
                step: int, fps: float) -> None:
        """One finished episode: rolling training statistics, or one test result."""
        if mode == "train":
            self._lengths.append(length)
            self._successes.append(success)
            self._returns.append(episode_return)
            self.scalar("rollout/ep_len_mean", sum(self._lengths) / len(self._lengths), step)
            self.scalar("rollout/success_rate",
                        sum(self._successes) / len(self._successes), step)
            self.scalar("rollout/ep_rew_mean", sum(self._returns) / len(self._returns), step)
        else:
            self.scalar("eval/ep_length", length, step)
            self.scalar("eval/success", float(success), step)
        self.scalar("time/fps", fps, step)

    def training(self, diagnostics: dict[str, Any], step: int) -> None:
        """A learner update: losses and the critic's mean prediction."""
        for key in ("critic_loss", "actor_loss", "mean_q", "frac_raised_lower"):
            if key in diagnostics:
                self.scalar(f"train/{key}", diagnostics[key], step)

    def evaluation(self, lengths: list[int], successes: list[bool], step: int) -> None:
        """The test phase as a whole (SB3's EvalCallback tags)."""
        if lengths:
            self.scalar("eval/mean_ep_length", sum(lengths) / len(lengths), step)
            self.scalar("eval/success_rate", sum(successes) / len(successes), step)

    def close(self) -> None:
        self.writer.close()
        self._csv.close()
