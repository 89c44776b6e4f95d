"""The report's statistics on data whose answers are known."""
from __future__ import annotations

import math

import numpy as np
import pytest
from qg_experiments.stats import (
    Interval,
    beats,
    format_interval,
    mean_interval,
    paired_comparison,
    pairs_to_detect,
)


def test_the_interval_covers_the_mean_and_narrows_with_more_data():
    rng = np.random.default_rng(1)
    small, large = rng.normal(10.0, 2.0, 10), rng.normal(10.0, 2.0, 1000)
    a, b = mean_interval(small), mean_interval(large)
    assert a.low < a.mean < a.high and b.low < b.mean < b.high
    assert a.mean == pytest.approx(small.mean())
    assert (b.high - b.low) < (a.high - a.low) / 5
    # 1000 normal draws: the bootstrap interval is the textbook 1.96 s / sqrt(n).
    half = 1.96 * large.std(ddof=1) / np.sqrt(large.size)
    assert (b.high - b.low) / 2 == pytest.approx(half, rel=0.1)
    assert b.low < 10.0 < b.high


def test_the_interval_covers_the_true_mean_about_95_percent_of_the_time():
    rng = np.random.default_rng(7)
    inside = 0
    trials = 200
    for k in range(trials):
        sample = rng.exponential(1.0, 30)
        interval = mean_interval(sample, seed=k)
        inside += interval.low < 1.0 < interval.high
    assert 0.88 <= inside / trials <= 0.99


def test_degenerate_samples_give_a_point_and_a_fixed_seed_repeats():
    assert mean_interval([200.0] * 5) == Interval(200.0, 200.0, 200.0, 5)
    assert mean_interval([7.0]) == Interval(7.0, 7.0, 7.0, 1)
    # One failure at the cap among ties: BCa is undefined there, the interval still exists.
    odd = mean_interval([5.0, 5.0, 5.0, 5.0, 200.0])
    assert odd.mean == 44.0 and odd.low >= 5.0 and odd.high <= 200.0 and odd.high > odd.low
    assert mean_interval([1.0, 4.0, 9.0, 3.0]) == mean_interval([1.0, 4.0, 9.0, 3.0])
    with pytest.raises(ValueError):
        mean_interval([])
    with pytest.raises(ValueError):
        mean_interval([1.0, float("nan")])


def test_beating_the_bar_needs_the_whole_interval_below_it():
    assert beats(Interval(20.0, 15.0, 30.0, 5), 31.0)
    assert not beats(Interval(20.0, 15.0, 35.0, 5), 31.0)
    assert format_interval(Interval(12.34, 8.06, 17.0, 5)) == "12.3 [8.1, 17.0]"


def test_paired_comparison_finds_a_consistent_improvement_and_not_noise():
    rng = np.random.default_rng(3)
    b = rng.uniform(20.0, 60.0, 40)
    better = paired_comparison(b - 5.0 + rng.normal(0.0, 1.0, 40), b)
    assert better.wins_a == 40 and better.wins_b == 0 and better.ties == 0
    assert better.wilcoxon_p < 1e-6 and better.sign_p < 1e-6 and better.significant()
    assert better.difference.mean == pytest.approx(5.0, abs=0.5)
    noise = paired_comparison(b + rng.normal(0.0, 1.0, 40), b)
    assert noise.wilcoxon_p > 0.05 and not noise.significant()
    worse = paired_comparison(b + 5.0, b)
    assert worse.wilcoxon_p < 1e-6 and not worse.significant()


def test_paired_comparison_counts_ties_and_matches_scipy_on_a_small_known_case():
    a = [5.0, 6.0, 200.0, 7.0, 8.0, 10.0]
    b = [5.0, 9.0, 200.0, 30.0, 200.0, 12.0]
    result = paired_comparison(a, b)
    assert (result.wins_a, result.wins_b, result.ties) == (4, 0, 2)
    # Four positive differences, none negative: the exact two-sided sign test gives 2 / 2^4.
    assert result.sign_p == pytest.approx(0.125)
    # Wilcoxon, zeros dropped, ranks 1..4 all positive: exact two-sided p = 2 / 2^4.
    assert result.wilcoxon_p == pytest.approx(0.125)
    assert paired_comparison([3.0, 3.0], [3.0, 3.0]).wilcoxon_p == 1.0
    with pytest.raises(ValueError):
        paired_comparison([1.0, 2.0], [1.0])


def test_paired_events_count_the_discordant_pairs_and_test_them_exactly():
    from qg_experiments.stats import paired_events
    a = [False] * 12 + [True]              # QG-DDPG: one run with the event
    b = [True] * 10 + [False] * 2 + [True]  # DDPG: ten more
    e = paired_events(a, b)
    assert (e.only_a, e.only_b, e.both, e.neither) == (0, 10, 1, 2)
    assert e.p == pytest.approx(2 * 0.5 ** 10)          # exact two-sided binomial, 10 vs 0
    balanced = paired_events([True, False] * 5, [False, True] * 5)
    assert balanced.only_a == balanced.only_b == 5 and balanced.p == pytest.approx(1.0)
    assert paired_events([False] * 4, [False] * 4).p == 1.0
    with pytest.raises(ValueError):
        paired_events([True], [True, False])


