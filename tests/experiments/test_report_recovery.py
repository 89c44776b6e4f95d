"""results.md section 7: the deterministic test actor's stalls and the actor with stall recovery
stand in separate columns, and recovery episodes never enter the test numbers."""
from __future__ import annotations

import csv
from pathlib import Path

from qg_experiments.report.comparison import graph_section
from qg_experiments.report.tables import episodes_csv


def _run(algorithm: str, seed: int, recovery: bool) -> dict:
    """A trained run (8 inserted training episodes) whose deterministic test stalls on poses 0
    and 1 (cap 200); with ``recovery`` the 8 poses once more, all inserted in 20 steps."""
    spec = {"algorithm": algorithm, "critic_lr": 1e-2, "iterations": 50, "reward": "dense",
            "replay_capacity": None, "gamma": None, "observation": None, "seed": seed,
            "stall_recovery": recovery}
    episodes = [{"mode": "train", "pose": p, "success": True, "steps": 30} for p in range(8)]
    episodes += [{"mode": "test", "pose": p, "success": p > 1, "steps": 200 if p < 2 else 10}
                 for p in range(8)]
    if recovery:
        episodes += [{"mode": "recovery", "pose": p, "success": True, "steps": 20,
                      "recoveries": 2 if p < 2 else 0} for p in range(8)]
    return {"name": f"{algorithm}_s{seed}", "spec": spec, "episodes": episodes,
            "cycles": [{"mean_q": -0.5, "frac_raised_lower": 0.1, "critic_mc_error": 0.2}],
            "wall_time": 1.0}


def _row(lines: list[str]) -> list[str]:
    header = next(line for line in lines if line.startswith("| setting"))
    row = next(line for line in lines if line.startswith("| the grid"))
    return [c.strip() for c in header.split("|")[1:-1]], [c.strip() for c in row.split("|")[1:-1]]


def test_recovery_has_its_own_column_and_leaves_the_test_numbers_alone() -> None:
    plain = [_run(a, s, False) for a in ("qgddpg", "ddpg") for s in range(3)]
    recovered = [_run(a, s, a == "qgddpg") for a in ("qgddpg", "ddpg") for s in range(3)]
    names, without = _row(graph_section({"the grid": plain}, None, 0.9))
    _, with_recovery = _row(graph_section({"the grid": recovered}, None, 0.9))
    stalled = names.index("stalled test episodes (deterministic actor)")
    column = names.index("inserted with stall recovery")
    assert without[stalled] == with_recovery[stalled] == "6 of 24 / 6 of 24"
    assert without[column] == "— / —"
    assert with_recovery[column] == "24 of 24 (12 recoveries) / —"   # QG-DDPG's runs only
    # Every other number of the row is the same with recovery episodes saved or not.
    assert [c for i, c in enumerate(without) if i != column] == \
        [c for i, c in enumerate(with_recovery) if i != column]


def test_the_episodes_csv_keeps_the_recovery_episodes_counts(tmp_path: Path) -> None:
    path = tmp_path / "grid_episodes.csv"
    episodes_csv(path, [_run("qgddpg", 0, True), _run("ddpg", 0, False)])
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 24 + 16
    recovery = [r for r in rows if r["mode"] == "recovery"]
    assert [r["recoveries"] for r in recovery] == ["2", "2"] + ["0"] * 6
    assert all(r["recoveries"] == "" for r in rows if r["mode"] != "recovery")
