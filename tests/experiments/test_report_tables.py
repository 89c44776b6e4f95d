"""The CSVs beside results.md are the page's data: a table without rows leaves no file, not the
file an earlier step's runs left there."""
from __future__ import annotations

import csv

from qg_experiments.report.tables import episodes_csv, write_csv


def test_rows_are_written_and_a_table_without_rows_removes_the_old_file(tmp_path) -> None:
    path = tmp_path / "data" / "state_grid_summary.csv"
    write_csv(path, [{"algorithm": "ddpg", "mean_test_steps": 4.2, "curve": [1, 2]},
                     {"algorithm": "qgddpg", "mean_test_steps": 5.0, "curve": [3]}])
    with path.open() as f:
        rows = list(csv.DictReader(f))
    assert [(r["algorithm"], float(r["mean_test_steps"])) for r in rows] == \
        [("ddpg", 4.2), ("qgddpg", 5.0)]
    assert "curve" not in rows[0]                 # list-valued columns are left out
    write_csv(path, [])
    assert not path.exists()
    episodes = tmp_path / "data" / "state_grid_episodes.csv"
    episodes_csv(episodes, [{"name": "ddpg_s0", "episodes": [{"mode": "test", "steps": 7}]}])
    assert episodes.read_text().splitlines() == ["run,mode,steps", "ddpg_s0,test,7"]
    episodes_csv(episodes, [])
    assert not episodes.exists()
