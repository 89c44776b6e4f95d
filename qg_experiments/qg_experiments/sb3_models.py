"""Stable-Baselines3's algorithms of the registry (``learner/algorithms.py``), built one way for
every experiment that runs them beside ours (``peers``, ``standard_tasks``).

Why here: SB3 is the experiments' dependency, not the learner's, so the registry names an SB3
algorithm by its class and this module builds it, with the exploration noise the registry says it
takes (TD3 and DDPG: Gaussian or Ornstein-Uhlenbeck action noise; SAC: none, its policy is
stochastic). SB3 is imported when a model is built: the runs of our own algorithms never load it.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from qg_learning_node.learner.algorithms import algorithm

__all__ = ["OU_DT", "sb3_model"]

#: SB3's OU noise step (``OrnsteinUhlenbeckActionNoise``'s default dt; ``NoiseConfig``'s too).
OU_DT = 0.01


def sb3_model(key: str, env: Any, seed: int, noise: tuple[str, float, float] | None = None,
              **kwargs: Any) -> Any:
    """SB3's algorithm ``key`` with its ``MlpPolicy`` on ``env``, on the CPU.

    :param noise: ``(kind, sigma, theta)`` of the action noise, ``gaussian`` or ``ou``, in SB3's
        scaled action units; given only to an algorithm that takes action noise.
    :param kwargs: the algorithm's own settings (learning rate, ``policy_kwargs``, ...).
    """
    import stable_baselines3
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise
    entry = algorithm(key, "sb3")
    if noise is not None and entry.action_noise:
        kind, sigma, theta = noise
        dim = env.action_space.shape[0]
        mean, scale = np.zeros(dim), sigma * np.ones(dim)
        if kind not in ("gaussian", "ou"):
            raise ValueError(f"noise kind must be gaussian or ou, got {kind!r}")
        kwargs["action_noise"] = (NormalActionNoise(mean, scale) if kind == "gaussian" else
                                  OrnsteinUhlenbeckActionNoise(mean, scale, theta=theta,
                                                               dt=OU_DT))
    return getattr(stable_baselines3, entry.sb3_class)("MlpPolicy", env, seed=seed,
                                                       device="cpu", **kwargs)
