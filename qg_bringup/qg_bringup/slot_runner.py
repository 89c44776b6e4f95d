"""One slot of a training run at a time, until the journal holds it complete.

A slot is complete once its episode ended ``done`` and the learner checkpointed after it; an
attempt cut short (a process died, the episode was aborted, the learner lost it) is noted in the
journal and the slot runs again, after the stack answers again. A slot that keeps failing stops
the run with the reason instead of looping.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from qg_bringup.episode_schedule import EpisodeJob
from qg_bringup.run_journal import RunJournal

__all__ = ["SlotRunner", "learner_record", "MAX_ATTEMPTS", "CHECKPOINT_WAIT", "STACK_TIMEOUT"]

#: Attempts at one slot cut short before the run stops with the reason (a slot that keeps
#: failing is a fault to look at, not to loop on).
MAX_ATTEMPTS = 5
#: [s] how long a completed episode waits for the learner's checkpoint after it.
CHECKPOINT_WAIT = 60.0
#: [s] how long a run waits for its stack (robot, executor, learner) to come up.
STACK_TIMEOUT = 180.0
#: [s] how often the learner's checkpoint is looked for after an episode. It is written ~15 ms
#: after the episode's end and the next episode waits for it: polled every 50 ms, the gap
#: between two episodes was 65 ms at the median (the demo's 47 gaps: 3.9 s of its 47 s).
CHECKPOINT_POLL = 0.005


def learner_record(run_dir: Path) -> dict[str, Any] | None:
    """The learner's ``learner.json`` in ``run_dir`` (its last checkpoint), None if none."""
    from qg_learning_node.learner_node import CHECKPOINT_INFO_NAME
    path = run_dir / "checkpoints" / CHECKPOINT_INFO_NAME
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None



class SlotRunner:
    """Runs one slot to completion: again after an attempt cut short, waiting out restarts.

    A slot is complete once its episode ended ``done`` and the learner checkpointed after it.
    If the learner died before that checkpoint, the episode's transitions died with it (the
    restarted learner resumes from the checkpoint before), so the slot runs again; and after
    any restart the next attempt waits until the stack answers again (a learner that is not yet
    subscribed would miss the transitions).
    """

    def __init__(self, cli: Any, launcher: Any, guard: Any, lane: Any, journal: RunJournal,
                 run_dir: Path, label: str) -> None:
        self.cli, self.launcher, self.guard, self.lane = cli, launcher, guard, lane
        self.journal, self.run_dir, self.label = journal, run_dir, label
        self.refusals = 0
        self.deaths: list[str] = []     # restarts seen during the running attempt
        self.restarted = False          # a process came back: wait for the stack to answer
        self.learner_died = False       # during the running attempt or before its checkpoint

    def run(self, job: EpisodeJob) -> None:
        """One attempt at ``job``'s slot: complete in the journal, or cut short (the caller
        runs the slot again).

        :raises RuntimeError: a process stays dead, or the slot keeps failing.
        """
        from qg_bringup.stack_start import wait_for_stack
        self.lane.queue.append(job)
        self.learner_died = False
        while True:
            self._check_processes()
            if self.launcher.restarting():      # not before the stack is whole again
                self.cli.spin_for(0.1)
                continue
            if self.restarted and self.lane.job is None:
                wait_for_stack(self.cli, timeout=STACK_TIMEOUT)
                self.restarted = False
            try:
                outcome = self.lane.advance()
            except RuntimeError as exc:         # refused: a restarted peer not yet discovered
                self.refusals += 1
                if self.refusals > 20:
                    raise
                print(f"[{self.label}] slot {job.index + 1}: {exc}; asking again in 3 s",
                      flush=True)
                self._requeue(job)
                self.cli.spin_for(3.0)
                continue
            if outcome is not None:
                break
            self.cli.executor.spin_once(timeout_sec=0.01)
        self.refusals, deaths, self.deaths = 0, self.deaths, []
        if outcome.state == "done":
            record = self._learner_after(outcome.episode_id)
            if record is not None:
                self._check_count(outcome.episode_id, outcome.steps, record)
                self.journal.complete(outcome, record)
            elif self.learner_died:
                self._cut(job, outcome.episode_id, "the learner restarted before it "
                          "checkpointed the episode: its transitions are lost", outcome.steps)
            else:
                self._cut(job, outcome.episode_id, "the learner did not checkpoint the episode "
                          f"within {CHECKPOINT_WAIT:.0f} s: it did not learn from it",
                          outcome.steps)
            return
        said = outcome.message or "aborted"     # the guard's stop already names its death
        self._cut(job, outcome.episode_id,
                  "; ".join([said, *(death for death in deaths if death not in said)]),
                  outcome.steps)

    def _check_processes(self) -> None:
        died = self.launcher.poll()
        if died:
            name, code = died[0]
            raise RuntimeError(self.launcher.reasons.get(name, f"process {name} exited with "
                                                               f"code {code}"))
        for death in self.launcher.take_respawns():
            ended = self.guard.process_died(death)
            self.deaths.append(death.reason)
            self.restarted = True
            role = self.guard.roles.get(death.name)
            if role is not None and role.robot is None:
                self.learner_died = True
            print(f"[{self.label}] {death.reason} in {death.delay:.1f} s"
                  + (f"; episode {', '.join(ended)} ended aborted" if ended else ""), flush=True)
            if role is not None and role.executor and self.lane.job is not None \
                    and not self.lane.episode_id:
                # It died before naming the episode: no status will ever end it.
                job = self.lane.forget()
                self._cut(job, "", death.reason)
                self._requeue(job)

    def _requeue(self, job: EpisodeJob) -> None:
        self.lane.forget()
        if not self.lane.queue:
            self.lane.queue.append(job)

    def _cut(self, job: EpisodeJob, episode_id: str, reason: str, steps: int = 0) -> None:
        self.journal.cut(job.index, episode_id, reason, steps)
        attempts = self.journal.attempts(job.index)
        print(f"[{self.label}] slot {job.index + 1} ({job.mode}) cut short ({reason}): "
              f"running it again (attempt {attempts + 1})", flush=True)
        if attempts >= MAX_ATTEMPTS:
            raise RuntimeError(f"slot {job.index + 1} was cut short {attempts} times, last: "
                               f"{reason}")

    def _learner_after(self, episode_id: str) -> dict[str, Any] | None:
        """The learner's record once it has checkpointed after ``episode_id``; None if it
        died first or did not within ``CHECKPOINT_WAIT`` seconds (a learner that missed the
        whole episode never names it)."""
        deadline = time.monotonic() + CHECKPOINT_WAIT
        while time.monotonic() < deadline:
            record = learner_record(self.run_dir)
            if record is not None and record.get("episode_id") == episode_id:
                return record
            self._check_processes()
            if self.learner_died:               # its checkpoint of this episode never comes
                return None
            self.cli.executor.spin_once(timeout_sec=CHECKPOINT_POLL)
        return None

    def _check_count(self, episode_id: str, steps: int, record: dict[str, Any]) -> None:
        """Warn when the learner holds fewer transitions than the completed episodes, this
        one included, sent (it missed some: the count stays in the journal)."""
        expected = self.journal.steps() + steps
        held = record.get("transitions")
        if isinstance(held, int) and held < expected:
            print(f"[{self.label}] warning: after {episode_id} the learner holds {held} "
                  f"transitions, the completed episodes sent {expected}: it missed "
                  f"{expected - held}", flush=True)
