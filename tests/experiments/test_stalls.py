"""Stalls of the deterministic test actor are counted only in runs that trained, and a stalled
pose is matched against the same run's training (docs/learning.md, section 15)."""
from __future__ import annotations

from qg_experiments.stalls import recovery_text, run_recoveries, run_stalls, stall_counts


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


def test_recovery_is_counted_apart_and_only_for_trained_runs() -> None:
    # The same trained run with its 8 test poses once more with recovery: 7 inserted, 9
    # recoveries. Its deterministic stalls stay 3 of 8: recovery never enters them.
    trained = _episodes([(p, p >= 2) for p in range(8)], [(p, p not in (0, 3, 5))
                                                          for p in range(8)])
    recovered = trained + [{"mode": "recovery", "pose": p, "success": p != 4,
                            "recoveries": 2 if p in (0, 3, 5) else int(p == 4) * 3}
                           for p in range(8)]
    assert run_recoveries(trained) is None                     # not run with recovery
    assert run_recoveries(recovered) == {"recovery_episodes": 8, "inserted_with_recovery": 7,
                                         "recoveries": 9}
    untrained = _episodes([(p, p >= 3) for p in range(8)], [(p, False) for p in range(8)])
    assert run_recoveries(untrained + recovered[16:]) is None
    counts = stall_counts([("qgddpg", recovered), ("qgddpg", trained)])["qgddpg"]
    assert counts["stalled_test_episodes"] == 6 and counts["trained_test_episodes"] == 16
    assert (counts["trained_with_recovery"], counts["recovery_episodes"],
            counts["inserted_with_recovery"], counts["recoveries"]) == (1, 8, 7, 9)
    assert recovery_text(counts) == "7 of 8 (9 recoveries)"
    assert recovery_text(stall_counts([("ddpg", trained)])["ddpg"]) == "—"
