"""The report's statistics on data whose answers are known."""
from __future__ import annotations

import numpy as np
import pytest
from qg_experiments.stats import (Interval, beats, format_interval, mean_interval,
                                                paired_comparison)


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
