"""The Monte-Carlo check of a critic: its Q against the exact discounted return of the
goal-reaching episodes it was trained on.

Why: a run records after every training cycle how far the critic is from the truth
(``critic_mc_error``), the measure of its over- or underestimation.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from qg_learning_node.executor.episode import TransitionRecord

if TYPE_CHECKING:
    from qg_learning_node.learner.ddpg import DDPG

__all__ = ["MonteCarloCheck"]


class MonteCarloCheck:
    """How far the critic is from the true discounted return of the episodes it was trained on.

    For every finished training episode that reached the goal, the discounted return from each
    step on is known exactly (the episode ended in a terminal state); ``error`` is the mean
    absolute difference between the critic's ``Q(s_t, a_t)`` and that return over all of them.
    Episodes cut by the step cap have no exact return and are left out.
    """

    def __init__(self, gamma: float) -> None:
        self.gamma = gamma
        self._open: list[TransitionRecord] = []
        self.states: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []
        self.returns: list[float] = []

    def add(self, record: TransitionRecord) -> None:
        """Take one transition; a terminal one closes its episode's exact returns."""
        self._open.append(record)
        if record.terminal:
            value = 0.0
            for step in reversed(self._open):
                value = step.reward + self.gamma * value
                self.states.append(step.state)
                self.actions.append(step.action)
                self.returns.append(value)
        if record.terminal or record.timeout:
            self._open = []

    def error(self, agent: DDPG) -> float:
        """Mean |Q(s, a) - G| over the goal-reaching episodes so far (NaN before the first)."""
        if not self.returns:
            return float("nan")
        q = agent.q_values(np.array(self.states), np.array(self.actions))
        return float(np.mean(np.abs(np.ravel(q) - np.array(self.returns))))
