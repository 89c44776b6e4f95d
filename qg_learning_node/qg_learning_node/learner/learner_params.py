"""The learner's parameters as sections, and learner settings from ROS parameters, where "none"
has to be spelled 0 or [].

Pure (no rclpy): the learner node declares exactly these sections, and what reads
``config/learner.yaml`` without a node (the experiments, tests) goes through
``learner_config_from_params``, which checks the same ranges the node's declaration does.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from qg_common.params import POSITIVE, ParameterSection, check_section

from qg_learning_node.learner.learner_config import RUNTIME_FIELDS, LearnerConfig

__all__ = ["LearnerNodeConfig", "LEARNER_SECTION", "LEARNER_SECTIONS",
           "learner_config_from_params"]


@dataclass(frozen=True)
class LearnerNodeConfig:
    """The learner node's own parameters (``config/learner.yaml``, top level).

    The state and action sizes are not among them: the executor owns the state definition and
    publishes the sizes on its latched ``executor/task_spec``, from which the learner builds its
    networks (``learner_node``).

    :param checkpoint_dir: folder of ``learner.pt``; "" = ``<runs>/checkpoints``.
    :param resume: restore networks, optimizers, graph and replay at start.
    :param robot_namespaces: the robots whose ``<ns>/transitions`` and ``<ns>/episode_status``
        this learner learns from; "" is the learner's own namespace (one robot, the default).
        ``qgl up --robots 2`` gives ``[robot0, robot1]`` (see ``qg_bringup/fleet.py``).
    """
    checkpoint_dir: str = ""
    resume: bool = False
    robot_namespaces: tuple[str, ...] = ("",)


#: The training settings. Those of ``RUNTIME_FIELDS`` (iterations, cycle length, batch size,
#: census period, learning rates) can change while the learner runs, from its next cycle; the
#: rest shape the networks, graph and replay memory it has built.
LEARNER_SECTION = ParameterSection(
    "learner", LearnerConfig, ranges={
        "replay_capacity": (0, 1_000_000_000), "iterations_per_cycle": (1, 1_000_000),
        "cycle_steps": (1, 1_000_000), "batch_size": (1, 1_000_000),
        "census_every": (1, 1_000_000), "graph_resolution": (0.0, 2.0),
        "updates_per_step": POSITIVE, "publish_every": (1, 1_000_000),
        "ddpg.gamma": (0.0, 1.0), "ddpg.critic_lr": (0.0, 1.0), "ddpg.actor_lr": (0.0, 1.0),
        "ddpg.tau": (0.0, 1.0), "ddpg.he_horizon": (1, 100_000), "ddpg.he_lambda": POSITIVE,
        "ddpg.actor_preact_penalty": POSITIVE},
    runtime=RUNTIME_FIELDS, applies="from the next training cycle",
    fixed=("read-only: the networks, Q-Graph and replay memory are built with it; restart "
           "the learner (without resume) to change it"))

#: The learner node's parameters.
LEARNER_SECTIONS = (ParameterSection("", LearnerNodeConfig), LEARNER_SECTION)


def learner_config_from_params(params: dict[str, Any], source: str = "") -> LearnerConfig:
    """The ``learner`` section of ``config/learner.yaml`` as a :class:`LearnerConfig`, checked
    as the node checks it (unknown keys, ranges).

    ``replay_capacity: 0`` means unbounded, ``zero_action: []`` means none and
    ``ddpg.actor_lr: 0.0`` means one tenth of the critic's, since ROS parameters cannot be null.
    :param source: where ``params`` come from, for the error message.
    """
    values = check_section(LEARNER_SECTION, params, source)
    if values.get("replay_capacity", None) in (0, None):
        values["replay_capacity"] = None
    if "zero_action" in values:
        values["zero_action"] = tuple(values["zero_action"]) or None
    ddpg = dict(values.get("ddpg", {}))
    if not ddpg.get("actor_lr"):
        ddpg["actor_lr"] = None
    values["ddpg"] = ddpg
    return LearnerConfig.from_dict(values)
