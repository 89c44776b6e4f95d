"""Stalls of the deterministic test actor are counted only in runs that trained, and a stalled
pose is matched against the same run's training (docs/learning.md, section 15)."""
from __future__ import annotations

from qg_experiments.stalls import run_stalls, stall_counts


def _episodes(train: list[tuple[int, bool]], test: list[tuple[int, bool]]) -> list[dict]:
    return ([{"mode": "train", "pose": p, "success": s} for p, s in train]
            + [{"mode": "test", "pose": p, "success": s} for p, s in test])


def test_a_trained_run_counts_its_failed_tests_and_an_untrained_run_none() -> None:
    # 8 training episodes, the last 6 inserted (poses 2..7), then 8 tests failing on 0, 3, 5.
    trained = _episodes([(p, p >= 2) for p in range(8)], [(p, p not in (0, 3, 5))
                                                          for p in range(8)])
    assert run_stalls(trained) == {"test_episodes": 8, "stalled": 3,
                                   "stalled_poses_inserted_in_training": 2}   # 3 and 5, not 0
    untrained = _episodes([(p, p >= 3) for p in range(8)], [(p, False) for p in range(8)])
    assert run_stalls(untrained) is None                 # 5 of the last 8: it never learned
    assert run_stalls(untrained, trained_at=5) == {"test_episodes": 8, "stalled": 8,
                                                   "stalled_poses_inserted_in_training": 5}
    counts = stall_counts([("qgddpg", trained), ("qgddpg", untrained), ("ddpg", trained)])
    assert counts["qgddpg"] == {"runs": 2, "trained": 1, "trained_test_episodes": 8,
                                "stalled_test_episodes": 3, "runs_with_a_stall": 1,
                                "stalled_poses_inserted_in_training": 2}
    assert counts["ddpg"]["stalled_test_episodes"] == 3
