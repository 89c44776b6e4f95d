"""A training run's plan and journal (``qg_bringup/run_journal.py``): the schedule is fixed by the
plan, the journal is whole after every change, and a resumed run settles the slot that was
running when it stopped."""
from __future__ import annotations

import json

import pytest
from qg_bringup.episode_schedule import EpisodeOutcome
from qg_bringup.run_journal import RunJournal, RunMismatch, RunPlan


def _outcome(slot: int, mode: str, steps: int, episode_id: str = "") -> EpisodeOutcome:
    return EpisodeOutcome(slot, mode, episode_id or f"e{slot}", slot % 8, steps, -1.0, True, 2.0)


def test_the_schedule_has_n_training_episodes_and_test_rounds_at_fixed_slots() -> None:
    plan = RunPlan(episodes=5, test_every=2, test_poses=2, seed=10)
    slots = plan.slots()
    assert [(j.mode, j.pose) for j in slots] == [
        ("train", 0), ("train", 1), ("test", 0), ("test", 1), ("train", 2), ("train", 3),
        ("test", 0), ("test", 1), ("train", 4), ("test", 0), ("test", 1)]
    assert [j.index for j in slots] == list(range(11))
    assert [j.seed for j in slots] == list(range(10, 21))
    # The demo's numbers: 40 training episodes from poses i mod 8, then the 8 tests.
    demo = RunPlan(episodes=40, test_poses=8, seed=1).slots()
    assert [(j.mode, j.pose, j.seed) for j in demo[:9]] == [("train", i % 8, 1 + i)
                                                            for i in range(9)]
    assert [(j.mode, j.pose, j.seed) for j in demo[40:]] == [("test", p, 41 + p)
                                                             for p in range(8)]
    for bad, word in (({"episodes": 0}, "--episodes"), ({"episodes": 2, "test_every": -1},
                      "--test-every"), ({"episodes": 2, "test_poses": 9}, "--test-poses")):
        with pytest.raises(ValueError, match=word):
            RunPlan(**bad)


def test_the_journal_continues_where_it_stopped_and_refuses_another_plan(tmp_path) -> None:
    plan = RunPlan(episodes=3, test_poses=1, settings={"critic_lr": 0.01})
    journal = RunJournal.open(tmp_path, plan)
    journal.begin_session()
    journal.started(0, "e0")
    journal.complete(_outcome(0, "train", 7), {"transitions": 7})
    journal.started(1, "e1")          # ... and the run stops here
    with pytest.raises(ValueError, match="not the next one"):
        journal.started(3, "e3")

    again = RunJournal.open(tmp_path, plan)
    assert again.next_slot == 1 and again.running["episode_id"] == "e1"
    assert again.reconcile({"episode_id": "e0", "state": "done", "transitions": 7}) \
        == "slot 1 (e1) was cut short: it runs again"
    assert again.next_slot == 1 and again.attempts(1) == 1 and again.running is None
    assert [j.index for j in again.remaining()] == [1, 2, 3]
    saved = json.loads((tmp_path / "journal.json").read_text())
    assert saved["next_slot"] == 1 and saved["cut_short"][0]["reason"] == \
        "the run stopped while it ran"
    assert not list(tmp_path.glob("*.tmp"))
    with pytest.raises(RunMismatch, match=r"episodes 3 there, 4 asked"):
        RunJournal.open(tmp_path, RunPlan(episodes=4, test_poses=1,
                                          settings={"critic_lr": 0.01}))


def test_a_slot_the_learner_checkpointed_before_the_run_stopped_is_complete(tmp_path) -> None:
    plan = RunPlan(episodes=2, test_poses=0)
    journal = RunJournal.open(tmp_path, plan)
    journal.started(0, "e0")
    learner = {"episode_id": "e0", "state": "done", "steps": 9, "episode_return": -2.5,
               "success": True, "initial_pose": 0, "transitions": 9}
    note = RunJournal.open(tmp_path, plan).reconcile(learner)
    assert note.startswith("slot 0 (e0) had completed")
    resumed = RunJournal.open(tmp_path, plan)
    assert resumed.next_slot == 1 and resumed.steps() == 9 and resumed.cut_short == []
    (outcome,) = resumed.outcomes()
    assert (outcome.episode_id, outcome.steps, outcome.success) == ("e0", 9, True)
    resumed.started(1, "e1")
    resumed.complete(_outcome(1, "train", 4, "e1"))
    assert resumed.finished and RunJournal.open(tmp_path, plan).steps("train") == 13


def test_an_episode_the_journal_never_heard_of_but_the_learner_checkpointed_completes_its_slot(
        tmp_path) -> None:
    """Ctrl-C between the start request and the executor's reply: the journal never noted the
    episode, but it ran to ``done`` and the learner checkpointed it. Running the slot again
    would leave its transitions in the learner twice: the slot is complete instead."""
    plan = RunPlan(episodes=3, test_poses=0)
    journal = RunJournal.open(tmp_path, plan)
    journal.started(0, "e0")
    journal.complete(_outcome(0, "train", 4, "e0"), {"transitions": 4})
    again = RunJournal.open(tmp_path, plan)
    assert again.running is None
    assert again.reconcile({"episode_id": "e0", "state": "done", "steps": 4,
                            "transitions": 4}) == "nothing was running"
    learner = {"episode_id": "e1", "mode": "train", "state": "done", "steps": 3,
               "initial_pose": 1, "transitions": 7}
    assert again.reconcile(learner).startswith("slot 1 (e1) had completed")
    assert again.next_slot == 2 and again.steps() == 7 and again.cut_short == []
    # a test episode's record never completes a training slot
    other = RunJournal.open(tmp_path / "other", plan)
    assert other.reconcile({**learner, "mode": "test"}) == "nothing was running"
    assert other.next_slot == 0
