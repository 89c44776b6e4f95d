"""The section of ``docs/results.md`` on the Franka through libfranka: the demo's learning on the
simulated Panda and on franky-sim's FR3, and the Panda's actor carried over to the FR3 without
further training. Its numbers come from whole ``qgl`` runs (the ROS stack, realtime against
franky-sim), recorded in ``docs/data/franka_rehearsal.json`` with the command of each; the
section is kept between markers so the report's other sections can be regenerated around it.

Usage: python -m qg_experiments.franka_report [--data docs/data/franka_rehearsal.json]
       [--results docs/results.md]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from qg_experiments.report.markdown import FRANKA_BLOCK, write_marked_block

__all__ = ["franka_section", "write_section", "DATA", "BEGIN", "END"]

#: Where the rehearsal's measured runs are kept (relative to the repository).
DATA = Path("docs/data/franka_rehearsal.json")
BEGIN, END = FRANKA_BLOCK
COLUMNS = ("robot", "engine and step", "run", "training inserted", "test poses inserted",
           "mean test steps", "wall time", "command")


def franka_section(data: dict[str, Any]) -> str:
    """The section's markdown from the rehearsal's data (``rows``: one dict a run)."""
    lines = [BEGIN, "## 9. The Franka through libfranka: franky-sim beside the simulated Panda",
             "", data["intro"], "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in data["rows"]:
        lines.append("| " + " | ".join(str(row[c]) for c in COLUMNS) + " |")
    lines += ["", *data.get("notes", []), END, ""]
    return "\n".join(lines)


def write_section(results_md: Path, data_path: Path = DATA) -> None:
    """Replace the marked block in ``results_md`` (or append it); nothing without data."""
    if data_path.exists():
        write_marked_block(results_md, BEGIN, END,
                           franka_section(json.loads(data_path.read_text())))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--results", type=Path, default=Path("docs/results.md"))
    args = parser.parse_args()
    write_section(args.results, args.data)
    print(f"wrote the Franka section of {args.results}")


if __name__ == "__main__":
    main()
