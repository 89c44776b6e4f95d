"""Every algorithm the project runs, named once: ours (DDPG, QG-DDPG and its variants) and the
Stable-Baselines3 peers.

Why one registry: an experiment chooses algorithms by key (``config/experiments.yaml``, a
benchmark's ``--algorithms``), a report prints their labels, and our learner needs to know what a
key switches on. Kept in one table, a new variant is one line, and no experiment keeps a list or
an if-chain of its own. Our algorithms differ only in what :meth:`Algorithm.learner_config` sets
on the learner: which bounds clip the TD targets (``DDPGConfig.bounds``), whether the Q-Graph
is kept, and whether the zero action's never-executed self-loops go into graph and replay. The
peers are named here by their SB3 class; the experiments build them (SB3 is not a dependency of
the learner).

Vanilla DDPG as in the thesis: no bounds and no zero-action loops (its replay holds executed
steps only). QG-DDPG: the graph's lower bounds, tightened by the a-priori bounds of a known
reward range, with the zero action's loops where the task has a zero action.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from qg_learning_node.learner.learner_config import (
    APRIORI_BOUNDS,
    BOUND_MODES,
    GRAPH_BOUNDS,
    LearnerConfig,
)

__all__ = ["Algorithm", "REGISTRY", "FAMILIES", "COMPARED", "algorithm", "keys", "label"]

FAMILIES = ("ours", "sb3")


@dataclass(frozen=True)
class Algorithm:
    """One algorithm of the registry.

    :param key: its name in configs, run names and on the command line.
    :param label: its name in tables and figures.
    :param family: ``ours`` (our learner core) | ``sb3`` (a Stable-Baselines3 class).
    :param bounds: ours: ``DDPGConfig.bounds`` when the reward range is known (a-priori bounds
        are dropped where it is not).
    :param zero_action_loops: ours: add the zero action's self-loops (where the task has one).
    :param sb3_class: sb3: the class name in ``stable_baselines3``.
    :param action_noise: sb3: takes Gaussian/OU action noise for exploration (TD3 and DDPG do;
        SAC explores through its stochastic policy).
    """
    key: str
    label: str
    family: str
    bounds: str = "none"
    zero_action_loops: bool = False
    sb3_class: str | None = None
    action_noise: bool = False

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ValueError(f"family must be one of {FAMILIES}, got {self.family!r}")
        if self.bounds not in BOUND_MODES:
            raise ValueError(f"bounds must be one of {BOUND_MODES}, got {self.bounds!r}")
        if (self.family == "sb3") != (self.sb3_class is not None):
            raise ValueError(f"{self.key}: an SB3 algorithm names its class, ours do not")

    @property
    def ours(self) -> bool:
        return self.family == "ours"

    @property
    def uses_graph(self) -> bool:
        """Keeps a Q-Graph of the replay data (its bounds need one)."""
        return self.bounds in GRAPH_BOUNDS

    @property
    def uses_reward_range(self) -> bool:
        """Takes the task's known reward range as a-priori bounds."""
        return self.bounds in APRIORI_BOUNDS

    def bounds_for(self, reward_range_known: bool) -> str:
        """The bound mode on a task whose reward range is (not) known: without one, the
        a-priori part is dropped (``qgraph+apriori`` -> ``qgraph``, ``apriori`` -> ``none``)."""
        if reward_range_known or not self.uses_reward_range:
            return self.bounds
        return "qgraph" if self.uses_graph else "none"

    def learner_config(self, base: LearnerConfig, zero_action: tuple[float, ...] | None,
                       reward_range_known: bool = True) -> LearnerConfig:
        """``base`` with this algorithm's bounds, graph and zero-action loops.

        :param zero_action: the task's action that leaves the state unchanged (actor units),
            or ``None`` if it has none; used only by an algorithm with ``zero_action_loops``.
        """
        if not self.ours:
            raise ValueError(f"{self.key} is {self.family}'s, not our learner's")
        bounds = self.bounds_for(reward_range_known)
        return dataclasses.replace(
            base, use_qgraph=bounds in GRAPH_BOUNDS,
            zero_action=zero_action if self.zero_action_loops else None,
            ddpg=dataclasses.replace(base.ddpg, bounds=bounds))


#: The registry, in the order tables list the algorithms.
REGISTRY: dict[str, Algorithm] = {a.key: a for a in (
    Algorithm("ddpg", "DDPG", "ours"),
    Algorithm("qgddpg", "QG-DDPG", "ours", bounds="qgraph+apriori", zero_action_loops=True),
    # QG-DDPG's parts apart: the graph without the a-priori bounds, the a-priori bounds alone.
    Algorithm("qgddpg_graph", "QG-DDPG, graph bounds only", "ours", bounds="qgraph",
              zero_action_loops=True),
    Algorithm("ddpg_apriori", "DDPG + a-priori bounds", "ours", bounds="apriori"),
    Algorithm("sb3_ddpg", "SB3 DDPG", "sb3", sb3_class="DDPG", action_noise=True),
    Algorithm("sb3_td3", "SB3 TD3", "sb3", sb3_class="TD3", action_noise=True),
    Algorithm("sb3_sac", "SB3 SAC", "sb3", sb3_class="SAC"),
)}
#: The pair the thesis compares, and every experiment by default: vanilla DDPG and QG-DDPG.
COMPARED = ("ddpg", "qgddpg")


def algorithm(key: str, family: str | None = None) -> Algorithm:
    """The registry's entry ``key``; ``family`` restricts it to ours or SB3's.

    :raises ValueError: for a key the registry (or that family) does not have.
    """
    known = keys(family)
    if key not in known:
        raise ValueError(f"algorithm must be one of {known}, got {key!r}")
    return REGISTRY[key]


def keys(family: str | None = None) -> tuple[str, ...]:
    """Every key, or those of one family, in registry order."""
    return tuple(k for k, a in REGISTRY.items() if family is None or a.family == family)


def label(key: str) -> str:
    """The table name of ``key`` (the key itself if the registry does not have it)."""
    return REGISTRY[key].label if key in REGISTRY else key
