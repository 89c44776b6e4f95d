"""The shaft task's world in MuJoCo (``shaft_world.ShaftWorld``), and the cell as a MuJoCo model.

``add_shaft_cell`` is the one MuJoCo description of the cell: it adds the shaft (welded to a
given hand body at the grasp point, with the payload the bridge's model does not know) and the
housing (the bore as a ring of boxes, the counterbore, the bearing's inner ring on a slide joint
with the fit's Coulomb friction and a hard stop at full travel) to any ``mujoco.MjSpec``: the
Panda's here, built from its URDF like pybullet's, or franky-sim's FR3 MJCF. ``set_cell_physics``
sets the options the cell's contacts were tuned with (``ShaftSceneConfig.mujoco``).

The shapes are the ones pybullet builds (``shaft_urdfs``); what differs is how each engine makes
contact rigid. MuJoCo's constraints are soft (a spring-damper of time constant ``solref`` per
constraint, and a force that lets a constraint give a little, ``solimp``), so a 0.1 mm clearance
and a friction that must hold a wedged shaft need stiffer settings than MuJoCo's defaults; each
is a key of ``MujocoSettings`` with the reason beside it.

The cell collides only with itself: its geoms use their own contact bit
(:data:`CELL_CONTACT_BIT`), so the shaft touches the housing and the inner ring and nothing
else, whatever collision geoms the arm's model has. Adding the cell installs MuJoCo's contact
filter ``core/native``: the bore's boxes that a separating axis parts from the shaft never reach
the narrow phase (the same contacts, in fewer microseconds).
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import TYPE_CHECKING
from xml.etree import ElementTree

import mujoco
import numpy as np
from qg_common.arm_description import ArmDescription
from qg_common.shaft_task import Fixture, ShaftTaskGeometry

from sim_robot_node.core.native import contact_wrench_sum, install_contact_filter
from sim_robot_node.core.shaft_urdfs import (
    PAYLOAD_INERTIA,
    PLUNGER_INERTIA,
    bare_arm_urdf,
    housing_boxes,
    plunger_box,
    shaft_inertia,
)

if TYPE_CHECKING:
    from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig

__all__ = ["CELL_CONTACT_BIT", "ShaftCell", "add_shaft_cell", "set_cell_physics",
           "MujocoShaftWorld", "build"]

#: The contype/conaffinity bit of the cell's geoms: the shaft has it as its type, the housing
#: and the inner ring as their affinity, nothing else in a model needs to have it.
CELL_CONTACT_BIT = 1 << 4

_INTEGRATORS = {"implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
                "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
                "Euler": mujoco.mjtIntegrator.mjINT_EULER, "RK4": mujoco.mjtIntegrator.mjINT_RK4}
_CONES = {"elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC, "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL}


@dataclass(frozen=True)
class ShaftCell:
    """The names of the cell's elements in the model ``add_shaft_cell`` added them to."""
    shaft_body: str
    shaft_geom: str
    housing_body: str
    plunger_joint: str
    payload_body: str | None


def _index(addresses: list[int]) -> slice | np.ndarray:
    """Addresses into a MuJoCo array: a slice where they run in order (a view, 20x faster to
    read and write than an index array: this is read and written every tick)."""
    if addresses == list(range(addresses[0], addresses[0] + len(addresses))):
        return slice(addresses[0], addresses[0] + len(addresses))
    return np.array(addresses)


