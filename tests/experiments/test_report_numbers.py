"""A number in results.md reads the same wherever it appears, and a diverged critic's error
(tens of millions) as its size rather than a row of digits."""
from __future__ import annotations

from qg_experiments.report.markdown import fmt


def test_a_number_has_its_decimals_and_a_huge_one_its_power_of_ten() -> None:
    assert fmt(2.4156, 2) == "2.42"
    assert fmt(999999.0, 1) == "999999.0"
    assert fmt(78658078.80, 2) == "7.87e+07"
    assert fmt(-13310915113.852, 3) == "-1.33e+10"
    assert fmt(None) == fmt(float("nan")) == "n/a"
