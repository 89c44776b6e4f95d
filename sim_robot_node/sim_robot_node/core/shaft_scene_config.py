"""The shaft task's simulated cell as numbers: its physics, the arm's imperfections, the engine.

A leaf of the simulator's imports: the scene (``shaft_scene``), the engines' worlds
(``shaft_world``, ``pybullet_world``, ``mujoco_world``) and the URDF builders (``shaft_urdfs``)
all read it, and it imports none of them, nor any engine.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from qg_common.params import config_from_dict

from sim_robot_node.core.arm_imperfections import ArmImperfections
from sim_robot_node.core.mujoco_settings import MujocoSettings
from sim_robot_node.core.pybullet_settings import PybulletSettings

__all__ = ["ENGINES", "ShaftSceneConfig"]

#: The engines a shaft scene can run on, and the module whose ``build`` makes its world
#: (``shaft_world.build_world`` imports it only then).
ENGINES = {"pybullet": "sim_robot_node.core.pybullet_world",
           "mujoco": "sim_robot_node.core.mujoco_world"}


@dataclass(frozen=True)
class ShaftSceneConfig:
    """The simulated cell's physics and the arm's imperfections (the geometry is the task's,
    ``ShaftTaskGeometry``). The defaults are the Panda's (``config/panda_scene.yaml``); another
    arm's config file names what differs.

    :param engine: the physics engine (:data:`ENGINES`).
    :param time_step: [s] one physics step = one control tick.
    :param gravity: [m/s^2].
    :param bore_segments: boxes in the bore's ring (24 or 32 change what random residuals need).
    :param counterbore_segments: boxes in the counterbore's wall.
    :param plunger_mass: [kg] the inner ring: heavy, so the friction stays Coulomb-like.
    :param plunger_friction: [N] the fit's Coulomb friction.
    :param shaft_mass: [kg] steel, 11.8 mm x 100 mm.
    :param friction: the combined lateral friction coefficient of shaft and housing.
    :param imperfections: the real arm's departures from the bridge's model.
    :param pybullet: pybullet's own settings; :param mujoco: MuJoCo's own settings.
    """
    engine: str = "mujoco"
    time_step: float = 0.001
    gravity: float = 9.81
    bore_segments: int = 48
    counterbore_segments: int = 32
    plunger_mass: float = 2.0
    plunger_friction: float = 11.0
    shaft_mass: float = 0.086
    friction: float = 0.5
    imperfections: ArmImperfections = field(default_factory=ArmImperfections)
    pybullet: PybulletSettings = field(default_factory=PybulletSettings)
    mujoco: MujocoSettings = field(default_factory=MujocoSettings)

    def __post_init__(self) -> None:
        if self.engine not in ENGINES:
            raise ValueError(f"engine must be one of {sorted(ENGINES)}, got {self.engine!r}")
        if not 0.0 < self.time_step <= 0.01:
            raise ValueError(f"time_step must be in (0, 0.01] s, got {self.time_step}")
        for name in ("bore_segments", "counterbore_segments", "plunger_mass",
                     "plunger_friction", "shaft_mass", "friction"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not self.gravity >= 0.0:
            raise ValueError(f"gravity must be >= 0, got {self.gravity}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> ShaftSceneConfig:
        """From a scene section (``panda_scene`` of ``config/panda_scene.yaml``, ``xarm_scene``
        of ``config/xarm_scene.yaml``; ``imperfections``, ``pybullet``, ``mujoco`` nested)."""
        return config_from_dict(cls, params)
