"""The progress of a run as it happens: a progress bar that moves at every RL step, and the
training scalars (TensorBoard) of every episode and learner heartbeat.

It follows the running stack's topics (``transitions``, the learner's diagnostics) like any
client would: the bar counts episodes, its postfix shows the step, the return and how many
episodes inserted.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial

from qg_learning_node.learner.training_log import TrainingLog

from qg_bringup.episode_schedule import EpisodeOutcome, robot_name

__all__ = ["StepMonitor"]


@dataclass
class _RobotProgress:
    """What the progress line shows of one robot: its episode and the step it is at."""
    label: str = "idle"
    episode_id: str = ""
    steps: int = 0


class StepMonitor:
    """Follows the running stack for the demo: a progress line per RL step, training scalars.

    :param bar: the tqdm bar (one unit per episode) whose postfix shows the current step.
    :param log: where episode and learner scalars go.
    :param robots: the robots' namespaces ("" = one robot at the root); every robot's
        ``transitions`` move the bar, and with many robots the line shows each one's episode.
    """

    def __init__(self, cli, bar, log: TrainingLog, episodes: int,
                 robots: Sequence[str] = ("",)) -> None:
        from qg_common.topics import LEARNER_DIAGNOSTICS, RELIABLE_DEEP, TRANSITIONS
        from qg_interfaces.msg import LearnerDiagnostics, Transition
        self.bar, self.log, self.episodes = bar, log, episodes
        self.steps = 0
        self.rate_since = time.monotonic()
        self.robots = {robot: _RobotProgress() for robot in robots}
        self.last_return = float("nan")
        self.successes = {"train": [0, 0], "test": [0, 0]}
        self.actor_version = -1
        self.learner_transitions = 0     # as the learner's last heartbeat counts them
        for robot in robots:
            cli.node.create_subscription(Transition, robot_name(robot, TRANSITIONS),
                                         partial(self._on_transition, robot=robot), RELIABLE_DEEP)
        cli.node.create_subscription(LearnerDiagnostics, "/" + LEARNER_DIAGNOSTICS,
                                     self._on_diagnostics, 10)

    @property
    def fps(self) -> float:
        """RL steps per wall second since the first episode started."""
        return self.steps / max(1e-9, time.monotonic() - self.rate_since)

    def begin(self, index: int, mode: str, robot: str = "") -> None:
        if index == 0:
            self.rate_since = time.monotonic()
        self.robots[robot] = _RobotProgress(f"{mode} {index + 1}/{self.episodes}")
        self._show()

    def _on_transition(self, msg, robot: str = "") -> None:
        progress = self.robots[robot]
        if msg.episode_id != progress.episode_id:
            progress.episode_id, progress.steps = msg.episode_id, 0
        self.steps += 1
        progress.steps = int(msg.step) + 1
        self._show()

    def _on_diagnostics(self, msg) -> None:
        self.learner_transitions = int(msg.transitions)
        if int(msg.actor_version) != self.actor_version:      # a new training cycle, not a heartbeat
            self.actor_version = int(msg.actor_version)
            if self.actor_version > 0:
                self.log.training({"critic_loss": msg.critic_loss, "actor_loss": msg.actor_loss,
                                   "mean_q": msg.mean_q,
                                   "frac_raised_lower": msg.frac_raised_lower}, self.steps)

    def end(self, outcome: EpisodeOutcome) -> None:
        done = self.successes[outcome.mode]
        done[0] += int(outcome.success)
        done[1] += 1
        self.last_return = outcome.episode_return
        self.log.episode(outcome.mode, outcome.steps, outcome.success, outcome.episode_return,
                         self.steps, self.fps)
        if len(self.robots) > 1:       # (one robot: the line keeps its last episode)
            self.robots[outcome.robot] = _RobotProgress()
        self.bar.update(1)
        self._show()

    def _where(self) -> str:
        """``train 3/40 step 12``; many robots: each one's, ``r0 train 3/40 step 12, r1 idle``."""
        if list(self.robots) == [""]:
            progress = self.robots[""]
            return f"{progress.label} step {progress.steps}"
        return ", ".join(f"{robot.replace('robot', 'r', 1)} {p.label}"
                         + (f" step {p.steps}" if p.label != "idle" else "")
                         for robot, p in self.robots.items())

    def _show(self) -> None:
        train, test = self.successes["train"], self.successes["test"]
        self.bar.set_postfix_str(
            f"{self._where()} | {self.fps:.1f} steps/s | last return "
            f"{self.last_return:.2f} | inserted: train {train[0]}/{train[1]}"
            + (f", test {test[0]}/{test[1]}" if test[1] else ""))
