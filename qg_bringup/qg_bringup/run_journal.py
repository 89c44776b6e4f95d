"""A training run's folder: its plan, its episode schedule and how far it got.

``qgl run --run-dir DIR`` (and ``qgl demo``) keep in ``DIR``:

- ``run.json``: the plan (episodes, test rounds, seed, the learning settings, stack file,
  robot), written once; the same command on the same folder must ask for the same plan;
- ``journal.json``: every completed schedule slot with its outcome, the slot running now and
  the episode the executor named for it, and the attempts that were cut short (why); written
  atomically (a temporary file, fsync, rename) at every change, so a crash, a Ctrl-C or a
  reboot leaves the last whole version;
- ``checkpoints/learner.pt`` and ``learner.json``: the learner's state after the last
  completed episode (``learner_node``).

The schedule is fixed by the plan: slot ``i`` always has the same mode, pose and seed, so a
resumed run neither repeats nor skips one; a slot whose episode was cut short is run again.
Pure Python: the node-facing part is ``training_run.py``.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from qg_bringup.episode_schedule import EpisodeJob, EpisodeOutcome

__all__ = ["RunPlan", "RunJournal", "RunMismatch", "write_json_atomically", "N_POSES"]

#: The initial poses of the task (``executor/episode_request.py``).
N_POSES = 8
PLAN_NAME, JOURNAL_NAME = "run.json", "journal.json"


class RunMismatch(ValueError):
    """The run folder holds another run than the command asks for (one line for a user)."""


def write_json_atomically(path: Path, data: Any) -> None:
    """``path`` holds ``data`` whole or its old content, whatever stops the process when."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    directory = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(directory)            # the rename itself survives a power cut
    finally:
        os.close(directory)


@dataclass(frozen=True)
class RunPlan:
    """What a run is: N training episodes, test rounds, and what they run with.

    :param episodes: training episodes (N).
    :param test_every: a test round after every this many training episodes (0: none but the
        last).
    :param test_poses: poses per test round (0..8); a round also follows the last training
        episode.
    :param seed: slot ``i`` runs with seed ``seed + i``.
    :param settings: the learning settings the stack runs with (``DemoSettings``).
    :param stack: the stack file; :param robot: the robot plugin (None: the stack's).
    """
    episodes: int
    test_every: int = 0
    test_poses: int = 8
    seed: int = 1
    settings: dict[str, Any] = field(default_factory=dict)
    stack: str = ""
    robot: str | None = None

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"--episodes must be >= 1, got {self.episodes}")
        if self.test_every < 0:
            raise ValueError(f"--test-every must be >= 0, got {self.test_every}")
        if not 0 <= self.test_poses <= N_POSES:
            raise ValueError(f"--test-poses must be in 0..{N_POSES}, got {self.test_poses}")

    def slots(self) -> list[EpisodeJob]:
        """The whole schedule, in order: training episode ``k`` from pose ``k mod 8``, a test
        round (poses 0..test_poses-1) after every ``test_every``-th and after the last."""
        jobs: list[EpisodeJob] = []

        def add(mode: str, pose: int) -> None:
            jobs.append(EpisodeJob(len(jobs), mode, pose, self.seed + len(jobs)))

        for k in range(self.episodes):
            add("train", k % N_POSES)
            last = k == self.episodes - 1
            if self.test_poses and (last or (self.test_every and (k + 1) % self.test_every == 0)):
                for pose in range(self.test_poses):
                    add("test", pose)
        return jobs

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunPlan:
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in known})