def _quat_from_yaw(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def add_shaft_cell(spec: mujoco.MjSpec, hand: mujoco.MjsBody, geometry: ShaftTaskGeometry,
                   config: ShaftSceneConfig, grasp_position: np.ndarray | None = None,
                   grasp_quat: np.ndarray | None = None, prefix: str = "shaft_cell/"
                   ) -> ShaftCell:
    """Add the shaft task's cell to ``spec``: the shaft held by ``hand``, the housing in the
    world (a mocap body: ``MujocoShaftWorld.place_housing`` or the caller puts it where the
    fixture holds it; it starts at ``geometry.hole_position``, untilted).

    :param hand: the body that holds the shaft (the Panda's ``panda_hand_tcp``, the FR3's
        ``hand``).
    :param geometry: the cell's sizes and grasp point.
    :param config: the shaft's and the inner ring's masses, the fit's friction, the contact
        friction, the bore's segments, the imperfections' payload error and
        ``config.mujoco``'s contact settings.
    :param grasp_position: (3,) [m] the grasp point (the tool frame's origin) in ``hand``'s
        frame; ``None``: its origin. :param grasp_quat: (4,) (w, x, y, z) the tool frame's
        orientation in ``hand``'s frame (z along the shaft towards its tip); ``None``: the hand's.
    :param prefix: of every element's name.
    :returns: the names of what was added.
    """
    c = config
    install_contact_filter()      # the bore's far boxes never reach the narrow phase
    grasp_position = np.zeros(3) if grasp_position is None else np.asarray(grasp_position, float)
    grasp_quat = np.array([1.0, 0.0, 0.0, 0.0]) if grasp_quat is None else np.asarray(grasp_quat,
                                                                                       float)
    names = ShaftCell(shaft_body=prefix + "shaft", shaft_geom=prefix + "shaft",
                      housing_body=prefix + "housing", plunger_joint=prefix + "plunger",
                      payload_body=(prefix + "payload_error"
                                    if c.imperfections.payload_mass_error > 0.0 else None))
    contact = _contact(c)
    ixx, izz = shaft_inertia(geometry, c)
    shaft = hand.add_body(name=names.shaft_body, pos=grasp_position, quat=grasp_quat,
                          mass=c.shaft_mass, ipos=list(geometry.shaft_centre),
                          inertia=[ixx, ixx, izz], explicitinertial=True)
    shaft.add_geom(name=names.shaft_geom, type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                   size=[geometry.shaft_radius, geometry.shaft_length / 2, 0.0],
                   pos=list(geometry.shaft_centre), contype=CELL_CONTACT_BIT, conaffinity=0,
                   **contact)
    if names.payload_body is not None:
        # The real arm's unmodelled load: on the hand, never in the bridge's model.
        hand.add_body(name=names.payload_body, pos=grasp_position, quat=grasp_quat,
                      mass=c.imperfections.payload_mass_error,
                      ipos=list(c.imperfections.payload_com_error),
                      inertia=[PAYLOAD_INERTIA] * 3, explicitinertial=True)
    _add_housing(spec, geometry, c, names, prefix)
    return names


def _contact(config: ShaftSceneConfig) -> dict:
    """The contact settings of every geom of the cell (they collide only with each other, so
    these are their contacts' settings): sliding friction only (condim 3), as pybullet's
    contacts; no mass from the geoms (the bodies' inertials are explicit)."""
    m = config.mujoco
    return dict(condim=3, friction=[config.friction, 0.0, 0.0], solref=list(m.contact_solref),
                solimp=list(m.contact_solimp), margin=0.0, gap=0.0, density=0.0)


def _add_housing(spec: mujoco.MjSpec, g: ShaftTaskGeometry, c: ShaftSceneConfig,
                 names: ShaftCell, prefix: str) -> None:
    """The housing, a mocap body at the bearing face centre: the bore's and the counterbore's
    boxes (the bore's rim chamfered: each of its boxes a convex mesh), and the inner ring on its
    slide joint below the bore, its weight carried, held by the fit's friction up to its stop."""
    m, contact = c.mujoco, _contact(c)
    housing = spec.worldbody.add_body(name=names.housing_body, mocap=True,
                                      pos=list(g.hole_position))
    for i, box in enumerate(housing_boxes(g, c)):
        placed = dict(name=f"{prefix}housing_{i}", pos=list(box.centre),
                      quat=_quat_from_yaw(box.yaw), contype=0, conaffinity=CELL_CONTACT_BIT,
                      **contact)
        if m.rim_chamfer and i < c.bore_segments:
            spec.add_mesh(name=placed["name"],
                          uservert=_chamfered_box(box.size, m.rim_chamfer).ravel().tolist())
            housing.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=placed["name"], **placed)
        else:
            housing.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[s / 2 for s in box.size],
                             **placed)
    slab = plunger_box(g)
    plunger = housing.add_body(name=prefix + "plunger", pos=[0.0, 0.0, -g.bore_depth],
                               mass=c.plunger_mass, ipos=list(slab.centre),
                               inertia=[PLUNGER_INERTIA] * 3, explicitinertial=True,
                               gravcomp=1.0)         # its weight carried: only the fit holds it
    plunger.add_joint(name=names.plunger_joint, type=mujoco.mjtJoint.mjJNT_SLIDE,
                      axis=[0.0, 0.0, -1.0], range=[0.0, g.plunger_travel],
                      limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                      frictionloss=c.plunger_friction,
                      solref_friction=list(m.fit_solref), solimp_friction=list(m.fit_solimp),
                      solref_limit=list(m.contact_solref), solimp_limit=list(m.contact_solimp))
    plunger.add_geom(name=prefix + "plunger", type=mujoco.mjtGeom.mjGEOM_BOX,
                     size=[s / 2 for s in slab.size], pos=list(slab.centre), contype=0,
                     conaffinity=CELL_CONTACT_BIT, **contact)


