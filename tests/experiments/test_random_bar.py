"""The bar a learner must beat is the best random baseline counted like a test episode."""
from __future__ import annotations

import pytest
from qg_experiments.random_baselines import random_bar


def _row(label: str, steps: list[int]) -> dict:
    return {"label": label, "steps": steps}


def test_episodes_are_cut_at_the_test_cap_before_averaging() -> None:
    # Uncut, "steady" has the lower mean (20 < 25.75); cut at 30, the failure of "long tail"
    # only counts 30 and it becomes the bar: (1 + 1 + 1 + 30) / 4.
    rows = [_row("steady", [20, 20, 20, 20]), _row("long tail", [1, 1, 1, 100])]
    assert random_bar(rows, cap=1000) == pytest.approx((20.0, "steady"))
    mean, label = random_bar(rows, cap=30)
    assert label == "long tail"
    assert mean == pytest.approx(8.25)


def test_no_baselines_no_bar() -> None:
    assert random_bar([], cap=30) is None
