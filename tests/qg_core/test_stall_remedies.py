"""The two settings against the deterministic actor's stalls (docs/learning.md section 17):
self-loop targets in the learner (``ddpg.self_loop_tol``) and clean training steps in the
executor's noise (``noise.clean_fraction``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from qg_learning_node.executor.noise import ActionNoise, NoiseConfig
from qg_learning_node.learner.ddpg import DDPG, DDPGConfig
from qg_learning_node.learner.learner_config import LearnerConfig
from qg_learning_node.learner.replay import Batch

torch.set_num_threads(1)
SMALL = dict(actor_hidden=(16, 16), critic_hidden=(32, 32), critic_lr=3e-3, bounds='none')
GAMMA = 0.9


def loop_batch(motion: float, n: int = 32) -> Batch:
    """Transitions at rest whose state moved by ``motion``; reward -0.25 each."""
    rng = np.random.default_rng(0)
    s = rng.uniform(-0.2, 0.2, (n, 2))
    return Batch(s, rng.uniform(-1, 1, (n, 2)), np.full(n, -0.25), s + motion,
                 np.zeros(n, dtype=bool), np.full(n, -np.inf))


def fitted_q(tol: float, motion: float, steps: int = 400) -> np.ndarray:
    agent = DDPG(DDPGConfig(gamma=GAMMA, self_loop_tol=tol, **SMALL), 2, 2)
    batch = loop_batch(motion)
    for _ in range(steps):
        agent.train_step(batch)
    return agent.q_values(batch.states, batch.actions)


@pytest.mark.slow
def test_a_self_loop_takes_the_value_of_repeating_its_action_forever():
    # r / (1 - gamma) = -2.5: with the setting the critic fits it (within 0.1 on average) ...
    q = fitted_q(tol=1e-3, motion=1e-4)
    assert np.abs(q + 2.5).mean() < 0.1, q
    # ... bootstrapping the same loops from the critic (the thesis) is still far from it
    q_thesis = fitted_q(tol=0.0, motion=1e-4)
    assert np.abs(q_thesis + 2.5).min() > 0.5, q_thesis


@pytest.mark.slow
def test_a_step_that_moved_more_than_the_tolerance_is_no_self_loop():
    assert np.allclose(fitted_q(tol=1e-3, motion=0.05), fitted_q(tol=0.0, motion=0.05))


def test_terminal_steps_are_never_self_loops():
    agent = DDPG(DDPGConfig(gamma=GAMMA, self_loop_tol=1e-3, **SMALL), 2, 2)
    batch = loop_batch(0.0)
    batch = batch._replace(terminals=np.ones(len(batch.rewards), dtype=bool))
    assert not agent._self_loops(batch).any()
    assert agent._self_loops(loop_batch(0.0)).all()


def test_self_loop_tol_is_checked():
    with pytest.raises(ValueError, match='self_loop_tol'):
        DDPGConfig(self_loop_tol=-1e-3)
    assert LearnerConfig.from_dict({'ddpg': {'self_loop_tol': 1e-3}}).ddpg.self_loop_tol == 1e-3


def test_clean_steps_send_the_actors_own_action_at_their_rate():
    noise = ActionNoise(NoiseConfig(clean_fraction=0.25), 2, seed=7)
    action = np.array([0.2, -0.4])
    out = np.array([noise.explore(action) for _ in range(4000)])
    clean = np.all(out == action, axis=1)
    assert 0.22 < clean.mean() < 0.28, clean.mean()
    # the noisy steps carry the training noise (sigma 0.3)
    assert 0.25 < np.std(out[~clean, 0]) < 0.35


def test_without_clean_steps_exploration_is_the_thesis_noise_sample_for_sample():
    thesis = NoiseConfig(clean_fraction=0.0)
    a, b = ActionNoise(thesis, 2, seed=3), ActionNoise(thesis, 2, seed=3)
    action = np.array([0.1, 0.1])
    assert all(np.array_equal(a.explore(action), b.perturb(action)) for _ in range(200))


def test_the_noise_samples_do_not_depend_on_the_clean_fraction():
    """The clean steps draw from their own stream: a noisy step of a run with clean steps is
    the same noise sample as the thesis run's, step for step."""
    with_clean = ActionNoise(NoiseConfig(clean_fraction=0.5), 2, seed=11)
    thesis = ActionNoise(NoiseConfig(clean_fraction=0.0), 2, seed=11)
    action = np.zeros(2)
    noisy = [x for x in (with_clean.explore(action) for _ in range(400)) if np.any(x != 0)]
    assert 150 < len(noisy) < 250
    assert all(np.array_equal(x, thesis.perturb(action)) for x in noisy)


def test_clean_fraction_is_checked():
    with pytest.raises(ValueError, match='clean_fraction'):
        NoiseConfig(clean_fraction=1.5)


def test_a_random_baseline_sends_noise_on_every_step_whatever_the_executors_clean_steps():
    from qg_experiments.random_baselines import BaselineSpec, baseline_noise
    config = baseline_noise(NoiseConfig(clean_fraction=0.2, clean_episode_fraction=0.5),
                            BaselineSpec('uniform', 0.3))
    assert (config.kind, config.clean_fraction, config.clean_episode_fraction) == ('uniform', 0.0, 0.0)
    noise = ActionNoise(config, 2, seed=1)
    assert not any(np.all(noise.explore(np.zeros(2)) == 0.0) for _ in range(500))


def test_a_clean_episode_sends_the_actors_own_action_on_every_step():
    config = NoiseConfig(clean_fraction=0.0, clean_episode_fraction=0.25)
    clean = []
    for seed in range(400):
        noise = ActionNoise(config, 2, seed=seed)
        action = np.array([0.3, -0.4])
        steps = [noise.explore(action) for _ in range(5)]
        all_clean = all(np.array_equal(a, action) for a in steps)
        assert all_clean == noise.clean_episode          # a whole episode, or no step
        clean.append(all_clean)
    assert 0.19 < np.mean(clean) < 0.31                  # a quarter of the episodes
    # the noisy episodes keep the thesis's samples
    noisy_seed = clean.index(False)
    thesis = ActionNoise(NoiseConfig(clean_fraction=0.0), 2, seed=noisy_seed)
    ours = ActionNoise(config, 2, seed=noisy_seed)
    np.testing.assert_array_equal(ours.explore(np.zeros(2)), thesis.explore(np.zeros(2)))
    with pytest.raises(ValueError, match='clean_episode_fraction'):
        NoiseConfig(clean_episode_fraction=1.2)
