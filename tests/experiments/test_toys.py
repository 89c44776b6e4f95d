"""Reference problems: Baird's star and the ch. 7 soft-divergence toys (10 seeds each)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from qg_experiments import toys

torch.set_num_threads(1)


def test_baird_star_bounded_converges_plain_diverges():
    plain_norms, plain_values = toys.baird_star(bounded=False)
    norms, values = toys.baird_star(bounded=True)
    assert plain_norms[-1] > 5 * plain_norms[0]  # spirals out
    assert plain_norms[-1] > plain_norms[len(plain_norms) // 2]  # and keeps growing
    assert np.abs(values).max() < 1e-3  # graph-bounded TD reaches V = 0
    assert norms[-1] < norms[0] and abs(norms[-1] - norms[-100]) < 1e-6


@pytest.mark.slow
def test_ch7_three_state_subsets_std_ordered_by_kind(tmp_path):
    pooled = toys.transition_type_std(seeds=10)
    counts = {k: len(v) for k, v in pooled.items()}
    assert counts == {'directly_connected': 8, 'connected': 8, 'loose_end': 4, 'disconnected': 12}
    med = {k: float(np.median(v)) for k, v in pooled.items()}
    assert med['directly_connected'] < med['connected'] < med['loose_end']
    assert med['connected'] < med['disconnected']
    toys.plot_transition_types(pooled, tmp_path / 'types.png')
    assert (tmp_path / 'types.png').stat().st_size > 10_000


@pytest.mark.slow
def test_ch7_chain_std_grows_with_distance(tmp_path):
    dist, std = toys.chain_std(length=100, seeds=10, steps=1500)  # the figure uses 4000
    np.testing.assert_array_equal(np.sort(dist), np.arange(100))
    near, far = np.median(std[dist < 20]), np.median(std[dist >= 80])
    assert far > 3 * near
    rank_corr = np.corrcoef(np.argsort(np.argsort(dist)), np.argsort(np.argsort(std)))[0, 1]
    assert rank_corr > 0.8
    toys.plot_chain(dist, std, tmp_path / 'chain.png')
    assert (tmp_path / 'chain.png').stat().st_size > 10_000
