"""The demo's learning curve draws the simulation's random bar from the report, not a constant."""
from __future__ import annotations

import json
from pathlib import Path

from qg_bringup.episode_schedule import EpisodeOutcome
from qg_bringup.run_report import default_random_bar, load_random_bar, plot_learning_curve

ROOT = Path(__file__).resolve().parents[2]


def test_the_default_bar_is_the_reports_and_a_bad_file_draws_none(tmp_path: Path,
                                                                  capsys) -> None:
    # The bar ships as a config file (nothing is read from docs/ at run time) and is the
    # report's: the numbers of docs/data/thesis/random_bar.json.
    shipped = default_random_bar()
    assert shipped.name == "random_bar.json" and "docs" not in shipped.parts, shipped
    report = json.loads((ROOT / "docs" / "data" / "thesis" / "random_bar.json").read_text())
    assert {k: v for k, v in json.loads(shipped.read_text()).items() if k != "source"} == report
    good = tmp_path / "bar.json"
    good.write_text(json.dumps({"label": "uniform", "mean": 52.5, "low": 41.0, "high": 66.0,
                                "episodes": 40, "cap": 200, "seeds": [100, 101]}))
    bar = load_random_bar(good)
    assert bar["mean"] == 52.5 and bar["low"] == 41.0 and bar["episodes"] == 40
    for text in ("{not json", json.dumps({"label": "uniform"})):
        (tmp_path / "bad.json").write_text(text)
        assert load_random_bar(tmp_path / "bad.json") is None
    assert load_random_bar(tmp_path / "missing.json") is None
    assert "no random bar drawn" in capsys.readouterr().err
    outcomes = [EpisodeOutcome(index=i, mode="train", episode_id=f"e{i}", initial_pose=i % 8,
                               steps=10 + i, episode_return=-3.0, success=True, wall_time=1.0)
                for i in range(3)]
    plot_learning_curve(outcomes, tmp_path / "with.png", bar)
    plot_learning_curve(outcomes, tmp_path / "without.png", None)
    assert (tmp_path / "with.png").stat().st_size > 1000
    assert (tmp_path / "with.png").read_bytes() != (tmp_path / "without.png").read_bytes()
