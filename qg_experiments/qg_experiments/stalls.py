"""Stalls of the deterministic test actor (docs/learning.md, section 15).

A run that learned to insert with exploration noise can still fail test poses: without the noise
its actor may hold the shaft at a fixed point until the test cap. Counted here as the report and
``benchmarks/stall_counts.py`` count them: a run *trained* when at least :data:`TRAINED_AT` of
its last :data:`LAST_TRAINING` training episodes inserted, and a *stall* is a test episode of
such a run that did not insert.

Stall recovery (``executor/stall_recovery.py``) is counted apart: a run saved with
``RunSpec.stall_recovery`` has its test poses once more with recovery, as episodes of mode
:data:`RECOVERY_MODE`, which no test number reads (they all read mode ``test``). Their counts
here (:func:`run_recoveries`) stand beside the deterministic actor's, never inside them.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from typing import Any

__all__ = ["TRAINED_AT", "LAST_TRAINING", "RECOVERY_MODE", "run_stalls", "run_recoveries",
           "stall_counts", "recovery_text"]

#: Training episodes looked at, from the end, to call a run trained.
LAST_TRAINING = 8
#: How many of them must have inserted.
TRAINED_AT = 6
#: The mode of a run's test episodes run again with stall recovery.
RECOVERY_MODE = "recovery"


def _trained(episodes: list[dict[str, Any]], trained_at: int) -> bool:
    train = [e for e in episodes if e["mode"] == "train"]
    return sum(bool(e["success"]) for e in train[-LAST_TRAINING:]) >= trained_at


def run_stalls(episodes: list[dict[str, Any]], trained_at: int = TRAINED_AT
               ) -> dict[str, int] | None:
    """One run's stalls; ``None`` when the run did not train (then a failed test is no stall).

    :param episodes: the run's episodes in order, each with ``mode`` (train or test), ``pose``
        and ``success`` (bool).
    :returns: its test episodes, the stalled ones, and how many of those the run had inserted
        from the same pose in training.
    """
    if not _trained(episodes, trained_at):
        return None
    train = [e for e in episodes if e["mode"] == "train"]
    test = [e for e in episodes if e["mode"] == "test"]
    stalled = [e for e in test if not e["success"]]
    inserted = {e["pose"] for e in train if e["success"]}
    return {"test_episodes": len(test), "stalled": len(stalled),
            "stalled_poses_inserted_in_training": sum(e["pose"] in inserted for e in stalled)}


def run_recoveries(episodes: list[dict[str, Any]], trained_at: int = TRAINED_AT
                   ) -> dict[str, int] | None:
    """One run's test poses with stall recovery; ``None`` when the run did not train or was
    not run with recovery.

    :param episodes: as :func:`run_stalls`; the recovery episodes (mode :data:`RECOVERY_MODE`)
        carry ``recoveries``.
    :returns: the recovery episodes, those that inserted, and the recoveries applied.
    """
    runs = [e for e in episodes if e["mode"] == RECOVERY_MODE]
    if not runs or not _trained(episodes, trained_at):
        return None
    return {"recovery_episodes": len(runs),
            "inserted_with_recovery": sum(bool(e["success"]) for e in runs),
            "recoveries": sum(int(e.get("recoveries", 0)) for e in runs)}


def stall_counts(runs: Iterable[tuple[str, list[dict[str, Any]]]],
                 trained_at: int = TRAINED_AT) -> dict[str, dict[str, int]]:
    """Per algorithm, over ``(algorithm, episodes)`` of many runs: runs, runs trained, runs with
    a stall, the trained runs' test episodes, the stalled ones, and the stalled poses the same
    run had inserted in training; where trained runs were run with stall recovery too, apart:
    those runs, their recovery episodes, the inserted ones and the recoveries."""
    out: dict[str, Counter] = {}
    for algorithm, episodes in runs:
        c = out.setdefault(algorithm, Counter())
        c["runs"] += 1
        one = run_stalls(episodes, trained_at)
        if one is None:
            continue
        c["trained"] += 1
        c["trained_test_episodes"] += one["test_episodes"]
        c["stalled_test_episodes"] += one["stalled"]
        c["runs_with_a_stall"] += bool(one["stalled"])
        c["stalled_poses_inserted_in_training"] += one["stalled_poses_inserted_in_training"]
        recovered = run_recoveries(episodes, trained_at)
        if recovered is not None:
            c["trained_with_recovery"] += 1
            for key, value in recovered.items():
                c[key] += value
    return {algorithm: dict(c) for algorithm, c in out.items()}


def recovery_text(counts: dict[str, int]) -> str:
    """One algorithm's recovery counts as the report prints them: ``7 of 8 (3 recoveries)``;
    a dash when none of its trained runs ran with recovery."""
    if not counts.get("recovery_episodes"):
        return "—"
    return (f"{counts['inserted_with_recovery']} of {counts['recovery_episodes']} "
            f"({counts['recoveries']} recoveries)")