# --- the aggregates (Agarwal et al. 2021) and the verdicts ---------------------------------------
#: rliable's own test matrices (``tests/rliable/metrics_test.py``: runs x tasks) and its values.
RLIABLE_X = np.array([[1, 2], [2, 2], [1, 1], [2, 1]], dtype=float)
RLIABLE_Y = np.array([[1, 1], [2, 2], [3, 3]], dtype=float)


def test_iqm_and_probability_of_improvement_give_rliables_published_values():
    from qg_experiments.aggregates import iqm, probability_of_improvement
    assert iqm(RLIABLE_X) == 1.5 and iqm(RLIABLE_Y) == 2.0
    assert probability_of_improvement(RLIABLE_X, RLIABLE_Y) == pytest.approx(1 / 3)
    assert probability_of_improvement(RLIABLE_Y, RLIABLE_Y) == 0.5      # ties count half
    # The IQM drops the lowest and highest quarter: one run stuck at the cap moves it little.
    assert iqm(np.array([[4.0, 5.0, 6.0, 200.0]])) == 5.5


def test_the_stratified_bootstrap_resamples_runs_within_each_task_only():
    from qg_experiments.aggregates import count_below, profile_band, stratified_interval
    # Every run of task j scores j: resampling runs within tasks cannot change anything.
    fixed = np.tile(np.arange(8.0), (5, 1))
    assert stratified_interval(fixed) == Interval(3.5, 3.5, 3.5, 40)
    assert count_below(fixed, 2.5) == Interval(3.0, 3.0, 3.0, 40)       # tasks 0, 1, 2
    profile, low, high = profile_band(fixed, [-1.0, 3.5, 7.0])
    assert profile.tolist() == low.tolist() == high.tolist() == [1.0, 0.5, 0.0]
    with pytest.raises(ValueError):
        stratified_interval(np.array([1.0, 2.0]))                        # not runs x tasks


def test_holm_adjusts_a_family_step_down_and_keeps_its_order():
    from qg_experiments.stats import holm
    # Sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1 = 0.02, 0.03, 0.06, 0.04 -> monotone.
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, 0.9]) == [1.0, 1.0] and holm([0.2]) == [0.2]


def test_tost_finds_equivalence_inside_the_margin_and_not_outside_it():
    from qg_experiments.stats import equivalence_p, verdict
    a = np.arange(20.0)
    small = a + np.linspace(-2.0, 2.0, 20)          # every difference within 2 of zero
    # All 20 shifted differences on one side: the exact one-sided Wilcoxon p is 2^-20.
    assert equivalence_p(a, small, 10.0) == pytest.approx(0.5 ** 20)
    assert equivalence_p(a, a + 15.0 + np.linspace(-2.0, 2.0, 20), 10.0) > 0.5
    assert verdict(5.0, 0.01, 0.9) == "A better" and verdict(-5.0, 0.01, 0.9) == "B better"
    assert verdict(1.0, 0.3, 0.01) == "equivalent" and verdict(1.0, 0.3, 0.3) == "undecided"


def test_the_intervals_agree_with_the_ones_rliable_computes():
    from qg_experiments.aggregates import improvement_interval, profile_band, stratified_interval
    # rliable 1.2.0 (with pandas 2; arch fails to import under pandas 3) on these 5 x 8 scores,
    # its default percentile intervals, 10,000 (IQM) and 5,000 (improvement, profile) resamples:
    x = np.arange(40.0).reshape(5, 8) % 7 + np.linspace(0.0, 1.0, 8)
    y = np.flip(x, axis=0) * 1.3 - 2.0
    rliable = {"iqm x": (3.3, 2.55, 4.0643), "iqm y": (2.29, 1.3057, 3.2743),
               "improvement": (0.655, 0.52, 0.78)}
    ours = {"iqm x": stratified_interval(x), "iqm y": stratified_interval(y),
            "improvement": improvement_interval(x, y)}
    for name, (point, low, high) in rliable.items():
        got = ours[name]
        assert got.mean == pytest.approx(point), name
        # Different generators: the ends agree within the resampling error (a few hundredths).
        assert (got.low, got.high) == pytest.approx((low, high), abs=0.05), name
    profile, low, high = profile_band(x, [0.0, 2.0, 4.0, 6.0])
    assert profile.tolist() == [0.975, 0.675, 0.375, 0.125]
    assert low == pytest.approx([0.925, 0.55, 0.25, 0.025], abs=0.05)
    assert high == pytest.approx([1.0, 0.8, 0.5, 0.225], abs=0.05)


def test_pairs_to_detect_is_the_normal_approximation_and_grows_as_the_difference_shrinks():
    # Differences 0, 4, 8, ..., 36: mean 18, standard deviation 12.11; with z(0.975) = 1.960 and
    # z(0.8) = 0.8416, n = ((1.960 + 0.8416) * 12.11 / 18)^2 = 3.55 pairs.
    a = np.zeros(10)
    b = np.arange(10) * 4.0
    n, sd = pairs_to_detect(a, b)
    assert sd == pytest.approx(12.1106, abs=1e-4)
    assert n == pytest.approx(3.552, abs=1e-3)
    # A quarter of the difference with the same spread needs 16 times the pairs.
    n_small, _ = pairs_to_detect(a, b - 13.5)
    assert n_small == pytest.approx(16 * n, rel=1e-9)
    assert pairs_to_detect(a, b - 18.0)[0] == math.inf       # no difference to detect
    assert pairs_to_detect([1.0], [2.0])[0] == math.inf      # one pair: spread unknown