def _chamfered_box(size: tuple[float, float, float], chamfer: float) -> np.ndarray:
    """(10, 3) the corners of a bore box (radial, tangential, axial ``size``, centred) whose
    edge at the bore's rim (inner face, top) is cut by a 45 degree ``chamfer``."""
    hx, hy, hz = (s / 2 for s in size)
    corners = [(x, y, z) for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)
               if not (x < 0 and z > 0)]
    corners += [(x, y, z) for y in (-hy, hy)
                for x, z in ((-hx, hz - chamfer), (-hx + chamfer, hz))]
    return np.array(corners)


def set_cell_physics(spec: mujoco.MjSpec, config: ShaftSceneConfig) -> None:
    """The model-wide options the cell's contacts were tuned with: the time step, gravity and
    ``config.mujoco``'s integrator, friction cone and solver."""
    m = config.mujoco
    spec.option.timestep = config.time_step
    spec.option.gravity = [0.0, 0.0, -config.gravity]
    spec.option.integrator = _INTEGRATORS[m.integrator]
    spec.option.cone = _CONES[m.cone]
    spec.option.impratio = m.impratio
    spec.option.iterations = m.iterations
    spec.option.noslip_iterations = m.noslip_iterations
    spec.option.ccd_tolerance = m.ccd_tolerance


def arm_spec(arm: ArmDescription) -> mujoco.MjSpec:
    """The arm as the scene simulates it (``shaft_urdfs.bare_arm_urdf``) through MuJoCo's URDF
    import: each link a body (fixed frames kept, so the flange is a body), the URDF's joint
    damping removed (as in pybullet: the bridge's model has none)."""
    root = bare_arm_urdf(arm).getroot()
    root.insert(0, ElementTree.fromstring(
        '<mujoco><compiler fusestatic="false" discardvisual="true"/></mujoco>'))
    spec = mujoco.MjSpec.from_string(ElementTree.tostring(root, encoding="unicode"))
    for joint in spec.joints:
        joint.damping = [0.0, 0.0, 0.0]
        joint.frictionloss = 0.0
        joint.armature = 0.0
    return spec


