"""Every saved run says which code made it, and the report lists those commits: reuse of saved
runs does not see code changes, so a sweep resumed across commits must show the mix."""
from __future__ import annotations

import subprocess
from pathlib import Path

from qg_experiments.code_version import UNRECORDED, code_version
from qg_experiments.report.markdown import code_label


def test_a_run_records_the_commit_of_its_checkout(tmp_path: Path) -> None:
    here = Path(__file__).resolve().parent
    head = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    version = code_version()
    assert version["commit"] == head and len(head) == 40
    assert isinstance(version["modified"], bool)
    assert code_version(tmp_path) == UNRECORDED          # no checkout there


def test_the_report_counts_runs_per_commit_most_first() -> None:
    runs = [{"code": {"commit": "a" * 40, "modified": False}}] * 3 + \
           [{"code": {"commit": "b" * 40, "modified": True}}] + [{}] * 2
    assert code_label(runs) == ("`aaaaaaaaaa` (3 runs); `bbbbbbbbbb` with modified files (1 runs); "
                                "not recorded (2 runs, saved before runs recorded it)")
    assert code_label([]) == ""
    # a run continued on another commit counts under both; one continued on its own, once
    resumed = [{"code": {"commit": "b" * 40, "modified": False},
                "resumed": [{"episode": 40, "code": {"commit": "a" * 40, "modified": False}}]},
               {"code": {"commit": "a" * 40, "modified": False},
                "resumed": [{"episode": 9, "code": {"commit": "a" * 40, "modified": False}}]}]
    assert code_label(resumed) == ("`aaaaaaaaaa` (2 runs); `bbbbbbbbbb` (1 runs); 2 of them "
                                   "continued from saved progress, counted under each commit "
                                   "they ran on")
