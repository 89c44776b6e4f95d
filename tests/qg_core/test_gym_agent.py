"""QG-DDPG on Gymnasium environments (``learner/gym_agent.py``): spaces and units, the graph's
bounds where a task has terminals and none where it has not, seeded determinism, SB3's tags,
and ``qgl train``."""
from __future__ import annotations

import csv
import math
import os
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
import torch
from gymnasium import spaces
from qg_learning_node.learner.gym_agent import QGDDPG, SB3_DDPG_SETTINGS

SMALL = {"actor_hidden": (16, 16), "critic_hidden": (16, 16), "batch_size": 8}


class Corridor(gymnasium.Env):
    """Five cells 0..4 in a row, start at 0; the action (in [0, 2], 1 = stand still) moves one
    cell left (< 0.7) or right (> 1.3); the last cell is the terminal goal. Sparse reward: -1 per
    step, 0 on reaching the goal. States repeat exactly, so the data graph has loops and paths."""

    observation_space = spaces.Box(0.0, 4.0, (1,), np.float32)
    action_space = spaces.Box(0.0, 2.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.cell, self.t = 0, 0
        return np.array([self.cell], np.float32), {}

    def step(self, action):
        a = float(np.asarray(action).ravel()[0])
        self.cell = int(np.clip(self.cell + (a > 1.3) - (a < 0.7), 0, 4))
        self.t += 1
        goal = self.cell == 4
        return (np.array([self.cell], np.float32), 0.0 if goal else -1.0, goal, self.t >= 30,
                {"is_success": goal})


def _weights(agent: QGDDPG) -> list[np.ndarray]:
    return [t for _, t in agent.core.agent.actor_tensors()]


def test_the_graph_bounds_a_sparse_task_with_exact_values() -> None:
    agent = QGDDPG(Corridor(), seed=1, noise="uniform", learning_starts=400, train_freq=10,
                   gradient_steps=2, gamma=0.9, zero_action=(1.0,), **SMALL)
    assert agent.core.zero_action.tolist() == [0.0]          # env units 1.0 -> actor units 0.0
    assert agent.reward_range is None and agent.core.agent.config.bounds == "qgraph"
    agent.learn(500)
    graph = agent.core.graph
    # From cell 3 a right step reaches the goal: bound 0. From cell 2: -1 + 0.9 * 0 = -1 at best.
    right, stay = np.array([1.0]), np.array([0.0])
    assert graph.lower_bound(np.array([0.5]), right) == 0.0      # cell 3 scaled to [-1, 1]
    assert graph.lower_bound(np.array([0.0]), right) == pytest.approx(-1.0)
    # standing still at cell 0 forever is a loop: -1 / (1 - 0.9) = -10
    assert graph.lower_bound(np.array([-1.0]), stay) >= -10.0 - 1e-9
    ddpg = QGDDPG(Corridor(), algorithm="ddpg", seed=1, **SMALL)
    assert ddpg.core.graph is None and ddpg.core.zero_action is None


def test_without_terminals_or_loops_qgddpg_trains_exactly_like_ddpg() -> None:
    """Pendulum: every episode is truncated, states never repeat; no graph bound exists, so
    without an a-priori reward range the two algorithms compute the same updates."""
    runs = [QGDDPG(gymnasium.make("Pendulum-v1"), algorithm=a, seed=3, train_freq=5,
                   gradient_steps=1, **SMALL).learn(250) for a in ("qgddpg", "ddpg")]
    for a, b in zip(*map(_weights, runs)):
        np.testing.assert_array_equal(a, b)
    census = runs[0].core.graph.census()
    assert census["directly_connected"] == census["connected"] == 0


@pytest.mark.slow
def test_a_seed_gives_the_same_learning_and_another_seed_another() -> None:
    def run(seed: int) -> list[np.ndarray]:
        return _weights(QGDDPG(gymnasium.make("Pendulum-v1"), seed=seed, train_freq=5,
                               **SMALL).learn(200))
    first, second, other = run(4), run(4), run(5)
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0], other[0])


def test_actions_are_mapped_onto_the_box_and_observations_scaled() -> None:
    env = gymnasium.make("Pendulum-v1")            # torque in [-2, 2], speed in [-8, 8]
    agent = QGDDPG(env, seed=0, **SMALL)
    np.testing.assert_allclose(agent._state(np.array([1.0, 0.0, 8.0])), [1.0, 0.0, 1.0])
    np.testing.assert_allclose(agent._to_env(np.array([-1.0])), [-2.0])
    np.testing.assert_allclose(agent._to_env(np.array([0.25])), [0.5])
    raw = QGDDPG(env, seed=0, normalize_observations=False, **SMALL)
    np.testing.assert_allclose(raw._state(np.array([1.0, 0.0, 8.0])), [1.0, 0.0, 8.0])
    for _ in range(5):
        action, _ = agent.predict(env.observation_space.sample(), deterministic=False)
        assert env.action_space.contains(action)
    with pytest.raises(ValueError, match="Box action"):
        QGDDPG(gymnasium.make("CartPole-v1"))
    with pytest.raises(ValueError, match="unknown settings"):
        QGDDPG(env, learning_rate=1e-3)


