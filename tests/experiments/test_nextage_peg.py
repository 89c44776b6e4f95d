"""The fast runner's Nextage: the stack's cores on the peg, started where the free peg starts."""
from __future__ import annotations

import numpy as np
import pytest
from qg_common.params import config_file, load_ros_params
from qg_experiments.nextage_peg import NextagePeg


@pytest.fixture(scope="module")
def arm() -> NextagePeg:
    return NextagePeg(episode_steps=30)


def test_the_arm_starts_where_the_free_peg_starts(arm: NextagePeg) -> None:
    from sim_robot_node.core.peg_env import make_peg_env
    free = make_peg_env(load_ros_params(config_file("peg_env.yaml")))
    try:
        for seed in (3, 1000):
            np.testing.assert_allclose(arm.reset(seed), free.reset(seed=seed), atol=0.02)
    finally:
        free.close()


def test_moving_toward_the_hole_inserts_the_peg_and_rewards_rise(arm: NextagePeg) -> None:
    """A scripted policy: above the hole first, then down; terminal at the bottom."""
    arm.reset(5)
    rewards, terminal = [], False
    hole_top = 0.045            # [m] block height 0.04 plus 5 mm, workspace frame
    while not (terminal or arm.truncated):
        tip = arm.tip()
        move = np.array([-tip[0], -tip[1], 0.0])
        if np.linalg.norm(move) < 0.002:
            move[2] = -0.01
        elif tip[2] < hole_top:
            move = np.array([0.0, 0.0, hole_top + 0.005 - tip[2]])
        _, reward, terminal = arm.step(np.clip(move / 0.01, -1.0, 1.0))
        rewards.append(reward)
    assert terminal and arm.steps < 30
    assert rewards[-1] > -0.3 and rewards[-1] > rewards[0] + 0.3
    assert arm.sim_time > 0.02 * arm.steps


def test_a_step_before_reset_or_with_nan_is_refused() -> None:
    fresh = NextagePeg()
    with pytest.raises(ValueError, match="reset"):
        fresh.step(np.zeros(3))
    fresh.reset(0)
    with pytest.raises(ValueError, match="finite"):
        fresh.step(np.array([np.nan, 0.0, 0.0]))
