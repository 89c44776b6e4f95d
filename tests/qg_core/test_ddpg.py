"""DDPG train step: target clipping per bound mode, torch-free actor, determinism."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from qg_learning_node.learner.actor_mlp import ActorMLP
from qg_learning_node.learner.ddpg import DDPG, DDPGConfig, realisable_range
from qg_learning_node.learner.replay import Batch, ReplayMemory

torch.set_num_threads(1)


def fixed_batch(n=32, lower=-np.inf, seed=0):
    rng = np.random.default_rng(seed)
    s = rng.uniform(-1, 1, (n, 4))
    return Batch(s, rng.uniform(-1, 1, (n, 2)), np.full(n, -1.0), rng.uniform(-1, 1, (n, 4)),
                 np.zeros(n, dtype=bool), np.full(n, lower))


def test_defaults_follow_spec():
    config = DDPGConfig()
    assert config.actor_hidden == (100, 100) and config.critic_hidden == (100, 100)
    assert config.effective_actor_lr == pytest.approx(1e-4)
    assert not config.target_networks
    assert realisable_range(-1.0, 0.0, 0.99) == pytest.approx((-100.0, 0.0))
    with pytest.raises(ValueError):
        DDPGConfig(bounds='bogus')
    with pytest.raises(ValueError):
        DDPGConfig.from_dict({'batch': 3})


def test_graph_lower_bound_pulls_q_up_to_the_bound():
    small = dict(actor_hidden=(16, 16), critic_hidden=(16, 16), critic_lr=1e-2)
    agent = DDPG(DDPGConfig(bounds='qgraph', **small), 4, 2)
    batch = fixed_batch(lower=5.0)._replace(terminals=np.ones(32, dtype=bool))  # y = r = -1
    assert agent.train_step(batch)['frac_raised_lower'] == 1.0
    for _ in range(300):
        diag = agent.train_step(batch)
    np.testing.assert_allclose(agent.q_values(batch.states, batch.actions), 5.0, atol=0.3)
    vanilla = DDPG(DDPGConfig(bounds='none', **small), 4, 2)
    for _ in range(300):
        vanilla.train_step(batch)
    np.testing.assert_allclose(vanilla.q_values(batch.states, batch.actions), -1.0, atol=0.3)
    assert diag['frac_lowered_upper'] == 0.0


def test_vanilla_ignores_bounds_and_apriori_caps_at_r_max():
    batch = fixed_batch(lower=50.0)._replace(rewards=np.full(32, 3.0))
    vanilla = DDPG(DDPGConfig(bounds='none'), 4, 2).train_step(batch)
    assert vanilla['frac_raised_lower'] == 0.0 and vanilla['frac_lowered_upper'] == 0.0
    capped = DDPG(DDPGConfig(bounds='apriori'), 4, 2).train_step(batch)
    assert capped['frac_lowered_upper'] == 1.0  # r = 3 > r_max / (1 - g) = 0
    both = DDPG(DDPGConfig(bounds='qgraph+apriori'), 4, 2).train_step(batch)
    assert both['frac_lowered_upper'] == 1.0  # upper bound wins over the (wrong) 50
    with pytest.raises(ValueError):
        DDPG(DDPGConfig(bounds='empirical'), 4, 2).train_step(batch)
    emp = DDPG(DDPGConfig(bounds='empirical'), 4, 2).train_step(batch, reward_range=(-1.0, -0.5))
    assert emp['frac_lowered_upper'] == 1.0


def test_he2017_runs_on_replay_context():
    memory = ReplayMemory(None, 4, 2)
    rng = np.random.default_rng(0)
    s = rng.uniform(-1, 1, 4)
    for t in range(40):
        s2 = rng.uniform(-1, 1, 4)
        memory.add(s, rng.uniform(-1, 1, 2), -1.0, s2, t % 20 == 19)
        s = s2
    agent = DDPG(DDPGConfig(bounds='he2017', he_horizon=4), 4, 2)
    batch = memory.sample(16, rng)
    diag = agent.train_step(batch, context=memory.trajectory_context(batch.indices, 4))
    assert np.isfinite(diag['critic_loss'])
    with pytest.raises(ValueError):
        agent.train_step(batch)


def test_numpy_actor_matches_torch_and_seeds_are_deterministic():
    a, b = DDPG(DDPGConfig(seed=3), 4, 2), DDPG(DDPGConfig(seed=3), 4, 2)
    batch = fixed_batch()
    for agent in (a, b):
        for _ in range(5):
            agent.train_step(batch)
    x = np.random.default_rng(1).uniform(-1, 1, (7, 4))
    np.testing.assert_array_equal(a.act(x), b.act(x))
    np.testing.assert_allclose(ActorMLP.from_tensors(a.actor_tensors())(x), a.act(x), atol=1e-6)
    assert np.all(np.abs(a.act(x)) <= 1.0)
    assert DDPG(DDPGConfig(seed=4), 4, 2).act(x[0]).tolist() != a.act(x[0]).tolist()


def test_state_dict_restores_training_exactly():
    config = DDPGConfig(target_networks=True)
    a = DDPG(config, 4, 2)
    batch = fixed_batch()
    a.train_step(batch)
    b = DDPG(config, 4, 2)
    b.load_state_dict(a.state_dict())
    assert a.train_step(batch) == b.train_step(batch)
