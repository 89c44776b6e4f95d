"""Experiment budgets by profile (``config/experiments.yaml``): thesis, small and tiny (CI).

One profile fixes, for every experiment, how many runs, episodes and steps are spent; the task,
bridge, estimator and learner numbers always come from the stack's own config files. Seeds are
split once for all profiles: ``seeds.tuning`` for every probe and choice, ``seeds.report`` for
the report only, so no number in ``results.md`` comes from a seed a choice was made on. A budget
names its seeds as ``report``, ``tuning`` or an explicit list.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from qg_common.params import config_file, load_yaml
from qg_learning_node.executor.residual_task import state_dim
from qg_learning_node.learner.algorithms import COMPARED

from qg_experiments.runner import ALGORITHMS, ARMS, ESTIMATORS

__all__ = ["RandomBudget", "GridBudget", "VariantBudget", "PegBudget", "Profile", "Seeds",
           "Statistics", "load_profile", "VARIANT_KEYS"]

#: What a variant may change in a grid run (``RunSpec`` fields).
VARIANT_KEYS = ("reward", "replay_capacity", "gamma", "observation")


@dataclass(frozen=True)
class Seeds:
    """The two disjoint seed sets (``config/experiments.yaml``, ``seeds``)."""
    tuning: tuple[int, ...]
    report: tuple[int, ...]

    def __post_init__(self) -> None:
        if set(self.tuning) & set(self.report):
            raise ValueError(f"tuning and report seeds overlap: "
                             f"{sorted(set(self.tuning) & set(self.report))}")

    def resolve(self, value: Any) -> tuple[int, ...]:
        """``report``, ``tuning`` or a list of seeds."""
        if value in ("report", "tuning"):
            return getattr(self, value)
        if isinstance(value, (list, tuple)) and value and all(
                isinstance(v, int) and not isinstance(v, bool) for v in value):
            return tuple(value)
        raise ValueError(f"seeds must be 'report', 'tuning' or a list of integers, got {value!r}")


@dataclass(frozen=True)
class Statistics:
    """How the report decides (``config/experiments.yaml``, ``statistics``).

    :param level: the significance level of every test, after Holm's correction over the
        settings judged together.
    :param equivalence_margin: [test steps per episode] the difference in mean test steps that
        counts as no difference: two algorithms are equivalent when the paired difference lies
        inside (-margin, margin) beyond doubt (TOST).
    """
    level: float = 0.05
    equivalence_margin: float = 10.0

    def __post_init__(self) -> None:
        if not 0.0 < self.level < 1.0 or not self.equivalence_margin > 0:
            raise ValueError("statistics: level must lie in (0, 1) and equivalence_margin be > 0")


def _fields(cls: type, values: dict[str, Any]) -> dict[str, Any]:
    unknown = set(values) - set(cls.__dataclass_fields__)
    if unknown:
        raise ValueError(f"{cls.__name__}: unknown keys {sorted(unknown)}")
    return {k: tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list)
            else v for k, v in values.items()}


@dataclass(frozen=True)
class RandomBudget:
    """:param noises: ``({kind, sigma}, ...)``; :param episodes: per noise and seed (poses
    rotate); :param seeds: one run per noise and seed, each on its seed's arm."""
    noises: tuple[dict[str, Any], ...]
    episodes: int = 8
    max_steps: int = 1000
    seeds: tuple[int, ...] = (0,)

    def __post_init__(self) -> None:
        if not self.noises or self.episodes < 1 or self.max_steps < 1 or not self.seeds:
            raise ValueError("random: needs noises, seeds, episodes >= 1 and max_steps >= 1")


@dataclass(frozen=True)
class GridBudget:
    """:param cells: ``((critic_lr, iterations per cycle), ...)``.

    :param observation: the state of every run (``residual_task.OBSERVATIONS``); ``None`` keeps
        ``executor.yaml``'s.
    :param stall_recovery: every run also tests its poses with stall recovery, counted apart
        (``RunSpec.stall_recovery``; the runs' names end in ``_recovery``).
    """
    cells: tuple[tuple[float, int], ...]
    algorithms: tuple[str, ...] = COMPARED
    seeds: tuple[int, ...] = (0,)
    train_episodes: int = 40
    test_episodes: int = 8
    train_max_steps: int = 1000
    test_max_steps: int = 200
    cycle_steps: int = 20
    observation: str | None = None
    stall_recovery: bool = False

    def __post_init__(self) -> None:
        if self.observation is not None:
            state_dim(self.observation)
        if not self.cells or not self.seeds:
            raise ValueError("grid: needs cells and seeds")
        if set(self.algorithms) - set(ALGORITHMS):
            raise ValueError(f"grid: algorithms must be among {ALGORITHMS}")


