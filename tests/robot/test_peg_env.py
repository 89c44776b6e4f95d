"""The clearance-fit peg environment (SPEC 4): dynamics, rewards, determinism, both peg drives."""
from __future__ import annotations

import numpy as np
import pytest
from qg_common.params import config_file, load_ros_params
from robot_bridge_node.core.position_control import (
    PositionControlConfig,
    TaskSpacePositionController,
)
from sim_robot_node.core.nextage_scene import NextageSceneConfig, nextage_urdf_path
from sim_robot_node.core.peg_env import PegEnv, PegEnvConfig, toward_goal


@pytest.fixture(scope="module")
def config() -> PegEnvConfig:
    return PegEnvConfig.from_dict(load_ros_params(config_file("peg_env.yaml")))


@pytest.fixture
def env(config: PegEnvConfig):
    e = PegEnv(config)
    yield e
    e.close()




def run(env: PegEnv, policy, seed: int) -> tuple[bool, int, list[np.ndarray], list[float]]:
    states, rewards = [env.reset(seed)], []
    while not env.truncated:
        state, reward, terminal = env.step(policy(env))
        states.append(state)
        rewards.append(reward)
        if terminal:
            return True, env.steps, states, rewards
    return False, env.steps, states, rewards


def test_config_file_holds_the_spec_task(config: PegEnvConfig):
    g = config.geometry
    assert (2 * g.peg_radius, 2 * g.hole_radius, g.workspace_side) == (0.01, 0.02, 0.2)
    assert (config.action_scale, config.reward_length, config.episode_steps) == (0.01, 0.03, 200)
    assert not config.use_arm


def test_moving_toward_the_goal_inserts_the_peg(env: PegEnv):
    for seed in range(3):
        success, steps, states, rewards = run(env, toward_goal, seed)
        assert success, seed
        assert steps <= 40
        assert rewards[-1] > np.exp(-env.geometry.goal_tolerance / 0.03) - 1
        assert np.linalg.norm(states[-1] - env.goal_state) < 0.1


def test_random_actions_rarely_insert(env: PegEnv):
    rng = np.random.default_rng(0)
    results = [run(env, lambda _: rng.uniform(-1, 1, 3), seed)[0] for seed in range(4)]
    assert sum(results) <= 1


def test_states_rewards_and_moves_follow_the_spec(env: PegEnv):
    state = env.reset(seed=7)
    assert state.shape == (env.state_dim,) and np.all(np.abs(state) <= 1.0)
    np.testing.assert_allclose(env.scale_state(env.tip()), state)
    np.testing.assert_allclose(env.goal_state, [0.0, 0.0, -0.9])      # hole bottom at 1 cm
    assert env.reward(env.geometry.goal) == 0.0
    assert env.reward(env.geometry.goal + [0.03, 0.0, 0.0]) == pytest.approx(np.exp(-1) - 1)
    start = env.reset(start=np.array([0.05, 0.05, 0.1]))
    moved, reward, terminal = env.step(np.array([5.0, 0.0, -5.0]))    # clipped to one unit
    np.testing.assert_allclose((moved - start) * 0.1, [0.01, 0.0, -0.01], atol=5e-4)
    assert reward == pytest.approx(env.reward(env.tip())) and not terminal
    held, _, _ = env.step(np.zeros(3))                                # the zero action
    np.testing.assert_allclose(held, moved, atol=1e-4)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="overlaps"):
        env.reset(start=np.array([0.0, 0.02, 0.02]))


def test_same_seed_and_actions_give_the_same_episode(config: PegEnvConfig):
    actions = np.random.default_rng(3).uniform(-1, 1, (60, 3))
    episodes = []
    for env in (PegEnv(config), PegEnv(config)):
        for _ in range(2):                              # a reused env repeats itself too
            states = [env.reset(seed=11)] + [env.step(a)[0] for a in actions]
            episodes.append(np.array(states))
        env.close()
    for other in episodes[1:]:
        np.testing.assert_array_equal(other, episodes[0])
    other_seed = PegEnv(config)
    assert not np.array_equal(other_seed.reset(seed=12), episodes[0][0])
    other_seed.close()


def test_bad_configs_fail_loudly():
    with pytest.raises(ValueError, match="action_scale"):
        PegEnvConfig(action_scale=0.0)
    with pytest.raises(ValueError, match="unknown"):
        PegEnvConfig.from_dict({"episode_step": 100})
    with pytest.raises(ValueError, match="controller"):
        PegEnv(PegEnvConfig(use_arm=True))


def test_the_arm_option_inserts_too(config: PegEnvConfig):
    params = load_ros_params(config_file("nextage.yaml"))
    controller = TaskSpacePositionController(
        nextage_urdf_path(), "RARM_TOOL",
        PositionControlConfig.from_dict(params["position_control"]))
    arm_config = PegEnvConfig.from_dict({
        **load_ros_params(config_file("peg_env.yaml")), "use_arm": True,
        "arm": params["scene"]})
    assert arm_config.arm == NextageSceneConfig.from_dict(params["scene"])
    env = PegEnv(arm_config, controller)
    try:
        state = env.reset(start=np.array([0.01, -0.01, 0.06]))
        for _ in range(15):
            state, reward, terminal = env.step(toward_goal(env))
            if terminal:
                break
        assert terminal
        assert env.scene.ground_truth().success
    finally:
        env.close()