class MujocoShaftWorld:
    """The arm holding the shaft, and the housing, in a MuJoCo model and data of their own."""

    def __init__(self, arm: ArmDescription, geometry: ShaftTaskGeometry,
                 config: ShaftSceneConfig) -> None:
        self.geometry = geometry
        self.config = config
        spec = arm_spec(arm)
        set_cell_physics(spec, config)
        self.cell = add_shaft_cell(spec, spec.body(arm.tool_mount), geometry, config)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        joints = [m.joint(name).id for name in arm.joint_names]
        self._qpos = _index([int(m.jnt_qposadr[j]) for j in joints])
        self._dof = _index([int(m.jnt_dofadr[j]) for j in joints])
        plunger = m.joint(self.cell.plunger_joint).id
        self._plunger_qpos = int(m.jnt_qposadr[plunger])
        self._plunger_dof = int(m.jnt_dofadr[plunger])
        self._shaft = m.body(self.cell.shaft_body).id
        self._shaft_geom = m.geom(self.cell.shaft_geom).id
        self._mocap = int(m.body_mocapid[m.body(self.cell.housing_body).id])
        self._current = False             # kinematics of the current qpos computed
        # The compiled contact wrench sum's arguments, made once: it writes into ``_wrench``.
        self._wrench = np.zeros(6)
        self._wrench_sum = contact_wrench_sum()
        self._wrench_args = (ctypes.c_void_p(m._address), ctypes.c_void_p(self.data._address),
                             self._shaft_geom, self._shaft,
                             self._wrench.ctypes.data_as(ctypes.c_void_p))
        # Views of the arm's entries in the data (its buffers never move), where its joints'
        # entries run in order: read and written every step, ~0.5 us less a step than indexing
        # ``data`` each time. ``None``: indexed each time.
        d = self.data
        self._qpos_all = d.qpos
        ordered = isinstance(self._qpos, slice) and isinstance(self._dof, slice)
        self._q, self._dq, self._tau = ((d.qpos[self._qpos], d.qvel[self._dof],
                                         d.qfrc_applied[self._dof]) if ordered
                                        else (None, None, None))
        mujoco.mj_forward(m, self.data)
        self._current = True

    def _refresh(self) -> None:
        """Positions of every body at the current joint positions (``mj_step`` leaves those of
        the state before its integration)."""
        if not self._current:
            mujoco.mj_kinematics(self.model, self.data)
            self._current = True

    def _settle(self) -> None:
        """After a teleport: the solver's warm start forgotten (an episode depends only on its
        start) and the kinematics brought to the new state."""
        self.data.qacc_warmstart[:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        self._current = True

    # --- ShaftWorld ---------------------------------------------------------------------
    def set_arm_state(self, q: np.ndarray, dq: np.ndarray) -> None:
        self.data.qpos[self._qpos] = q
        self.data.qvel[self._dof] = dq
        self._settle()

    def arm_state(self) -> tuple[np.ndarray, np.ndarray]:
        if self._q is None:
            return self.data.qpos[self._qpos].copy(), self.data.qvel[self._dof].copy()
        return self._q.copy(), self._dq.copy()

    def set_arm_torques(self, tau: np.ndarray) -> None:
        if self._tau is None:
            self.data.qfrc_applied[self._dof] = tau
        else:
            self._tau[:] = tau

    def step(self) -> None:
        mujoco.mj_step(self.model, self.data)
        self._current = False

    def tool_pose(self) -> tuple[np.ndarray, np.ndarray]:
        self._refresh()
        d = self.data
        return d.xpos[self._shaft].copy(), d.xmat[self._shaft].reshape(3, 3).copy()

    def place_housing(self, fixture: Fixture) -> None:
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, np.asarray(fixture.rotation, float).ravel())
        self.data.mocap_pos[self._mocap] = fixture.position
        self.data.mocap_quat[self._mocap] = quat
        self._settle()

    def plunger_travel(self) -> float:
        return self._qpos_all.item(self._plunger_qpos)

    def set_plunger_travel(self, travel: float) -> None:
        self.data.qpos[self._plunger_qpos] = travel
        self.data.qvel[self._plunger_dof] = 0.0
        self._settle()

    def contact_wrench(self) -> np.ndarray:
        """The sum of the contact forces on the shaft of the last step, about the tool origin,
        tool frame: at rest what a wrist sensor between hand and shaft reads, the shaft's weight
        taken out. ``tests/robot/test_mujoco_world.py`` checks it against the arm's balance
        over a step (pybullet's summed contact points failed that check; its world reads the
        shaft joint's reaction instead). Summed in compiled code (``native/contact_wrench.c``):
        the ground truth and the ground-truth estimator read it, every 10th tick and every
        tick."""
        self._refresh()
        self._wrench_sum(*self._wrench_args)
        return self._wrench.copy()

    def close(self) -> None:
        """Nothing to release: the model and data are freed with the world."""


def build(arm: ArmDescription, geometry: ShaftTaskGeometry,
          config: ShaftSceneConfig) -> MujocoShaftWorld:
    """The shaft task's world in MuJoCo (``shaft_world.build_world`` calls it by name)."""
    return MujocoShaftWorld(arm, geometry, config)
