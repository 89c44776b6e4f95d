"""Experiment budgets by profile (``config/experiments.yaml``): thesis, small and tiny (CI).

One profile fixes, for every experiment, how many runs, episodes and steps are spent; the task,
bridge, estimator and learner numbers always come from the stack's own config files.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from qg_common.params import config_file

from qg_learning_node.executor.residual_task import state_dim
from qg_experiments.runner import ALGORITHMS, ESTIMATORS

__all__ = ["RandomBudget", "GridBudget", "VariantBudget", "PegBudget", "Profile", "load_profile"]


def _fields(cls: type, values: dict[str, Any]) -> dict[str, Any]:
    unknown = set(values) - set(cls.__dataclass_fields__)
    if unknown:
        raise ValueError(f"{cls.__name__}: unknown keys {sorted(unknown)}")
    return {k: tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list)
            else v for k, v in values.items()}


@dataclass(frozen=True)
class RandomBudget:
    """:param noises: ``({kind, sigma}, ...)``; :param episodes: per noise (poses rotate)."""
    noises: tuple[dict[str, Any], ...]
    episodes: int = 8
    max_steps: int = 1000

    def __post_init__(self) -> None:
        if not self.noises or self.episodes < 1 or self.max_steps < 1:
            raise ValueError("random: needs noises, episodes >= 1 and max_steps >= 1")


@dataclass(frozen=True)
class GridBudget:
    """:param cells: ``((critic_lr, iterations per cycle), ...)``.

    :param observation: the state of every run (``residual_task.OBSERVATIONS``); ``None`` keeps
        ``executor.yaml``'s.
    """
    cells: tuple[tuple[float, int], ...]
    algorithms: tuple[str, ...] = ALGORITHMS
    seeds: tuple[int, ...] = (0,)
    train_episodes: int = 40
    test_episodes: int = 8
    train_max_steps: int = 1000
    test_max_steps: int = 200
    cycle_steps: int = 20
    observation: str | None = None

    def __post_init__(self) -> None:
        if self.observation is not None:
            state_dim(self.observation)
        if not self.cells or not self.seeds:
            raise ValueError("grid: needs cells and seeds")
        if set(self.algorithms) - set(ALGORITHMS):
            raise ValueError(f"grid: algorithms must be among {ALGORITHMS}")


@dataclass(frozen=True)
class VariantBudget:
    """Experiment 4 at each algorithm's best grid cell: other rewards, smaller replay memories."""
    rewards: tuple[str, ...] = ()
    replay_capacities: tuple[int, ...] = ()
    seeds: tuple[int, ...] = (0,)


@dataclass(frozen=True)
class PegBudget:
    """:param train_iterations: minibatch updates after each episode (thesis: 50 x 15 = 750).

    :param gamma: the peg's own discount: its episodes last up to 200 steps, ten times the
        Panda task's, whose ``learner.yaml`` discount is tuned to them.
    """
    lrs: tuple[float, ...]
    algorithms: tuple[str, ...] = ALGORITHMS
    seeds: tuple[int, ...] = (0, 1, 2)
    episodes: int = 100
    train_iterations: int = 750
    episode_steps: int = 200
    gamma: float = 0.99

    def __post_init__(self) -> None:
        if not self.lrs or len(self.seeds) < 2:
            raise ValueError("peg: needs lrs and at least two seeds (the Q spread is across seeds)")


@dataclass(frozen=True)
class Profile:
    name: str
    estimator: str
    random: RandomBudget
    grid: GridBudget
    variants: VariantBudget
    peg: PegBudget
    nextage: PegBudget | None = None   # experiment 6: the peg on the simulated Nextage

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {self.estimator!r}")


def load_profile(name: str, path: Path | None = None, estimator: str | None = None) -> Profile:
    """Profile ``name`` of ``config/experiments.yaml`` (or ``path``)."""
    data = yaml.safe_load((Path(path) if path else config_file("experiments.yaml")).read_text())
    profiles = data["profiles"]
    if name not in profiles:
        raise ValueError(f"unknown profile {name!r}; known: {sorted(profiles)}")
    p = profiles[name]
    random = dict(p["random"])
    random["noises"] = tuple(dict(n) for n in random["noises"])
    return Profile(name=name, estimator=estimator or data.get("estimator", "ekf"),
                   random=RandomBudget(**random),
                   grid=GridBudget(**_fields(GridBudget, p["grid"])),
                   variants=VariantBudget(**_fields(VariantBudget, p.get("variants", {}))),
                   peg=PegBudget(**_fields(PegBudget, p["peg"])),
                   nextage=PegBudget(**_fields(PegBudget, p["nextage"])) if "nextage" in p
                   else None)
