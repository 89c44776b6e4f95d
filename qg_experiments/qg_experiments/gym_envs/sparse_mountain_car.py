"""``MountainCarContinuous-v0`` with the thesis's sparse reward: -1 per step, 0 at the goal.

Why: the thesis claims the Q-Graph matters most under a sparse reward, where a critic alone sees
nothing but -1 until an episode first reaches the goal. Gymnasium's continuous mountain car
pays +100 at the goal and an action cost otherwise (a dense shaping of sorts); this variant keeps
its dynamics, start, goal (terminal) and 999-step cap and replaces only the reward, so the
returns read as steps: a return of -120 is the goal reached in 121 steps, -999 never reached.
The realisable range is [-1 / (1 - gamma), 0], the a-priori bounds QG-DDPG takes.
"""
from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

__all__ = ["SparseMountainCar", "REWARD_RANGE"]

#: The rewards: -1 per step, 0 on the step that reaches the goal.
REWARD_RANGE = (-1.0, 0.0)


class SparseMountainCar(gymnasium.Wrapper):
    """Gymnasium's ``MountainCarContinuous-v0`` (its 999-step limit included) with the sparse
    reward of :data:`REWARD_RANGE`; ``info["is_success"]`` on reaching the goal."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(gymnasium.make("MountainCarContinuous-v0", **kwargs))

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        obs, _, terminated, truncated, info = self.env.step(action)
        return obs, 0.0 if terminated else -1.0, terminated, truncated, {
            **info, "is_success": bool(terminated)}
