"""The report's divergence call: soft divergence runs away, fitting noise only overshoots."""
from qg_experiments.report.divergence import split_by_excess


def test_only_a_mean_q_beyond_a_tenth_of_the_range_counts_as_diverged():
    # The gamma 0.9 dense-reward range [-10, 0]: DDPG's +44 of the thesis grid diverged, while
    # the QG-DDPG peaks of 0.16-0.23 above 0 are fitting noise of unclipped predictions.
    excess = {"ddpg_runaway": 44.1, "qg_peak": 0.228, "qg_small": 0.016,
              "inside": -0.5, "just_over": 1.01, "at_margin": 1.0}
    diverged, overshot = split_by_excess(excess, (-10.0, 0.0))
    assert diverged == ["just_over", "ddpg_runaway"]
    assert overshot == ["qg_small", "qg_peak", "at_margin"]


def test_the_margin_scales_with_the_range():
    # gamma 0.99: the range is [-100, 0] and the margin 10.
    assert split_by_excess({"a": 9.0, "b": 11.0}, (-100.0, 0.0)) == (["b"], ["a"])