def test_sb3_ddpg_settings_build_sb3s_networks() -> None:
    agent = QGDDPG(gymnasium.make("Pendulum-v1"), algorithm="ddpg", **SB3_DDPG_SETTINGS)
    actor = agent.core.agent.actor
    assert [m.out_features for m in actor if isinstance(m, torch.nn.Linear)] == [400, 300, 1]
    assert isinstance(actor[1], torch.nn.ReLU) and isinstance(actor[-1], torch.nn.Tanh)
    bias = actor[0].bias.detach().numpy()            # nn.Linear's init: U(+-1/sqrt(fan_in))
    assert np.all(np.abs(bias) <= 1 / np.sqrt(3)) and np.any(bias != 0)
    assert agent.core.agent.config.target_networks and agent.core.config.batch_size == 256


def test_learning_writes_sb3s_tags(tmp_path) -> None:
    agent = QGDDPG(Corridor(), seed=0, train_freq=5, **SMALL)
    agent.learn(70, tensorboard_log=tmp_path / "tb")
    agent.close()
    with (tmp_path / "tb" / "progress.csv").open() as f:
        tags = {row["tag"] for row in csv.DictReader(f)}
    assert {"rollout/ep_len_mean", "rollout/ep_rew_mean", "rollout/success_rate", "time/fps",
            "train/critic_loss", "train/actor_loss", "train/mean_q"} <= tags
    assert list((tmp_path / "tb").glob("events.out.tfevents.*"))


def test_max_episodes_and_the_callback_stop_learning() -> None:
    agent = QGDDPG(Corridor(), seed=0, **SMALL).learn(10_000, max_episodes=2)
    assert agent.episodes == 2 and agent.num_timesteps <= 60
    seen = []
    agent = QGDDPG(Corridor(), seed=0, **SMALL).learn(10_000, callback=lambda e: seen.append(e)
                                                      or len(seen) < 3)
    assert agent.episodes == 3 and [e["steps"] for e in seen][0] >= 1



def test_an_episode_spanning_two_learn_calls_is_reported_whole() -> None:
    """A sweep evaluating every N steps calls ``learn`` in chunks: an episode cut by a chunk's
    end goes on in the next call and is reported once, with all its steps (it was reported
    with only the next call's steps, its return likewise)."""
    seen: list[dict] = []
    agent = QGDDPG(gymnasium.make("Pendulum-v1"), seed=0, **SMALL)
    for chunk in (150, 150, 100):                  # Pendulum truncates every episode at 200
        agent.learn(chunk, callback=lambda e: seen.append(e) or True)
    assert [e["steps"] for e in seen] == [200, 200]
    assert [e["timesteps"] for e in seen] == [200, 400]
    assert all(-16.3 * 200 <= e["return"] < -1.0 for e in seen)   # every step costs
