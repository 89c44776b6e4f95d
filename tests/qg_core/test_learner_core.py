"""Learner core: cycles, zero-action loops in graph and replay, exact checkpoint restore."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from qg_learning_node.learner.ddpg import DDPGConfig
from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore

torch.set_num_threads(1)


def config(**kw) -> LearnerConfig:
    base = dict(ddpg={'bounds': 'qgraph+apriori', 'actor_hidden': [16, 16],
                      'critic_hidden': [16, 16]}, zero_action=[0.0, 0.0], iterations_per_cycle=3)
    base.update(kw)
    return LearnerConfig.from_dict(base)


def feed(core: LearnerCore, steps: int, seed: int = 0) -> list[bool]:
    rng = np.random.default_rng(seed)
    s, due = rng.uniform(-1, 1, 4), []
    for t in range(steps):
        s2 = rng.uniform(-1, 1, 4)
        due.append(core.add_transition(s, rng.uniform(-1, 1, 2), -1.0, s2, t % 25 == 24))
        s = s2
    return due


def test_cycles_and_zero_action_loops():
    core = LearnerCore(config(), 4, 2)
    due = feed(core, 50)
    assert [i for i, d in enumerate(due) if d] == [19, 39]
    assert len(core.replay) == 50 + 48  # a loop after every non-terminal step
    assert core.graph.num_real == 50 and len(core.graph) == 98
    result = core.train_cycle()
    assert result['actor_version'] == 1
    assert result['directly_connected'] == 2 and result['total'] == 98
    assert result['loose_end'] == 0
    assert 0.0 <= result['frac_raised_lower'] <= 1.0
    # the critic, frozen while the actor's loss runs through it, trains again afterwards
    assert all(p.requires_grad for p in core.agent.critic.parameters())


def test_vanilla_without_graph_and_validation():
    core = LearnerCore(config(ddpg={'bounds': 'none'}, use_qgraph=False, zero_action=None), 4, 2)
    feed(core, 20)
    assert len(core.replay) == 20 and core.graph is None
    assert 'connected' not in core.train_cycle()
    with pytest.raises(ValueError):
        config(use_qgraph=False)
    with pytest.raises(ValueError):
        LearnerCore(config(zero_action=[0.0]), 4, 2)


#: TD3's parts (ch. 9's peer): twin critics, target networks, and target smoothing noise drawn
#: from a generator of the agent's own, which a checkpoint has to carry as well.
TD3 = {'bounds': 'qgraph+apriori', 'actor_hidden': [16, 16], 'critic_hidden': [16, 16],
       'twin_critics': True, 'target_networks': True, 'target_noise': 0.2}


@pytest.mark.parametrize('ddpg', [None, TD3], ids=['qgddpg', 'td3'])
def test_save_load_gives_identical_next_cycle(tmp_path, ddpg):
    core = LearnerCore(config(replay_capacity=30, **({'ddpg': ddpg} if ddpg else {})), 4, 2)
    feed(core, 40)
    core.train_cycle()
    core.save(tmp_path / 'learner.pt')
    restored = LearnerCore.load(tmp_path / 'learner.pt')
    for c in (core, restored):
        feed(c, 20, seed=7)
    assert restored.train_cycle() == core.train_cycle()
    x = np.random.default_rng(2).uniform(-1, 1, (5, 4))
    np.testing.assert_array_equal(restored.agent.act(x), core.agent.act(x))
    assert isinstance(restored.config.ddpg, DDPGConfig)


def test_async_schedule_trains_updates_per_step_in_chunks():
    """``async``: 2.5 train steps per transition on average, an actor every 5 train steps."""
    core = LearnerCore(config(schedule='async', updates_per_step=2.5, publish_every=5), 4, 2)
    versions = []
    for due in feed(core, 10):
        while core.training_due():
            versions.append(core.train_cycle()['actor_version'])
    assert core.updates == 25 and versions == [1, 2, 3, 4, 5]
    assert not core.training_due()
    # the thesis schedule owes iterations_per_cycle per cycle, and nothing once they are done
    cycle = LearnerCore(config(), 4, 2)
    feed(cycle, 20)
    assert cycle.training_due()
    cycle.train_cycle()
    assert cycle.updates == 3 and not cycle.training_due()
    with pytest.raises(ValueError, match='schedule'):
        config(schedule='sometimes')
