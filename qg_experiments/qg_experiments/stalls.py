"""Stalls of the deterministic test actor (docs/learning.md, section 15).

A run that learned to insert with exploration noise can still fail test poses: without the noise
its actor may hold the shaft at a fixed point until the test cap. Counted here as the report and
``benchmarks/stall_counts.py`` count them: a run *trained* when at least :data:`TRAINED_AT` of
its last :data:`LAST_TRAINING` training episodes inserted, and a *stall* is a test episode of
such a run that did not insert.
"""
from __future__ import annotations

from collections import Counter
from typing import Any, Iterable

__all__ = ["TRAINED_AT", "LAST_TRAINING", "run_stalls", "stall_counts"]

#: Training episodes looked at, from the end, to call a run trained.
LAST_TRAINING = 8
#: How many of them must have inserted.
TRAINED_AT = 6


def run_stalls(episodes: list[dict[str, Any]], trained_at: int = TRAINED_AT
               ) -> dict[str, int] | None:
    """One run's stalls; ``None`` when the run did not train (then a failed test is no stall).

    :param episodes: the run's episodes in order, each with ``mode`` (train or test), ``pose``
        and ``success`` (bool).
    :returns: its test episodes, the stalled ones, and how many of those the run had inserted
        from the same pose in training.
    """
    train = [e for e in episodes if e["mode"] == "train"]
    if sum(bool(e["success"]) for e in train[-LAST_TRAINING:]) < trained_at:
        return None
    test = [e for e in episodes if e["mode"] == "test"]
    stalled = [e for e in test if not e["success"]]
    inserted = {e["pose"] for e in train if e["success"]}
    return {"test_episodes": len(test), "stalled": len(stalled),
            "stalled_poses_inserted_in_training": sum(e["pose"] in inserted for e in stalled)}


def stall_counts(runs: Iterable[tuple[str, list[dict[str, Any]]]],
                 trained_at: int = TRAINED_AT) -> dict[str, dict[str, int]]:
    """Per algorithm, over ``(algorithm, episodes)`` of many runs: runs, runs trained, runs with
    a stall, the trained runs' test episodes, the stalled ones, and the stalled poses the same
    run had inserted in training."""
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
    return {algorithm: dict(c) for algorithm, c in out.items()}
