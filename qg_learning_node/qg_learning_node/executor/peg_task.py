"""The clearance-fit peg-in-hole MDP on a position-controlled arm (SPEC 4; the Nextage).

What the executor needs to run the peg through the ROS stack, the same task as the free peg of
the in-process experiments (``sim_robot_node/core/peg_env.py``):

- state: the peg tip in the workspace, scaled linearly from the cube of side ``workspace_side``
  to [-1, 1]^3. The tip is computed from the tool pose the bridge measures (forward kinematics
  of the joints, as on a real arm): the peg's length below the tool frame along its z axis;
- action: a position offset in [-1, 1]^3 scaled to at most ``action_scale`` per axis; the
  command is a pose reference for the bridge's task-space position controller (the tool's
  orientation is kept), the target clipped to the workspace;
- reward: dense ``exp(-d / reward_length) - 1`` of the measured tip's distance ``d`` to the hole
  bottom, or sparse -1 / 0;
- the episode ends at the goal (terminal: the measured tip within ``goal_tolerance`` of the hole
  bottom) or at its step cap; it starts at the cell's seeded free start ``k``.

The cell (where the block is, the sizes, the workspace) is ``qg_common.peg_task``'s.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from qg_common.params import config_from_dict
from qg_common.peg_task import PegCell
from qg_common.types import PoseReference, StartPose, WrenchSetpoint

from qg_learning_node.executor.residual_task import Observation

__all__ = ["PegTaskConfig", "PegTask", "PEG_STATE_DIM", "PEG_ACTION_DIM"]

PEG_STATE_DIM = 3
PEG_ACTION_DIM = 3


@dataclass(frozen=True)
class PegTaskConfig:
    """The peg task as the executor runs it (``config/executor_nextage.yaml``, section ``peg``).

    :param action_scale: [m] tip offset of a unit action per axis (thesis: 1 cm).
    :param reward_length: [m] length scale of the dense reward ``exp(-d/reward_length) - 1``.
    :param train_max_steps: step cap of training episodes.
    :param test_max_steps: step cap of test episodes.
    :param reward: default reward when a request leaves it empty: sparse | dense.
    """
    action_scale: float = 0.01
    reward_length: float = 0.03
    train_max_steps: int = 200
    test_max_steps: int = 200
    reward: str = "dense"

    def __post_init__(self) -> None:
        if self.reward not in ("sparse", "dense"):
            raise ValueError(f"reward must be sparse or dense, got {self.reward!r}")
        for name in ("action_scale", "reward_length"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.train_max_steps < 1 or self.test_max_steps < 1:
            raise ValueError("step caps must be >= 1")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> PegTaskConfig:
        return config_from_dict(cls, params)

    def max_steps(self, mode: str) -> int:
        return self.train_max_steps if mode == "train" else self.test_max_steps


class PegTask:
    """Maps at-rest observations to scaled tip states and rewards, actions to pose references."""

    state_dim = PEG_STATE_DIM
    action_dim = PEG_ACTION_DIM
    #: The state is a place (the tip), no component measures a step's progress (stall recovery).
    progress_dims: tuple[int, ...] = ()

    def __init__(self, config: PegTaskConfig, cell: PegCell) -> None:
        self.config = config
        self.cell = cell
        self._low = cell.geometry.workspace_low
        self._high = cell.geometry.workspace_high

    def tip(self, obs: Observation) -> np.ndarray:
        """The peg tip in the workspace frame [m], from the measured tool pose."""
        return self.cell.tip(obs.tool_position, obs.tool_rotation)

    def start_pose(self, index: int) -> StartPose:
        """The cell's start ``index``: a seeded free tip position, the tool pointing down."""
        return self.cell.start_pose(index)

    def distance(self, obs: Observation) -> float:
        """[m] the measured tip's distance to the centre of the hole bottom."""
        return float(np.linalg.norm(self.tip(obs) - self.cell.geometry.goal))

    def succeeded(self, obs: Observation) -> bool:
        """The goal: the measured tip within ``goal_tolerance`` of the hole bottom."""
        return self.distance(obs) < self.cell.geometry.goal_tolerance

    def state(self, obs: Observation, previous: Observation | None = None) -> np.ndarray:
        """The tip scaled from the workspace cube to [-1, 1]^3 (clipped); ``previous`` (the
        step's start) is not needed."""
        del previous
        centre, half = (self._low + self._high) / 2, (self._high - self._low) / 2
        return np.clip((self.tip(obs) - centre) / half, -1.0, 1.0)

    def command(self, action: np.ndarray, obs: Observation) -> WrenchSetpoint:
        """The pose reference that moves the tip by ``action`` (clipped to [-1, 1]) times
        ``action_scale``, kept in the workspace; no feed-forward wrench.

        :raises ValueError: for a non-finite action.
        """
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (PEG_ACTION_DIM,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be {PEG_ACTION_DIM} finite numbers, got {action!r}")
        target = np.clip(self.tip(obs) + np.clip(a, -1.0, 1.0) * self.config.action_scale,
                         self._low, self._high)
        rotation = np.asarray(obs.tool_rotation)
        position = self.cell.origin + target - rotation[:, 2] * self.cell.geometry.peg_length
        return WrenchSetpoint(np.zeros(6), PoseReference(position, rotation))

    def hold(self) -> WrenchSetpoint:
        """Stay where the tool is (what the executor sends when an episode is cut short)."""
        return WrenchSetpoint(np.zeros(6))

    def reward(self, obs: Observation, kind: str) -> float:
        """Dense: ``exp(-d / reward_length) - 1``; sparse: -1 per step, 0 at the goal."""
        if kind == "sparse":
            return 0.0 if self.succeeded(obs) else -1.0
        if kind == "dense":
            return float(np.exp(-self.distance(obs) / self.config.reward_length) - 1.0)
        raise ValueError(f"reward must be sparse or dense, got {kind!r}")

    def left_bore(self, obs: Observation) -> bool:
        """The peg cannot leave anything: the workspace clips every target."""
        del obs
        return False
