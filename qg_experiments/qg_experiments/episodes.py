"""One episode of the shaft task driven to its end on an in-process robot, and the seeds of a
run's episodes.

Why: training, testing, the random baseline and the diagnoses run episodes exactly as the
executor node does (its ``Episode``, its stall recovery), and a seed must give the same steps.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from qg_learning_node.executor.episode import Actor, Episode, TransitionRecord
from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_learning_node.executor.stall_recovery import StallRecovery

from qg_experiments.core.insertion_robot import InsertionRobot

__all__ = ["run_episode", "zero_policy", "episode_noise_seed", "recovery_seed"]

#: Recovery episodes' perturbation seeds start here (``recovery_seed``): apart from training's.
_RECOVERY_SEEDS = 100_000


def episode_noise_seed(run_seed: int, index: int) -> int:
    """Exploration-noise seed of episode ``index`` of a run (distinct across runs and episodes)."""
    return 1_000_003 * run_seed + 1000 + index


def recovery_seed(run_seed: int, index: int) -> int:
    """Perturbation seed of recovery episode ``index`` of a run (distinct from every training
    episode's noise seed of the same run)."""
    return episode_noise_seed(run_seed, _RECOVERY_SEEDS + index)


def zero_policy(state: np.ndarray) -> np.ndarray:
    """The base policy alone; with exploration noise on top it is a random residual policy."""
    del state
    return np.zeros(ACTION_DIM)


def run_episode(env: InsertionRobot, episode: Episode, actor: Actor,
                on_transition: Callable[[TransitionRecord], None] | None = None,
                recovery: StallRecovery | None = None) -> dict[str, Any]:
    """Drive ``episode`` to its end on ``env``; ``on_transition(record)`` after every step.

    :param recovery: stall recovery between the actor and the robot, as the executor node
        runs it in test episodes; the result then counts its ``recoveries`` and their steps.
    """
    episode.begin(env.reset(episode.initial_pose))
    while not episode.done:
        action = episode.choose_action(actor)
        if recovery is not None:
            action = recovery.act(episode.state, action)
        record: TransitionRecord = episode.observe(action, env.step(action))
        if on_transition is not None:
            on_transition(record)
    result = {"episode": episode.episode_id, "mode": episode.mode, "pose": episode.initial_pose,
              "steps": episode.step, "success": episode.success,
              "end_reason": episode.end_reason, "return": episode.episode_return,
              "truly_inserted": episode.truly_inserted}
    if recovery is not None:
        result.update(recoveries=recovery.recoveries, recovered_at=list(recovery.started_at))
    return result
