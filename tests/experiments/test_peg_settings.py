"""The peg experiments keep their own discount: learner.yaml's is tuned to the Panda task."""
from __future__ import annotations

from qg_common.params import config_file, load_ros_params
from qg_experiments.peg import peg_specs
from qg_experiments.profile import PegBudget, load_profile


def test_peg_runs_take_the_budgets_discount_not_the_panda_learners():
    panda_gamma = load_ros_params(config_file("learner.yaml"), "learner")["learner"]["ddpg"][
        "gamma"]
    thesis = load_profile("thesis")
    assert thesis.peg.gamma == thesis.nextage.gamma == 0.99 != panda_gamma
    specs = peg_specs(PegBudget(lrs=(1e-3, 1e-4), seeds=(0, 1), gamma=0.95))
    assert len(specs) == 8 and {s.gamma for s in specs} == {0.95}


def test_peg_networks_are_the_thesis_ch_8_3_2_ones():
    """3 x 200 both; the actor's weights He-uniform, the critic's from N(0, 0.001), biases 0;
    no target networks; one learning rate for actor and critic."""
    import numpy as np
    import torch
    from qg_experiments.peg import PegRunSpec, peg_learner_config
    from qg_learning_node.learner.ddpg import DDPG

    config = peg_learner_config(PegRunSpec(algorithm="qgddpg", lr=1e-4, seed=3), action_dim=3)
    d = config.ddpg
    assert d.actor_hidden == d.critic_hidden == (200, 200, 200)
    assert (d.actor_init, d.critic_init, d.target_networks) == ("he_uniform", "normal_1e-3",
                                                                False)
    assert d.actor_lr == d.critic_lr == 1e-4 and config.seed == d.seed == 3
    agent = DDPG(d, state_dim=3, action_dim=3)
    critic = [m for m in agent.critic.net if isinstance(m, torch.nn.Linear)]
    weights = torch.cat([m.weight.detach().flatten() for m in critic]).numpy()
    assert abs(weights.std() - 1e-3) < 2e-5 and abs(weights.mean()) < 2e-5
    assert all(not m.bias.any() for m in critic)
    # He-uniform: U(-b, b), b = sqrt(6 / fan_in); the 200-wide layers' weights reach b
    hidden = [m for m in agent.actor if isinstance(m, torch.nn.Linear)][1]
    bound = np.sqrt(6 / 200)
    assert bound * 0.99 < hidden.weight.abs().max().item() <= bound
    q = agent.q_values(np.zeros((4, 3)), np.zeros((4, 3)))
    assert np.all(np.abs(q) < 1e-6)           # Q starts at ~0, the top of [-100, 0]


def test_the_peg_explores_on_every_step_as_the_thesis():
    from qg_experiments.peg import peg_noise_config
    panda = load_ros_params(config_file("executor.yaml"))["noise"]
    assert panda["clean_fraction"] > 0.0                  # the Panda's stall remedy ...
    noise = peg_noise_config()
    assert noise.clean_fraction == noise.clean_episode_fraction == 0.0   # ... not the peg's
    assert (noise.kind, noise.sigma) == (panda["kind"], panda["sigma"])


def test_a_peg_run_saved_before_the_thesis_networks_is_run_again(tmp_path):
    """A saved peg run is reused only with the networks and exploration it ran with."""
    import json

    from qg_experiments.core.stack_settings import config_digest
    from qg_experiments.peg import PegRunSpec
    from qg_experiments.tasks import result_path, saved_result

    spec = PegRunSpec(algorithm="ddpg", lr=1e-4, seed=100)
    path = result_path(tmp_path, spec)
    path.parent.mkdir(parents=True)
    saved = {"spec": {**spec.__dict__}, "config_digest": config_digest(), "episodes": []}
    path.write_text(json.dumps(saved))                       # the Panda's inits: no settings
    assert saved_result(tmp_path, spec) is None
    path.write_text(json.dumps({**saved, "task_settings": spec.task_settings}))
    assert saved_result(tmp_path, spec) is not None
    assert spec.task_settings["networks"]["critic_init"] == "normal_1e-3"


def test_the_random_policies_meet_the_learners_starts_and_learn_nothing():
    """Episode k of every run of a seed starts at the same place, learning or random; the
    ``noise`` policy is the learners' exploration on the zero action, ``uniform`` the box."""
    import dataclasses

    import numpy as np
    import pytest
    from qg_experiments import peg

    starts: dict[str, list] = {}
    noise = peg.peg_noise_config()
    for name, config in (("noise", noise), ("uniform", dataclasses.replace(noise, kind="uniform"))):
        env = peg._peg_env("free", None, 3)
        seen: list = []

        def act(state: np.ndarray, seen: list = seen) -> np.ndarray:
            seen.append(np.array(state))
            return np.zeros(env.action_dim)
        records = peg._episodes(env, 7, range(3), config, act)
        env.close()
        starts[name] = [seen[sum(r["steps"] for r in records[:k])] for k in range(3)]
        assert all(r["steps"] == 3 and not r["success"] and "mean_q" not in r for r in records)
    assert np.array_equal(starts["noise"], starts["uniform"])
    assert not np.array_equal(starts["noise"][0], starts["noise"][1])   # starts differ
    spec = peg.PegRandomSpec(kind="uniform", seed=7, episodes=2, episode_steps=3)
    result = spec.run()
    assert spec.experiment == "peg_random" and result["name"] == "random_uniform_s7"
    assert [e["steps"] for e in result["episodes"]] == [3, 3] and result["rl_steps"] == 6
    assert spec.run()["episodes"] == result["episodes"]          # seeded: the same again
    assert peg.PegRandomSpec(kind="noise", seed=7, episodes=2, episode_steps=3).run()[
        "episodes"] != result["episodes"]
    with pytest.raises(ValueError, match="kind must be one of"):
        peg.PegRandomSpec(kind="gaussian", seed=0)
    budget = PegBudget(lrs=(1e-3,), seeds=(0, 1), random=("noise", "uniform"))
    assert [s.name for s in peg.peg_random_specs(budget)] == [
        "random_noise_s0", "random_noise_s1", "random_uniform_s0", "random_uniform_s1"]
    assert load_profile("thesis").peg.random == ("noise", "uniform")
