"""Experiment 1: random residual policies, the bar a learner has to beat.

The base push with a random residual on top: uniform over the whole action box, or Gaussian or
Ornstein-Uhlenbeck noise (theta and dt from ``executor.yaml``) of a given sigma. It is the
executor's training episode with the zero actor and that noise, so step caps, end reasons and
the pose rotation are the same as in learning runs.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from qg_common.types import N_START_POSES
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.noise import KINDS, ActionNoise, NoiseConfig
from qg_learning_node.executor.residual_task import ACTION_DIM

from qg_experiments import stats
from qg_experiments.profile import RandomBudget
from qg_experiments.runner import (
    ESTIMATORS,
    InsertionRobot,
    StackSettings,
    config_digest,
    episode_noise_seed,
    run_episode,
    zero_policy,
)

__all__ = ["BaselineSpec", "baseline_noise", "baseline_specs", "run_baseline", "summarize_baselines", "random_bar",
           "Bar", "random_bar_of"]


def baseline_noise(noise: NoiseConfig, spec: BaselineSpec) -> NoiseConfig:
    """The executor's ``noise`` as a random policy of ``spec``'s kind and sigma: every step
    noisy (no clean steps or episodes: the zero actor has no action of its own to send clean,
    so a clean step would be the zero residual, a different policy)."""
    return dataclasses.replace(noise, kind=spec.kind, sigma=spec.sigma, clean_fraction=0.0,
                               clean_episode_fraction=0.0)


@dataclass(frozen=True)
class BaselineSpec:
    """Random residuals of one noise ``kind``/``sigma`` for ``episodes`` episodes (poses rotate).

    :param max_steps: step cap of an episode (thesis: 1000, the training cap).
    """
    kind: str
    sigma: float
    episodes: int = 8
    max_steps: int = 1000
    seed: int = 0
    estimator: str = "ekf"
    config_dir: str | None = None
    experiment: str = "random"
    arm: str = "realistic"

    def __post_init__(self) -> None:
        if self.kind not in KINDS or self.kind == "none":
            raise ValueError(f"noise kind must be one of {KINDS[1:]}, got {self.kind!r}")
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {self.estimator!r}")
        if self.episodes < 1 or self.max_steps < 1:
            raise ValueError("episodes and max_steps must be >= 1")

    @property
    def label(self) -> str:
        return "uniform" if self.kind == "uniform" else f"{self.kind} sigma={self.sigma:g}"

    @property
    def name(self) -> str:
        sigma = "" if self.kind == "uniform" else f"_sigma{self.sigma:g}"
        arm = "_ideal" if self.arm == "ideal" else ""
        return f"{self.kind}{sigma}{arm}_s{self.seed}"

    def run(self) -> dict[str, Any]:
        return run_baseline(self)


def run_baseline(spec: BaselineSpec) -> dict[str, Any]:
    """Run the episodes; per-episode records plus simulated/wall time."""
    start = time.perf_counter()
    settings = StackSettings.load(spec.config_dir, spec.arm).with_arm_seed(spec.seed)
    settings = dataclasses.replace(
        settings, task=dataclasses.replace(settings.task, train_max_steps=spec.max_steps))
    noise_config = baseline_noise(settings.noise, spec)
    env = InsertionRobot(settings, spec.estimator)
    episodes = []
    for index in range(spec.episodes):
        noise = ActionNoise(noise_config, ACTION_DIM, episode_noise_seed(spec.seed, index))
        episode = Episode(f"random{index:03d}", "train", index % N_START_POSES,
                          settings.task.reward, env.residual, noise)
        episodes.append(run_episode(env, episode, zero_policy))
    return {"experiment": spec.experiment, "name": spec.name, "label": spec.label,
            "spec": dataclasses.asdict(spec), "config_digest": config_digest(spec.config_dir),
            **settings.step_record,
            "episodes": episodes, "rl_steps": env.steps,
            "step_timeouts": env.step_timeouts, "sim_time": env.sim_time,
            "wall_time": time.perf_counter() - start}


def summarize_baselines(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per noise setting (seeds pooled): steps per episode, failures counted at the cap."""
    by_label: dict[str, list[dict[str, Any]]] = {}
    for result in results:
        by_label.setdefault(result["label"], []).append(result)
    rows = []
    for label, group in by_label.items():
        episodes = [e for r in group for e in r["episodes"]]
        steps = np.array([e["steps"] for e in episodes], dtype=float)
        rows.append({"label": label, "kind": group[0]["spec"]["kind"],
                     "sigma": group[0]["spec"]["sigma"], "episodes": len(episodes),
                     "max_steps": group[0]["spec"]["max_steps"],
                     "success_rate": float(np.mean([e["success"] for e in episodes])),
                     "mean_steps": float(steps.mean()), "median_steps": float(np.median(steps)),
                     "std_steps": float(steps.std()), "steps": steps.astype(int).tolist(),
                     "wall_time": float(sum(r["wall_time"] for r in group)),
                     "sim_time": float(sum(r["sim_time"] for r in group))})
    return sorted(rows, key=lambda row: row["mean_steps"])


def random_bar(rows: list[dict[str, Any]], cap: int) -> tuple[float, str] | None:
    """The best random baseline's mean steps with every episode counted at most ``cap`` steps.

    Learning runs are tested with their own step cap, and a failed test counts as that cap; the
    random episodes are cut the same way so both means are over the same truncated quantity.
    :returns: ``(mean, label)`` of the best setting, or ``None`` without baselines.
    """
    if not rows:
        return None
    capped = [(float(np.minimum(row["steps"], cap).mean()), row["label"]) for row in rows]
    return min(capped)


@dataclass(frozen=True)
class Bar:
    """The random bar: the best random setting's mean steps, its episodes cut at the test cap,
    with the 95 % interval over those episodes."""
    label: str
    interval: stats.Interval
    cap: int

    @property
    def mean(self) -> float:
        return self.interval.mean


def random_bar_of(rows: list[dict[str, Any]], cap: int) -> Bar | None:
    """The :class:`Bar` of the random baselines ``rows`` (:func:`random_bar`)."""
    best = random_bar(rows, cap)
    if best is None:
        return None
    row = next(r for r in rows if r["label"] == best[1])
    return Bar(best[1], stats.mean_interval(np.minimum(row["steps"], cap)), cap)


def baseline_specs(budget: RandomBudget, estimator: str = "ekf", config_dir: str | None = None,
                   arm: str = "realistic") -> list[BaselineSpec]:
    """One spec per noise setting and seed of the profile (each seed on its own arm)."""
    return [BaselineSpec(kind=n["kind"], sigma=float(n.get("sigma", 0.0)),
                         episodes=budget.episodes, max_steps=budget.max_steps, seed=seed,
                         estimator=estimator, config_dir=config_dir, arm=arm)
            for n in budget.noises for seed in budget.seeds]
