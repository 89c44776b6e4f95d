"""TD3's remedies against overestimation as DDPG settings (``ddpg.twin_critics``,
``ddpg.target_noise``): the twins' minimum is the target and the actor's objective, target
actions are smoothed, and both are off by default (the thesis)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from qg_learning_node.learner.ddpg import DDPG, DDPGConfig
from qg_learning_node.learner.learner_config import LearnerConfig
from qg_learning_node.learner.replay import Batch

torch.set_num_threads(1)
SMALL = dict(actor_hidden=(16, 16), critic_hidden=(32, 32), critic_lr=1e-3, bounds='none',
             gamma=0.9)


def batch(n: int = 32, seed: int = 0) -> Batch:
    rng = np.random.default_rng(seed)
    return Batch(rng.uniform(-1, 1, (n, 2)), rng.uniform(-1, 1, (n, 2)), np.full(n, -0.25),
                 rng.uniform(-1, 1, (n, 2)), np.zeros(n, dtype=bool), np.full(n, -np.inf))


def test_the_thesis_networks_are_the_same_with_or_without_the_twin():
    one, two = DDPG(DDPGConfig(**SMALL), 2, 2), DDPG(DDPGConfig(twin_critics=True, **SMALL), 2, 2)
    assert one.critic2 is None and two.critic2 is not None
    for a, b in zip(list(one.actor.parameters()) + list(one.critic.parameters()),
                    list(two.actor.parameters()) + list(two.critic.parameters())):
        assert torch.equal(a, b)
    # the twin is a different network, not a copy
    w1, w2 = two.critic.net[0].weight, two.critic2.net[0].weight
    assert float((w1 - w2).detach().abs().max()) > 0.05


def test_the_value_is_the_twins_minimum_and_the_target_uses_it():
    agent = DDPG(DDPGConfig(twin_critics=True, **SMALL), 2, 2)
    b = batch()
    s, a = torch.as_tensor(b.states, dtype=torch.float32), torch.as_tensor(b.actions, dtype=torch.float32)
    s2 = torch.as_tensor(b.next_states, dtype=torch.float32)
    with torch.no_grad():
        q1, q2 = agent.critic(s, a), agent.critic2(s, a)
        a2 = agent.actor(s2)
        target_min = torch.minimum(agent.critic(s2, a2), agent.critic2(s2, a2))
        target_one = agent.critic(s2, a2)
    np.testing.assert_allclose(agent.q_values(b.states, b.actions),
                               torch.minimum(q1, q2).numpy(), rtol=1e-6)
    assert float((q1 - q2).abs().max()) > 1e-3          # the minimum is not trivially one critic
    y = -0.25 + 0.9 * target_min
    loss = agent.train_step(b)['critic_loss']            # critic 1's loss before its update
    assert loss == pytest.approx(float(torch.mean((y - q1) ** 2)), rel=1e-5)
    assert loss != pytest.approx(float(torch.mean((-0.25 + 0.9 * target_one - q1) ** 2)), rel=1e-3)


def test_both_critics_learn_the_same_target():
    agent = DDPG(DDPGConfig(twin_critics=True, **SMALL), 2, 2)
    b = batch()
    b = Batch(b.states, b.actions, b.rewards, b.next_states, np.ones(len(b.rewards), dtype=bool),
              b.lower_bounds)                            # terminal: the target is r
    for _ in range(400):
        agent.train_step(b)
    s, a = torch.as_tensor(b.states, dtype=torch.float32), torch.as_tensor(b.actions, dtype=torch.float32)
    with torch.no_grad():
        for critic in (agent.critic, agent.critic2):
            assert float((critic(s, a) + 0.25).abs().max()) < 0.03


def test_target_noise_changes_the_target_and_is_seeded():
    b = batch()
    plain = DDPG(DDPGConfig(twin_critics=True, **SMALL), 2, 2).train_step(b)['critic_loss']
    smoothed = [DDPG(DDPGConfig(twin_critics=True, target_noise=0.2, **SMALL), 2, 2)
                .train_step(b)['critic_loss'] for _ in range(2)]
    assert smoothed[0] == smoothed[1]                    # same seed, same noise
    assert smoothed[0] != pytest.approx(plain, rel=1e-4)
    with pytest.raises(ValueError, match='target_noise'):
        DDPGConfig(target_noise=-0.1)


def test_a_twin_checkpoint_round_trips_and_a_single_critic_one_is_refused():
    config = DDPGConfig(twin_critics=True, **SMALL)
    agent = DDPG(config, 2, 2)
    for _ in range(3):
        agent.train_step(batch())
    restored = DDPG(config, 2, 2)
    restored.load_state_dict(agent.state_dict())
    b = batch(seed=5)
    np.testing.assert_array_equal(restored.q_values(b.states, b.actions),
                                  agent.q_values(b.states, b.actions))
    with pytest.raises(ValueError, match='one critic'):
        restored.load_state_dict(DDPG(DDPGConfig(**SMALL), 2, 2).state_dict())
    assert LearnerConfig.from_dict({'ddpg': {'twin_critics': True}}).ddpg.twin_critics
