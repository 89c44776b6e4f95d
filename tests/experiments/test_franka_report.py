"""The Franka section of results.md: rendered from its data, replaced in place between its
markers (the rest of the page untouched), left alone without data."""
from __future__ import annotations

import json
from pathlib import Path

from qg_experiments.franka_report import BEGIN, COLUMNS, DATA, END, write_section

ROOT = Path(__file__).resolve().parents[2]


def _data(tmp_path: Path, inserted: str) -> Path:
    row = {c: "-" for c in COLUMNS} | {"test poses inserted": inserted}
    path = tmp_path / "franka.json"
    path.write_text(json.dumps({"intro": "Runs.", "rows": [row], "notes": ["A note."]}))
    return path


def test_the_section_replaces_its_old_self_and_nothing_else(tmp_path: Path) -> None:
    results = tmp_path / "results.md"
    results.write_text("# Results\n\nbefore\n")
    write_section(results, _data(tmp_path, "7 of 8"))
    first = results.read_text()
    assert first.startswith("# Results\n\nbefore\n") and first.count(BEGIN) == 1
    assert "| 7 of 8 |" in first and first.rstrip().endswith(END)
    results.write_text(first + "\nafter\n")
    write_section(results, _data(tmp_path, "8 of 8"))
    second = results.read_text()
    assert second.count(BEGIN) == 1 and "| 8 of 8 |" in second and "| 7 of 8 |" not in second
    assert second.startswith("# Results\n\nbefore\n") and second.endswith("after\n")


def test_without_data_the_page_is_left_alone(tmp_path: Path) -> None:
    results = tmp_path / "results.md"
    results.write_text("# Results\n")
    write_section(results, tmp_path / "missing.json")
    assert results.read_text() == "# Results\n"


def test_the_shipped_page_holds_the_shipped_data() -> None:
    page = (ROOT / "docs" / "results.md").read_text()
    data = json.loads((ROOT / DATA).read_text())
    assert page.count(BEGIN) == 1
    for row in data["rows"]:
        assert "| " + " | ".join(str(row[c]) for c in COLUMNS) + " |" in page
