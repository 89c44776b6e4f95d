"""The algorithm registry (``learner/algorithms.py``): one entry per algorithm, and what each of
ours switches on in the learner, wherever it runs (the runner's Panda task, a Gymnasium task)."""
from __future__ import annotations

import pytest
from qg_learning_node.learner.algorithms import COMPARED, REGISTRY, algorithm, keys, label
from qg_learning_node.learner.learner_config import LearnerConfig


def test_each_algorithm_is_named_once_and_the_families_split_the_registry() -> None:
    assert set(keys("ours")) | set(keys("sb3")) == set(REGISTRY)
    assert not set(keys("ours")) & set(keys("sb3"))
    assert len({a.label for a in REGISTRY.values()}) == len(REGISTRY)
    assert set(COMPARED) == {"ddpg", "qgddpg"} and label("qgddpg") == "QG-DDPG"
    assert [REGISTRY[k].sb3_class for k in keys("sb3")] == ["DDPG", "TD3", "SAC"]
    with pytest.raises(ValueError, match="one of"):
        algorithm("sb3_td3", "ours")
    with pytest.raises(ValueError, match="not our learner"):
        algorithm("sb3_td3").learner_config(LearnerConfig(), None)


@pytest.mark.parametrize("key, bounds, graph, loops", [
    ("ddpg", "none", False, None), ("qgddpg", "qgraph+apriori", True, (0.0, 0.0)),
    ("qgddpg_graph", "qgraph", True, (0.0, 0.0)), ("ddpg_apriori", "apriori", False, None)])
def test_our_algorithms_set_bounds_graph_and_zero_action_loops(key, bounds, graph, loops) -> None:
    config = algorithm(key).learner_config(LearnerConfig(), (0.0, 0.0))
    assert (config.ddpg.bounds, config.use_qgraph, config.zero_action) == (bounds, graph, loops)


def test_without_a_known_reward_range_the_a_priori_part_is_dropped() -> None:
    unknown = {k: algorithm(k).learner_config(LearnerConfig(), None, reward_range_known=False)
               for k in keys("ours")}
    assert {k: c.ddpg.bounds for k, c in unknown.items()} == {
        "ddpg": "none", "qgddpg": "qgraph", "qgddpg_graph": "qgraph", "ddpg_apriori": "none"}
    assert unknown["qgddpg"].use_qgraph and unknown["qgddpg"].zero_action is None
