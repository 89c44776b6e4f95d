"""The residual force-policy MDP of the shaft insertion: state, action, reward, episode end.

One definition for the ROS executor and the fast in-process runner, so both run the same task:
- state: estimated contact (Fx, Fy, Tx, Ty) in the EEF frame, linearly scaled to [-1, 1];
- action: actor output in [-1, 1]^2 scaled to residual torques (tx, ty) of at most 3 Nm, on top
  of the constant base push Fz = -15 N: the feed-forward wrench [0, 0, Fz, tx, ty, 0];
- reward: sparse (-1 per step, 0 at the goal) or dense (pose error to the inserted pose);
- the episode ends at the goal (terminal), at its step cap, or when the shaft leaves the bore.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["TaskConfig", "Observation", "ResidualTask", "STATE_DIM", "ACTION_DIM"]

STATE_DIM = 4
ACTION_DIM = 2


@dataclass(frozen=True)
class TaskConfig:
    """:param base_force: constant push along EEF z [N] (negative: into the bore).
    :param max_residual_torque: actor output 1.0 maps to this torque [Nm].
    :param force_range: |F| that maps to state 1.0 [N]; :param torque_range: same for torque [Nm].
    :param sigma_position: dense reward's position scale [m]; :param sigma_orientation: [rad].
    :param max_lateral_offset: the episode ends (not terminal) past this tip offset [m].
    :param train_max_steps: step cap of training episodes; :param test_max_steps: of test ones.
    :param reward: default reward type, sparse | dense.
    """
    base_force: float = -15.0
    max_residual_torque: float = 3.0
    force_range: float = 20.0
    torque_range: float = 3.0
    sigma_position: float = 0.015
    sigma_orientation: float = 0.7
    max_lateral_offset: float = 0.015
    train_max_steps: int = 1000
    test_max_steps: int = 200
    reward: str = "dense"

    def __post_init__(self) -> None:
        if self.reward not in ("sparse", "dense"):
            raise ValueError(f"reward must be sparse or dense, got {self.reward!r}")
        for name in ("max_residual_torque", "force_range", "torque_range", "sigma_position",
                     "sigma_orientation", "max_lateral_offset"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.train_max_steps < 1 or self.test_max_steps < 1:
            raise ValueError("step caps must be >= 1")

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "TaskConfig":
        unknown = set(values) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown task parameters: {sorted(unknown)}")
        return cls(**values)

    def max_steps(self, mode: str) -> int:
        return self.train_max_steps if mode == "train" else self.test_max_steps


@dataclass(frozen=True)
class Observation:
    """What the executor sees when a step comes to rest (simulator truth only for rewards)."""
    wrench: np.ndarray            # (6,) estimated contact wrench, tool frame
    success: bool                 # ground truth: fully inserted
    position_error: float         # [m] to the inserted pose
    orientation_error: float      # [rad] norm of the x/y angle-axis error
    lateral_offset: float         # [m] tip from the hole axis


class ResidualTask:
    """Maps observations to states and rewards, and actions to feed-forward wrenches."""

    def __init__(self, config: TaskConfig) -> None:
        self.config = config
        c = config
        self._state_scale = np.array([c.force_range, c.force_range, c.torque_range, c.torque_range])

    def state(self, obs: Observation) -> np.ndarray:
        """(Fx, Fy, Tx, Ty) scaled to [-1, 1] (clipped)."""
        w = np.asarray(obs.wrench, dtype=np.float64)
        raw = np.array([w[0], w[1], w[3], w[4]])
        return np.clip(raw / self._state_scale, -1.0, 1.0)

    def wrench(self, action: np.ndarray) -> np.ndarray:
        """Feed-forward wrench [0, 0, Fz, tx, ty, 0] for an actor output in [-1, 1]^2.

        :raises ValueError: for a non-finite action (the caller sends the zero residual instead).
        """
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (ACTION_DIM,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be {ACTION_DIM} finite numbers, got {action!r}")
        tx, ty = np.clip(a, -1.0, 1.0) * self.config.max_residual_torque
        return np.array([0.0, 0.0, self.config.base_force, tx, ty, 0.0])

    def reward(self, obs: Observation, kind: str) -> float:
        """Sparse: -1 per step, 0 at the goal. Dense: 0.5 (exp(-dR/sR) + exp(-dP/sP)) - 1."""
        if kind == "sparse":
            return 0.0 if obs.success else -1.0
        if kind == "dense":
            c = self.config
            return 0.5 * (np.exp(-obs.orientation_error / c.sigma_orientation)
                          + np.exp(-obs.position_error / c.sigma_position)) - 1.0
        raise ValueError(f"reward must be sparse or dense, got {kind!r}")

    def left_bore(self, obs: Observation) -> bool:
        """The shaft tip left the hole axis too far: end the episode (a failure, not terminal)."""
        return obs.lateral_offset > self.config.max_lateral_offset

    @staticmethod
    def reward_range(kind: str) -> tuple[float, float]:
        """(r_min, r_max) of both reward types: [-1, 0]."""
        del kind
        return (-1.0, 0.0)
