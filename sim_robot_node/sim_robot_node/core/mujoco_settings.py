"""What only MuJoCo has a setting for in the shaft task's cell (``ShaftSceneConfig.mujoco``).

Beside its engine (``mujoco_world``) but without importing it: a scene config that names
another engine never loads MuJoCo.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MujocoSettings"]


@dataclass(frozen=True)
class MujocoSettings:
    """What only MuJoCo has a setting for (``mujoco_world``). MuJoCo's constraints are soft: each
    is a spring-damper of time constant ``solref[0]`` (damping ratio ``solref[1]``) whose force
    lets it give a little (``solimp``: the impedance rises from ``solimp[0]`` to ``solimp[1]``
    over ``solimp[2]`` m of penetration). Its defaults (20 ms, 0.9-0.95 over 1 mm) let a pushed
    shaft sink into the bore's wall and a held one creep; the task's 0.1 mm clearance and its
    wedging need them stiffer.

    :param integrator: MuJoCo's integrator: ``implicitfast`` (stable with the arm's damping at a
        1 ms step), ``implicit``, ``Euler`` or ``RK4``.
    :param cone: the friction cone, ``elliptic`` (Coulomb's) or ``pyramidal``.
    :param impratio: tangential over normal impedance of elliptic cones: > 1 makes a contact's
        friction stiffer than its normal, so a wedged shaft sticks instead of creeping.
    :param iterations: the constraint solver's iterations per step.
    :param noslip_iterations: iterations of MuJoCo's no-slip pass after the solver (0: none).
    :param ccd_tolerance: [m] the convex collider's tolerance (the shaft is a cylinder: every
        contact of it goes through it). At MuJoCo's 1e-6, a contact that penetrates less than
        about 1 um can come out with its normal reversed: the wall then pulls the shaft in and
        the squeeze holds it by friction (a landed shaft stuck at the bore's mouth).
    :param rim_chamfer: [m] a 45 degree chamfer of the bore's rim (0: a sharp edge), each of its
        boxes then a convex mesh. pybullet rounds every shape's edges by its URDF collision
        margin, 1 mm (the bore's rim, the shaft's tip); MuJoCo's are sharp, and the shaft's
        flat end resting on a sharp rim holds by friction where pybullet's slides in: without
        it uniform random residuals needed 87 steps (5 of 8 starts in 200 steps, at rest);
        with it 31.7 (32 of 32, docs/learning.md section 14). A chamfer of the tip instead did
        as well (24 steps, 8 of 8) but its mesh doubles the collision time; the rim's costs
        nothing (its boxes are tested anyway).
    :param contact_solref: (time constant [s], damping ratio) of the shaft's contacts and the
        inner ring's hard stop; MuJoCo clamps the time constant to at least 2 time steps.
    :param contact_solimp: (d0, dwidth, width [m], midpoint, power) of the same.
    :param fit_solref: (time constant [s], damping ratio) of the fit's friction (the inner
        ring's joint ``frictionloss``): below the friction force the ring creeps at a speed
        proportional to the force times the constraint's softness.
    :param fit_solimp: (d0, dwidth, width [m], midpoint, power) of the same (only d0 counts:
        friction has no penetration).
    """
    integrator: str = "implicitfast"
    cone: str = "elliptic"
    impratio: float = 10.0
    iterations: int = 50
    noslip_iterations: int = 0
    ccd_tolerance: float = 1e-10
    rim_chamfer: float = 0.001
    contact_solref: tuple[float, ...] = (0.002, 1.0)
    contact_solimp: tuple[float, ...] = (0.99, 0.999, 0.0001, 0.5, 2.0)
    fit_solref: tuple[float, ...] = (0.002, 1.0)
    fit_solimp: tuple[float, ...] = (0.999, 0.999, 0.001, 0.5, 2.0)

    def __post_init__(self) -> None:
        if self.integrator not in ("implicitfast", "implicit", "Euler", "RK4"):
            raise ValueError(f"mujoco: integrator must be implicitfast, implicit, Euler or RK4, "
                             f"got {self.integrator!r}")
        if self.cone not in ("elliptic", "pyramidal"):
            raise ValueError(f"mujoco: cone must be elliptic or pyramidal, got {self.cone!r}")
        if self.iterations < 1 or self.noslip_iterations < 0:
            raise ValueError(f"mujoco: iterations must be >= 1 and noslip_iterations >= 0, got "
                             f"{self.iterations}, {self.noslip_iterations}")
        if not 0.0 < self.ccd_tolerance <= 1e-6:
            raise ValueError(f"mujoco: ccd_tolerance must be in (0, 1e-6] m, got "
                             f"{self.ccd_tolerance}")
        if not 0.0 <= self.rim_chamfer < 0.003:
            raise ValueError(f"mujoco: rim_chamfer must be in [0, 3 mm), got {self.rim_chamfer}")
        if not self.impratio >= 1.0:
            raise ValueError(f"mujoco: impratio must be >= 1, got {self.impratio}")
        for name in ("contact_solref", "fit_solref"):
            value = getattr(self, name)
            if len(value) != 2 or not value[0] > 0.0 or not value[1] > 0.0:
                raise ValueError(f"mujoco: {name} must be (time constant > 0, damping ratio "
                                 f"> 0), got {value}")
        for name in ("contact_solimp", "fit_solimp"):
            value = getattr(self, name)
            if (len(value) != 5 or not 0.0 < value[0] < 1.0 or not 0.0 < value[1] < 1.0
                    or not value[2] > 0.0):
                raise ValueError(f"mujoco: {name} must be (d0, dwidth in (0, 1), width > 0, "
                                 f"midpoint, power), got {value}")
