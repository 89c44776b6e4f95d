"""One physics engine's world of the shaft task, behind one small protocol, chosen by name.

The scene (``shaft_scene.ShaftScene``) holds what is the task's and the arm's whatever engine
steps them: the cell's geometry (``qg_common.shaft_task``), the start poses and their inverse
kinematics, the arm's imperfections (friction, sensor errors, jitter), the ground truth. A
``ShaftWorld`` is all an engine contributes: the arm (its URDF) holding the shaft, the housing
with its bore, counterbore and the bearing's inner ring (the "plunger") on its sliding joint, one
physics step, and the states and forces only an engine can tell. ``build_world`` makes the world
of the engine a scene config names (``shaft_scene_config.ENGINES``): ``pybullet``
(``pybullet_world``) or ``mujoco`` (``mujoco_world``); the engine modules are imported only
when built, so one engine's absence or start-up cost never reaches a process that runs the
other.
"""
from __future__ import annotations

import importlib
from typing import Protocol

import numpy as np
from qg_common.arm_description import ArmDescription
from qg_common.shaft_task import Fixture, ShaftTaskGeometry

from sim_robot_node.core.shaft_scene_config import ENGINES, ShaftSceneConfig

__all__ = ["ShaftWorld", "build_world"]


class ShaftWorld(Protocol):
    """The shaft task in one engine: stepped once per control tick.

    Frames: the arm's base frame is the world's; the tool frame is the grasp point on the shaft
    axis, with the flange's orientation (z along the shaft towards its tip). Joint vectors are in
    the order of the arm description's ``joint_names``.
    """

    def set_arm_state(self, q: np.ndarray, dq: np.ndarray) -> None:
        """Put the driven joints at ``q`` moving at ``dq`` (a teleport: no physics between)."""
        ...

    def arm_state(self) -> tuple[np.ndarray, np.ndarray]:
        """The driven joints' true positions [rad] and velocities [rad/s]."""
        ...

    def set_arm_torques(self, tau: np.ndarray) -> None:
        """The joint torques [Nm] the links get during the next steps, until set again."""
        ...

    def step(self) -> None:
        """One physics step of the scene config's ``time_step``; the plunger's weight is carried
        (only the fit's friction holds it)."""
        ...

    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The tool's true position (3,) and rotation (3, 3), base frame."""
        ...

    def place_housing(self, fixture: Fixture) -> None:
        """Put the housing (bearing face centre and orientation) where the fixture really holds
        it."""
        ...

    def plunger_travel(self) -> float:
        """[m] how far the bearing's inner ring has been pushed down its travel."""
        ...

    def set_plunger_travel(self, travel: float) -> None:
        """Put the inner ring ``travel`` down its travel, at rest (0: the start of the fit)."""
        ...

    def contact_wrench(self) -> np.ndarray:
        """(6,) the wrench the housing exerts on the shaft, about the tool origin, tool frame
        (what a perfect wrist force-torque sensor between hand and shaft would read, the
        shaft's weight taken out)."""
        ...

    def close(self) -> None:
        """Release the engine's resources (a process that builds many worlds)."""
        ...


def build_world(arm: ArmDescription, geometry: ShaftTaskGeometry,
                config: ShaftSceneConfig) -> ShaftWorld:
    """The world of ``config.engine``: ``arm`` holding the shaft over the housing of
    ``geometry``, with the physics of ``config`` (and its imperfections' payload error, which
    the world carries and the bridge's model does not know).

    :raises ValueError: for an engine not in :data:`ENGINES`.
    """
    if config.engine not in ENGINES:
        raise ValueError(f"engine must be one of {sorted(ENGINES)}, got {config.engine!r}")
    module = importlib.import_module(ENGINES[config.engine])
    return module.build(arm, geometry, config)
