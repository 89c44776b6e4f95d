"""Exploration noise for the residual torques, and the random baselines built from it.

The thesis compares uniform sampling with Gaussian and Ornstein-Uhlenbeck noise (theta = 1,
dt = 0.01) for the random baselines; the same processes serve as exploration noise in training.
All live in actor-output units, [-1, 1] per dimension, and the result is clipped to that box.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["NoiseConfig", "ActionNoise", "KINDS"]

KINDS = ("none", "gaussian", "ou", "uniform")


@dataclass(frozen=True)
class NoiseConfig:
    """:param kind: none | gaussian | ou | uniform.
    :param sigma: standard deviation (gaussian, ou); ignored by uniform (the whole box).
    :param theta: OU mean reversion; :param dt: OU time step.
    :param clean_fraction: share of training steps that send the actor's own action without
        noise (``config/executor.yaml``'s 0.2, chosen on the tuning seeds; 0: every step noisy,
        the thesis). Why: a deterministic test actor can stall at a
        fixed point where its own action, repeated at rest, leaves the state unchanged; with
        noise on every step that action never reaches replay, and the critic never learns
        what it is worth (docs/learning.md section 17). A random policy (a zero actor) has no
        action of its own: its baselines keep 0.
    :param clean_episode_fraction: share of training episodes that send the actor's own action
        on every step (0: none). Why: the deterministic test actor follows its own path, which
        noisy episodes leave after a step or two; a clean episode puts that whole path, and a
        stall at its end, into replay, where the critic learns what the stall is worth.
    """
    kind: str = "gaussian"
    sigma: float = 0.3
    theta: float = 1.0
    dt: float = 0.01
    clean_fraction: float = 0.2
    clean_episode_fraction: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"noise kind must be one of {KINDS}, got {self.kind!r}")
        if self.sigma < 0 or self.theta < 0 or self.dt <= 0:
            raise ValueError(f"noise needs sigma >= 0, theta >= 0, dt > 0; got {self}")
        if not 0.0 <= self.clean_fraction <= 1.0:
            raise ValueError(f"noise clean_fraction must lie in [0, 1], got {self.clean_fraction}")
        if not 0.0 <= self.clean_episode_fraction <= 1.0:
            raise ValueError("noise clean_episode_fraction must lie in [0, 1], got "
                             f"{self.clean_episode_fraction}")

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> NoiseConfig:
        return cls(**{k: v for k, v in values.items() if k in cls.__dataclass_fields__})


class ActionNoise:
    """Noise added to the actor's output (or, with a zero actor, a random policy).

    :param dim: action dimension.
    """

    def __init__(self, config: NoiseConfig, dim: int, seed: int = 0) -> None:
        self.config = config
        self.dim = dim
        self.reset(seed)

    def reset(self, seed: int) -> None:
        """Start a new episode's noise sequence (OU state back to 0)."""
        self.rng = np.random.default_rng(seed)
        # the clean steps draw from their own stream: the noise samples stay those of the seed
        self.clean_rng = np.random.default_rng([seed, 1])
        fraction = self.config.clean_episode_fraction
        self.clean_episode = fraction > 0 and bool(
            np.random.default_rng([seed, 2]).random() < fraction)
        self.ou_state = np.zeros(self.dim)

    def sample(self) -> np.ndarray:
        c = self.config
        if c.kind == "gaussian":
            return self.rng.normal(0.0, c.sigma, self.dim)
        if c.kind == "ou":
            self.ou_state = (self.ou_state - c.theta * self.ou_state * c.dt
                             + c.sigma * np.sqrt(c.dt) * self.rng.normal(size=self.dim))
            return self.ou_state.copy()
        if c.kind == "uniform":
            return self.rng.uniform(-1.0, 1.0, self.dim)
        return np.zeros(self.dim)

    def perturb(self, action: np.ndarray) -> np.ndarray:
        """``action`` plus one noise sample, clipped to [-1, 1]."""
        return np.clip(action + self.sample(), -1.0, 1.0)

    def clean_step(self) -> bool:
        """Whether this training step goes without noise (every step of a clean episode, else
        ``clean_fraction`` of them, drawn from their own seeded stream)."""
        if self.clean_episode:
            return True
        return self.config.clean_fraction > 0 and bool(
            self.clean_rng.random() < self.config.clean_fraction)

    def explore(self, action: np.ndarray) -> np.ndarray:
        """A training step's action: ``action`` itself on a clean step, else :meth:`perturb`;
        clipped to [-1, 1]. With ``clean_fraction`` 0 exactly :meth:`perturb`."""
        if self.clean_step():
            return np.clip(action, -1.0, 1.0)
        return self.perturb(action)