class RunJournal:
    """How far a run got; every change is on disk before the call returns.

    :param folder: the run folder (``run.json``, ``journal.json``).
    """

    def __init__(self, folder: Path, plan: RunPlan, data: dict[str, Any]) -> None:
        self.folder, self.plan = folder, plan
        self.slots = plan.slots()
        self.completed: list[dict[str, Any]] = data.get("completed", [])
        self.running: dict[str, Any] | None = data.get("running")
        self.cut_short: list[dict[str, Any]] = data.get("cut_short", [])
        self.sessions: list[dict[str, Any]] = data.get("sessions", [])

    @classmethod
    def open(cls, folder: Path, plan: RunPlan) -> RunJournal:
        """The run in ``folder``: a new one (its plan written), or the one there, which must
        be ``plan``. :raises RunMismatch: naming the settings that differ."""
        folder.mkdir(parents=True, exist_ok=True)
        plan_path = folder / PLAN_NAME
        if plan_path.is_file():
            try:
                saved = json.loads(plan_path.read_text())
            except ValueError as exc:
                raise RunMismatch(f"{plan_path} is unreadable ({exc})") from None
            differ = {k: (saved.get(k), v) for k, v in plan.to_dict().items()
                      if saved.get(k) != v}
            if differ:
                raise RunMismatch(f"{folder} holds another run: " + ", ".join(
                    f"{k} {old!r} there, {new!r} asked" for k, (old, new) in differ.items())
                    + " (same command to continue it, or another --run-dir)")
        else:
            write_json_atomically(plan_path, plan.to_dict())
        path = folder / JOURNAL_NAME
        data = json.loads(path.read_text()) if path.is_file() else {}
        return cls(folder, plan, data)

    # --- where it is -------------------------------------------------------------------------
    @property
    def next_slot(self) -> int:
        """The slot to run next (slots complete in order)."""
        return len(self.completed)

    @property
    def finished(self) -> bool:
        return self.next_slot >= len(self.slots)

    def remaining(self) -> list[EpisodeJob]:
        return self.slots[self.next_slot:]

    def outcomes(self) -> list[EpisodeOutcome]:
        """The completed slots' outcomes, in order."""
        known = {f.name for f in fields(EpisodeOutcome)}
        return [EpisodeOutcome(**{k: v for k, v in o.items() if k in known})
                for o in self.completed]

    def steps(self, mode: str | None = None) -> int:
        """RL steps of the completed episodes (of ``mode``; None: all)."""
        return sum(o["steps"] for o in self.completed if mode is None or o["mode"] == mode)

    # --- changes -----------------------------------------------------------------------------
    def begin_session(self, note: str = "") -> None:
        """A command started (or resumed) the run here."""
        self.sessions.append({"started": time.time(), "at_slot": self.next_slot, "note": note})
        self._save()

    def started(self, slot: int, episode_id: str) -> None:
        """The executor runs ``slot`` as ``episode_id``."""
        self._check_next(slot)
        self.running = {"slot": slot, "episode_id": episode_id, "started": time.time()}
        self._save()

    def complete(self, outcome: EpisodeOutcome, learner: dict[str, Any] | None = None) -> None:
        """``outcome`` ended ``done``: its slot is complete. :param learner: the learner's
        ``learner.json`` after it (its transition count), if it checkpointed in time."""
        self._check_next(outcome.index)
        entry = asdict(outcome)
        entry["learner_transitions"] = None if learner is None else learner.get("transitions")
        self.completed.append(entry)
        self.running = None
        self._save()

    def cut(self, slot: int, episode_id: str, reason: str, steps: int = 0) -> None:
        """The attempt at ``slot`` ended without completing it (aborted, its executor died,
        the run stopped, the learner lost it): the slot runs again. ``steps``: how far it got."""
        self.cut_short.append({"slot": slot, "episode_id": episode_id, "reason": reason,
                               "steps": steps, "at": time.time()})
        self.running = None
        self._save()

    def attempts(self, slot: int) -> int:
        """How many attempts at ``slot`` were cut short."""
        return sum(c["slot"] == slot for c in self.cut_short)

    def reconcile(self, learner: dict[str, Any] | None) -> str:
        """At a resume: settle the slot that was running when the run stopped.

        The learner's checkpoint is what it learned. If it checkpointed after an episode that
        ended ``done`` and that no completed slot holds, that episode was the next slot's (the
        run starts no other): the run stopped between the learner's checkpoint and its own
        journal entry, or even before the executor's reply named the episode, so the slot is
        complete, with the learner's record of it. Otherwise a slot that was running was cut
        short and runs again. What was done.
        """
        known = {c["episode_id"] for c in self.completed}
        slot = self.next_slot
        episode_id = None if learner is None else learner.get("episode_id")
        if (learner is not None and learner.get("state") == "done" and episode_id
                and episode_id not in known and slot < len(self.slots)
                and learner.get("mode") in (None, self.slots[slot].mode)
                and (self.running is None or self.running["episode_id"] == episode_id)):
            job = self.slots[slot]
            started = self.running["started"] if self.running is not None else 0.0
            self.complete(EpisodeOutcome(
                slot, job.mode, episode_id, int(learner.get("initial_pose", job.pose)),
                int(learner["steps"]), float(learner.get("episode_return", 0.0)),
                bool(learner.get("success", False)), 0.0, "", started,
                "done", "completed as the run stopped (from the learner's checkpoint)"),
                learner)
            return f"slot {slot} ({episode_id}) had completed: taken from the learner's record"
        if self.running is None:
            return "nothing was running"
        slot, episode_id = self.running["slot"], self.running["episode_id"]
        self.cut(slot, episode_id, "the run stopped while it ran")
        return f"slot {slot} ({episode_id}) was cut short: it runs again"

    def _check_next(self, slot: int) -> None:
        if slot != self.next_slot:
            raise ValueError(f"slot {slot} is not the next one ({self.next_slot})")

    def _save(self) -> None:
        write_json_atomically(self.folder / JOURNAL_NAME, {
            "plan": self.plan.to_dict(), "completed": self.completed, "running": self.running,
            "cut_short": self.cut_short, "sessions": self.sessions,
            "next_slot": self.next_slot, "slots": len(self.slots),
            "training_done": sum(o["mode"] == "train" for o in self.completed)})
