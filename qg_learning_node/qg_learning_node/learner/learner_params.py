"""Learner settings from ROS parameters, where "none" has to be spelled 0 or []."""
from __future__ import annotations

from typing import Any

from qg_learning_node.learner.learner_core import LearnerConfig

__all__ = ["learner_config_from_params"]


def learner_config_from_params(params: dict[str, Any]) -> LearnerConfig:
    """The ``learner`` section of ``config/learner.yaml`` as a :class:`LearnerConfig`.

    ``replay_capacity: 0`` means unbounded, ``zero_action: []`` means none and
    ``ddpg.actor_lr: 0.0`` means one tenth of the critic's, since ROS parameters cannot be null.
    """
    values = dict(params)
    if values.get("replay_capacity", None) in (0, None):
        values["replay_capacity"] = None
    zero = values.get("zero_action")
    values["zero_action"] = tuple(zero) if zero else None
    ddpg = dict(values.get("ddpg", {}))
    if not ddpg.get("actor_lr"):
        ddpg["actor_lr"] = None
    values["ddpg"] = ddpg
    return LearnerConfig.from_dict(values)
