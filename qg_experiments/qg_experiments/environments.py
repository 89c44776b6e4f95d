"""Learning environments found by name, so the experiments never import a simulator.

A package registers a factory ``make(params: dict, **overrides) -> env`` under the entry-point
group ``qg_experiments.environments`` (``sim_robot_node`` registers ``peg``, the free
clearance-fit peg of experiment 5). An environment has ``state_dim``, ``action_dim``,
``reset(seed) -> state``, ``step(action) -> (state, reward, terminal)``, ``truncated`` and
``close()``.
"""
from __future__ import annotations

from typing import Any

from qg_common.plugins import load_registered

__all__ = ["ENVIRONMENT_GROUP", "make_environment"]

ENVIRONMENT_GROUP = "qg_experiments.environments"


def make_environment(name: str, params: dict[str, Any], **overrides: Any) -> Any:
    """The environment registered as ``name``, built from its parameter file's contents.

    :raises ValueError: if no installed package registers ``name``.
    """
    return load_registered(ENVIRONMENT_GROUP, name, what="environment")(params, **overrides)
