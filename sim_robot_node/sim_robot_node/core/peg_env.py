"""The clearance-fit peg-in-hole task as an RL environment (thesis ch. 3.1.1 and 8.3.2; SPEC 4).

The peg is always upright; an action is a 3-D position offset in [-1, 1] scaled to at most 1 cm
per axis. The new reference is set and the simulation runs until the peg is at rest again, so one
RL step is one settled move. The state is what the thesis calls the tip position of the peg
(its goal is "an element of the state space"): the tip in the workspace, scaled linearly from the
20 cm cube to [-1, 1]. The reward ``exp(-d/0.03) - 1`` of the distance ``d`` to the goal at the
hole bottom lies in [-1, 0]; reaching the goal (peg inserted) ends the episode.

Two ways to move the peg:
* free (default): the peg alone, dragged by a force-limited rigid constraint to the reference;
  fast, and what the hyperparameter sweeps of experiment 5 need;
* arm: the Nextage scene, the reference going through a task-space position controller (IK) to
  the motors. The controller lives in ``robot_bridge_node``, which depends on this package, so it
  is passed in (anything with ``reset(q)`` and ``step(q, pose) -> q_target``).

Both rebuild their pybullet world on ``reset``, so an episode depends only on its seed and actions.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import pybullet as p
from qg_common.params import config_from_dict
from qg_common.peg_task import PegCell, PegHoleGeometry, sample_start

from sim_robot_node.core.nextage_scene import (
    NextagePegScene,
    NextageSceneConfig,
    build_hole_block,
    build_peg,
)

__all__ = ["PegEnvConfig", "PegEnv", "JointTargetController", "toward_goal", "make_peg_env"]


class JointTargetController(Protocol):
    """A task-space position controller (e.g. the bridge's ``TaskSpacePositionController``)."""

    def reset(self, q: np.ndarray) -> None:
        """Start from the measured configuration."""

    def step(self, q: np.ndarray, pose_reference: np.ndarray) -> np.ndarray:
        """Joint position target toward a 4x4 tool pose reference."""


@dataclass(frozen=True)
class PegEnvConfig:
    """The peg environment.

    :param action_scale: peg offset of a unit action per axis [m] (thesis: 1 cm).
    :param episode_steps: RL steps after which an episode is cut (not terminal) [steps].
    :param reward_length: length scale of the reward ``exp(-d/reward_length) - 1`` [m].
    :param time_step: physics step [s].
    :param drive_force: force limit of the free peg's drive constraint [N].
    :param rest_speed: the peg is at rest below this tip speed [m/s] ...
    :param rest_time: ... held for this long [s].
    :param min_step_time: shortest RL step [s].
    :param max_step_time: longest RL step: the move ends here even if not at rest [s].
    :param use_arm: move the peg with the Nextage arm instead of the free drive.
    :param geometry: the peg and hole (also used by the arm scene, overriding its own).
    :param arm: the Nextage scene (only with ``use_arm``).
    """
    action_scale: float = 0.01
    episode_steps: int = 200
    reward_length: float = 0.03
    time_step: float = 1e-3
    drive_force: float = 20.0
    rest_speed: float = 0.002
    rest_time: float = 0.01
    min_step_time: float = 0.02
    max_step_time: float = 0.5
    use_arm: bool = False
    geometry: PegHoleGeometry = field(default_factory=PegHoleGeometry)
    arm: NextageSceneConfig = field(default_factory=NextageSceneConfig)

    def __post_init__(self) -> None:
        for name in ("action_scale", "reward_length", "time_step", "drive_force", "rest_speed",
                     "rest_time", "min_step_time", "max_step_time"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.episode_steps < 1:
            raise ValueError(f"episode_steps must be >= 1, got {self.episode_steps}")
        if not self.min_step_time <= self.max_step_time:
            raise ValueError(f"min_step_time {self.min_step_time} exceeds max_step_time "
                             f"{self.max_step_time}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> PegEnvConfig:
        """Build from a parameter dict (``geometry`` and ``arm`` nested; unknown keys fail)."""
        return config_from_dict(cls, params)


class PegEnv:
    """Free (or arm-held) upright peg over a block with a clearance-fit hole.

    :param config: the environment.
    :param controller: the task-space position controller, required with ``config.use_arm``.
    """

    state_dim = 3
    action_dim = 3

    def __init__(self, config: PegEnvConfig | None = None,
                 controller: JointTargetController | None = None) -> None:
        self.config = config or PegEnvConfig()
        if self.config.use_arm and controller is None:
            raise ValueError("use_arm needs a task-space position controller")
        self.geometry = self.config.geometry
        self.controller = controller
        self._centre = (self.geometry.workspace_low + self.geometry.workspace_high) / 2
        self._half = (self.geometry.workspace_high - self.geometry.workspace_low) / 2
        self._client: int | None = None
        self._scene: NextagePegScene | None = None
        self.steps = 0
        self.physics_steps = 0

    # --- public API -------------------------------------------------------------------------
    @property
    def goal_state(self) -> np.ndarray:
        """The state of a fully inserted peg."""
        return self.scale_state(self.geometry.goal)

    @property
    def scene(self) -> NextagePegScene | None:
        """The Nextage scene of the arm option (ground truth, wrist sensor); None if free."""
        return self._scene

    @property
    def truncated(self) -> bool:
        """True once the episode has run ``episode_steps`` steps."""
        return self.steps >= self.config.episode_steps

    def scale_state(self, tip: np.ndarray) -> np.ndarray:
        """Tip position (workspace frame) -> state in [-1, 1]^3."""
        return np.clip((np.asarray(tip, float) - self._centre) / self._half, -1.0, 1.0)

    def reward(self, tip: np.ndarray) -> float:
        """``exp(-d/reward_length) - 1`` with ``d`` the tip distance to the goal [m]."""
        distance = np.linalg.norm(np.asarray(tip, float) - self.geometry.goal)
        return float(np.exp(-distance / self.config.reward_length) - 1.0)

    def reset(self, seed: int | None = None, start: np.ndarray | None = None) -> np.ndarray:
        """New episode with the tip at ``start`` (workspace frame) or at a free random position.

        :returns: the initial state.
        """
        tip = sample_start(self.geometry, np.random.default_rng(seed)) if start is None \
            else np.asarray(start, float)
        if not self.geometry.is_free(tip, margin=0.0):
            raise ValueError(f"start {tip} overlaps the block")
        if self.config.use_arm:
            self._reset_arm(tip)
        else:
            self._reset_free(tip)
        self.steps = 0
        return self.scale_state(self.tip())

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool]:
        """Move by ``action`` (clipped to [-1, 1]) and wait until the peg is at rest.

        :returns: next state, reward, terminal (the peg is inserted).
        :raises ValueError: on a non-finite action or a step before ``reset``.
        """
        if self._client is None and self._scene is None:
            raise ValueError("call reset() before step()")
        action = np.asarray(action, float)
        if action.shape != (self.action_dim,) or not np.all(np.isfinite(action)):
            raise ValueError(f"action must be {self.action_dim} finite values, got {action}")
        target = np.clip(self.tip() + np.clip(action, -1.0, 1.0) * self.config.action_scale,
                         self.geometry.workspace_low, self.geometry.workspace_high)
        self._settle(target)
        self.steps += 1
        tip = self.tip()
        distance = float(np.linalg.norm(tip - self.geometry.goal))
        return self.scale_state(tip), self.reward(tip), distance < self.geometry.goal_tolerance

    def tip(self) -> np.ndarray:
        """Peg tip position in the workspace frame [m] (ground truth)."""
        if self._scene is not None:
            return self._scene.peg_tip()
        position, _ = p.getBasePositionAndOrientation(self._peg, physicsClientId=self._client)
        return np.asarray(position) - np.array([0.0, 0.0, self.geometry.peg_length / 2])

    def close(self) -> None:
        """Release the physics client."""
        if self._scene is not None:
            self._scene.close()
            self._scene = None
        if self._client is not None and p.isConnected(self._client):
            p.disconnect(self._client)
        self._client = None

    # --- free peg ---------------------------------------------------------------------------
    def _reset_free(self, tip: np.ndarray) -> None:
        if self._client is None:
            self._client = p.connect(p.DIRECT)
        client = self._client
        p.resetSimulation(physicsClientId=client)
        p.setGravity(0, 0, -9.81, physicsClientId=client)
        p.setPhysicsEngineParameter(fixedTimeStep=self.config.time_step, physicsClientId=client)
        floor = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
        p.createMultiBody(0.0, floor, physicsClientId=client)
        build_hole_block(client, self.geometry, np.zeros(3))
        self._peg = build_peg(client, self.geometry)
        centre = (tip + [0.0, 0.0, self.geometry.peg_length / 2]).tolist()
        p.resetBasePositionAndOrientation(self._peg, centre, [0, 0, 0, 1], physicsClientId=client)
        self._drive = p.createConstraint(self._peg, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0],
                                         [0, 0, 0], centre, physicsClientId=client)
        p.changeConstraint(self._drive, centre, maxForce=self.config.drive_force,
                           physicsClientId=client)

    # --- arm --------------------------------------------------------------------------------
    def _reset_arm(self, tip: np.ndarray) -> None:
        if self._scene is not None:
            self._scene.close()
        self._scene = NextagePegScene(replace(self.config.arm, time_step=self.config.time_step),
                                      PegCell(geometry=self.geometry))
        q = self._scene.reset(start=tip)
        self.controller.reset(q)
        self._pose_reference = self._scene.tool_pose()

    # --- shared -----------------------------------------------------------------------------
    def _settle(self, target: np.ndarray) -> None:
        """Set the reference to ``target`` (tip, workspace frame) and run until at rest."""
        cfg = self.config
        if self._scene is not None:
            self._pose_reference = self._scene.tool_pose_for_tip(target)
        else:
            centre = (target + [0.0, 0.0, self.geometry.peg_length / 2]).tolist()
            p.changeConstraint(self._drive, centre, maxForce=cfg.drive_force,
                               physicsClientId=self._client)
        min_steps = round(cfg.min_step_time / cfg.time_step)
        max_steps = round(cfg.max_step_time / cfg.time_step)
        rest_steps = max(1, round(cfg.rest_time / cfg.time_step))
        calm = 0
        previous = self.tip()
        for n in range(1, max_steps + 1):
            self._physics_step()
            tip = self.tip()
            speed = np.linalg.norm(tip - previous) / cfg.time_step
            previous = tip
            calm = calm + 1 if speed < cfg.rest_speed else 0
            if n >= min_steps and calm >= rest_steps:
                break

    def _physics_step(self) -> None:
        self.physics_steps += 1
        if self._scene is None:
            p.stepSimulation(physicsClientId=self._client)
            return
        q = self._scene.joint_state().q
        self._scene.set_joint_targets(self.controller.step(q, self._pose_reference))
        self._scene.step()


def toward_goal(env: PegEnv) -> np.ndarray:
    """A scripted baseline policy: rise above the block, centre over the hole, go straight down.

    It reads the true tip position, so it is a reference for what a learner can approach, not
    a policy on the state alone.
    """
    g = env.geometry
    tip = env.tip()
    offset = g.goal - tip
    if np.linalg.norm(offset[:2]) > 0.002:
        if tip[2] < g.block_height + 0.01:
            return np.array([0.0, 0.0, 1.0])
        return np.clip(np.r_[offset[:2], 0.0] / g.hole_radius, -1.0, 1.0)
    return np.clip(offset / g.hole_radius, -1.0, 1.0)


def make_peg_env(params: dict[str, Any], **overrides: Any) -> PegEnv:
    """The free peg from ``config/peg_env.yaml``'s parameters with ``overrides`` (e.g.
    ``episode_steps``); registered as the learning environment ``peg``."""
    return PegEnv(replace(PegEnvConfig.from_dict(params), **overrides))
