"""What only pybullet has a setting for in the shaft task's cell (``ShaftSceneConfig.pybullet``).

Beside its engine (``pybullet_world``) but without importing it: a scene config that names
another engine never loads pybullet.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PybulletSettings"]


@dataclass(frozen=True)
class PybulletSettings:
    """What only pybullet has a setting for.

    :param solver_iterations: constraint solver iterations per step (a light plunger needs 200,
        or the friction motor acts as a damper; the 2 kg one is Coulomb-like at 50).
    :param contact_breaking_threshold: [m] contacts kept this far apart (pybullet's default 0.02
        keeps idle contacts around the ring and makes steps 5x slower).
    """
    solver_iterations: int = 50
    contact_breaking_threshold: float = 0.001

    def __post_init__(self) -> None:
        if self.solver_iterations < 1 or not self.contact_breaking_threshold > 0.0:
            raise ValueError("pybullet: solver_iterations must be >= 1 and "
                             "contact_breaking_threshold > 0")