@dataclass(frozen=True)
class VariantBudget:
    """Experiment 4: the grid's protocol with one setting changed, at fixed cells.

    :param cells: ``((critic_lr, iterations), ...)``, the same for both algorithms so each
        (cell, seed) is a pair; ``grid`` in the profile file: every cell of the grid.
    :param settings: ``({name, <one or more of VARIANT_KEYS>}, ...)``, e.g.
        ``{name: sparse, reward: sparse}``.
    """
    cells: tuple[tuple[float, int], ...] = ()
    settings: tuple[dict[str, Any], ...] = ()
    seeds: tuple[int, ...] = (0,)

    def __post_init__(self) -> None:
        for setting in self.settings:
            changes = set(setting) - {"name"}
            if "name" not in setting or not changes or changes - set(VARIANT_KEYS):
                raise ValueError(f"variant {setting!r}: needs a name and one or more of "
                                 f"{VARIANT_KEYS}")
        if self.settings and not self.cells:
            raise ValueError("variants: settings need cells")

    def overrides(self) -> list[tuple[str, dict[str, Any]]]:
        """``(name, RunSpec field changes)`` per setting."""
        return [(s["name"], {k: v for k, v in s.items() if k != "name"})
                for s in self.settings]


@dataclass(frozen=True)
class PegBudget:
    """:param train_iterations: minibatch updates after each episode (thesis: 50 x 15 = 750).

    :param gamma: the peg's own discount: its episodes last up to 200 steps, ten times the
        Panda task's, whose ``learner.yaml`` discount is tuned to them.
    :param random: random policies run on the same seeds and starts, the bar both learners
        have to clear (``peg.PEG_RANDOM_KINDS``); none by default.
    """
    lrs: tuple[float, ...]
    algorithms: tuple[str, ...] = COMPARED
    seeds: tuple[int, ...] = (0, 1, 2)
    episodes: int = 100
    train_iterations: int = 750
    episode_steps: int = 200
    gamma: float = 0.99
    random: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.lrs or len(self.seeds) < 2:
            raise ValueError("peg: needs lrs and at least two seeds (the Q spread is across seeds)")


@dataclass(frozen=True)
class Profile:
    """:param state_grid: the grid once more with another state (the thesis's 4-D wrench
    state), reported beside the grid; ``None``: not run."""
    name: str
    estimator: str
    random: RandomBudget
    grid: GridBudget
    variants: VariantBudget
    peg: PegBudget
    nextage: PegBudget | None = None   # experiment 6: the peg on the simulated Nextage
    state_grid: GridBudget | None = None
    arm: str = "realistic"
    seeds: Seeds = Seeds(tuning=(0,), report=(1,))
    statistics: Statistics = Statistics()

    def __post_init__(self) -> None:
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {self.estimator!r}")
        if self.arm not in ARMS:
            raise ValueError(f"arm must be one of {ARMS}, got {self.arm!r}")


def load_profile(name: str, path: Path | None = None, estimator: str | None = None) -> Profile:
    """Profile ``name`` of ``config/experiments.yaml`` (or ``path``)."""
    data = load_yaml((Path(path) if path else config_file("experiments.yaml")).read_text())
    profiles = data["profiles"]
    if name not in profiles:
        raise ValueError(f"unknown profile {name!r}; known: {sorted(profiles)}")
    seeds = Seeds(tuning=tuple(data["seeds"]["tuning"]), report=tuple(data["seeds"]["report"]))

    def section(cls: type, values: dict[str, Any]) -> Any:
        values = dict(values)
        if "seeds" in values:
            values["seeds"] = seeds.resolve(values["seeds"])
        if "noises" in values:
            values["noises"] = tuple(dict(n) for n in values["noises"])
        if "settings" in values:
            values["settings"] = tuple(dict(s) for s in values["settings"])
        return cls(**_fields(cls, values))

    p = profiles[name]
    grid = section(GridBudget, p["grid"])
    variants = dict(p.get("variants", {}))
    if variants.get("cells") == "grid":          # every cell of the grid
        variants["cells"] = [list(cell) for cell in grid.cells]
    return Profile(name=name, estimator=estimator or data.get("estimator", "ekf"),
                   random=section(RandomBudget, p["random"]), grid=grid,
                   variants=section(VariantBudget, variants),
                   peg=section(PegBudget, p["peg"]),
                   nextage=section(PegBudget, p["nextage"]) if "nextage" in p else None,
                   state_grid=section(GridBudget, {**p["grid"], **p["state_grid"]})
                   if "state_grid" in p else None,
                   arm=data.get("arm", "realistic"), seeds=seeds,
                   statistics=Statistics(**_fields(Statistics, data.get("statistics", {}))))