@pytest.mark.slow
def test_qgl_train_runs_on_pendulum(tmp_path) -> None:
    env = {**os.environ, "QG_RUNS_DIR": str(tmp_path)}
    out = subprocess.run([os.path.join(os.path.dirname(sys.executable), "qgl"), "train",
                          "--env", "Pendulum-v1", "--steps", "60", "--test-episodes", "1",
                          "--set", "actor_hidden=[8,8]", "--set", "critic_hidden=[8,8]"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "60 steps" in out.stdout and "test return over 1 episodes" in out.stdout
    assert len(list(tmp_path.glob("train_Pendulum-v1_*/progress.csv"))) == 1


def _grid_actions_after(steps: int, normalize: bool, actor_preact_penalty: float = 0.0
                        ) -> tuple[int, np.ndarray]:
    """QG-DDPG at the standard tasks' MountainCar settings (seed 103, whose first episode reaches
    the goal): goal-reaching episodes, and the deterministic actions on an 81-state grid."""
    env = gymnasium.make("MountainCarContinuous-v0")
    agent = QGDDPG(env, algorithm="qgddpg", seed=103, **{
        **SB3_DDPG_SETTINGS, "actor_hidden": (64, 64), "critic_hidden": (64, 64), "noise": "ou",
        "noise_sigma": 0.5, "noise_theta": 0.15, "reward_range": (-0.1, 100.0),
        "normalize_observations": normalize, "actor_preact_penalty": actor_preact_penalty})
    goals = []
    agent.learn(steps, callback=lambda e: goals.append(e["success"]) or True)
    grid = [np.array([x, v], np.float32) for x in np.linspace(-1.2, 0.5, 9)
            for v in np.linspace(-0.07, 0.07, 9)]
    return sum(goals), np.array([agent.predict(s)[0][0] for s in grid])


def _saturation_after(steps: int, normalize: bool) -> tuple[int, float]:
    """Goal-reaching episodes, and the share of the grid where |action| > 0.99."""
    goals, actions = _grid_actions_after(steps, normalize)
    return goals, float(np.mean(np.abs(actions) > 0.99))


@pytest.mark.slow
def test_on_raw_mountain_car_observations_the_first_goal_saturates_qgddpgs_actor_for_good(
        ) -> None:
    """The cause of QG-DDPG's MountainCar seeds at -99.9 (docs/learning.md, section 13): the
    graph bounds the first goal-reaching chain, the critic's values jump and the actor saturates
    at one end on every state; with the raw observation (velocity within +-0.07) the critic
    cannot tell the directions of motion apart and the saturated actor stays there, a constant
    push that never reaches the goal. Scaled to [-1, 1], the same run recovers."""
    goals, saturated = _saturation_after(1_000, normalize=False)
    assert goals == 1 and saturated == 1.0
    goals, saturated = _saturation_after(2_250, normalize=True)
    assert goals >= 1 and saturated < 0.5


@pytest.mark.slow
def test_the_actors_pre_tanh_penalty_keeps_its_tanh_off_saturation_after_the_first_goal(
        ) -> None:
    """The fix of the test above (docs/learning.md, section 13): the same run, the same first
    goal, with ``actor_preact_penalty`` 0.1 (the standard tasks' MountainCar setting). Without
    it tanh's slope 1 - a^2, the factor by which the actor receives the critic's gradient, is
    below 1e-4 on all 81 states (measured: at most 3.4e-5); with it above 1e-3 on every state
    (measured: at least 0.0145), so the critic can still turn the actor."""
    goals, actions = _grid_actions_after(1_000, normalize=False)
    assert goals == 1 and np.all(1.0 - actions ** 2 < 1e-4)
    goals, actions = _grid_actions_after(1_000, normalize=False, actor_preact_penalty=0.1)
    assert goals == 1 and np.all(1.0 - actions ** 2 > 1e-3)


def test_a_negative_or_infinite_actor_penalty_is_refused() -> None:
    from qg_learning_node.learner.ddpg import DDPGConfig
    for bad in (-0.1, math.inf, math.nan):
        with pytest.raises(ValueError, match="actor_preact_penalty"):
            DDPGConfig(actor_preact_penalty=bad)
    with pytest.raises(ValueError, match="actor_preact_penalty"):
        QGDDPG(gymnasium.make("Pendulum-v1"), actor_preact_penalty=-1.0)


@pytest.mark.slow
def test_our_ddpg_train_step_is_sb3_ddpgs() -> None:
    """From the same weights on the same minibatch, our DDPG at SB3 DDPG's settings updates as
    SB3's DDPG does (float32 rounding through Adam apart): what differs between the two on
    Pendulum is the random streams, not the algorithm (docs/learning.md, section 13)."""
    from qg_learning_node.learner.replay import Batch
    from stable_baselines3 import DDPG
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.type_aliases import ReplayBufferSamples
    env = gymnasium.make("Pendulum-v1")
    sb3 = DDPG("MlpPolicy", env, seed=0, device="cpu", policy_kwargs={"net_arch": [64, 64]})
    sb3.set_logger(Logger(None, []))
    ours = QGDDPG(env, algorithm="ddpg", seed=0, **{**SB3_DDPG_SETTINGS, "actor_hidden": (64, 64),
                                                    "critic_hidden": (64, 64)}).core.agent
    nets = [(ours.actor, sb3.actor.mu), (ours.critic.net, sb3.critic.qf0),
            (ours.actor_target, sb3.actor_target.mu), (ours.critic_target.net, sb3.critic_target.qf0)]
    for mine, theirs in nets:
        mine.load_state_dict(theirs.state_dict())
    rng = np.random.default_rng(1)
    n = 256
    s, a = rng.uniform(-1, 1, (n, 3)), rng.uniform(-1, 1, (n, 1))
    r, s2 = -rng.uniform(0, 16, n), rng.uniform(-1, 1, (n, 3))

    def f(x):
        return torch.as_tensor(x, dtype=torch.float32)
    batch = ReplayBufferSamples(f(s), f(a), f(s2), torch.zeros(n, 1), f(r)[:, None],
                                torch.ones(n, 1))
    sb3.replay_buffer.sample = lambda *args, **kwargs: batch
    start = ours.critic.net[0].weight.detach().clone()
    for _ in range(3):
        sb3.train(gradient_steps=1, batch_size=n)
        ours.train_step(Batch(s, a, r, s2, np.zeros(n, bool), np.full(n, -np.inf), np.arange(n)))
    for mine, theirs in nets:
        for p, q in zip(mine.parameters(), theirs.parameters()):
            assert float((p - q).abs().max()) < 1e-4
    assert float((ours.critic.net[0].weight - start).abs().max()) > 1e-3     # it did learn
