"""The in-process runner's public names in one place, for the experiments, benchmarks and tests
that import them from here.

Why: the runner's jobs live in modules named for them; this module keeps ``qg_experiments.runner``
importable and defines nothing itself.

=============================  ==================================================================
:mod:`.core.stack_settings`    ``StackSettings``, ``ARMS``, ``DEFAULT_ROBOT``, ``config_digest``,
                               ``STACK_CONFIG_FILES``, ``stall_recovery_config``
:mod:`.core.insertion_robot`   ``InsertionRobot``, ``ESTIMATORS``
:mod:`.episodes`               ``run_episode``, ``zero_policy``, ``episode_noise_seed``,
                               ``recovery_seed``
:mod:`.run_spec`               ``RunSpec``, ``ALGORITHMS``, ``algorithm_config``
:mod:`.critic_check`           ``MonteCarloCheck``
:mod:`.training`               ``run_training``, ``LivePolicy``
=============================  ==================================================================
"""
from __future__ import annotations

from qg_experiments.core.insertion_robot import ESTIMATORS, InsertionRobot
from qg_experiments.core.stack_settings import (
    ARMS,
    DEFAULT_ROBOT,
    STACK_CONFIG_FILES,
    StackSettings,
    config_digest,
    stall_recovery_config,
)
from qg_experiments.critic_check import MonteCarloCheck
from qg_experiments.episodes import episode_noise_seed, recovery_seed, run_episode, zero_policy
from qg_experiments.run_spec import ALGORITHMS, RunSpec, algorithm_config
from qg_experiments.training import LivePolicy, run_training

__all__ = ["ALGORITHMS", "ARMS", "ESTIMATORS", "DEFAULT_ROBOT", "StackSettings", "InsertionRobot",
           "LivePolicy", "RunSpec", "MonteCarloCheck",
           "algorithm_config", "run_episode", "run_training", "episode_noise_seed", "zero_policy",
           "config_digest", "STACK_CONFIG_FILES", "recovery_seed", "stall_recovery_config"]
