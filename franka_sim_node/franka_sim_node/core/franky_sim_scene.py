"""Scene extensions for franky-sim's MuJoCo world (``franky_sim_host.SceneExtension``).

Each function returns an extension that adds MJCF elements before the scene is compiled.

``shaft_scene`` is the shaft task's cell, the one the simulated Panda learns in: the shaft held
rigidly in the hand at the grasp point (as a closed gripper holds it), the housing with its bore,
counterbore and the bearing's inner ring, all from ``sim_robot_node``'s MuJoCo description of the
cell (``mujoco_world.add_shaft_cell``: one description of the cell for every MuJoCo arm) with the
geometry of ``config/shaft_task.yaml`` and the physics of ``config/panda_scene.yaml``. The
housing stands where the task's fixture says (``shaft_task.hole_position``, ``housing_yaw``,
``housing_tilt``): the pose a real cell measures and the executor's targets assume.

``demo_scene`` proves the mechanism with a block and a held cylinder (contacts: the held part
collides only with the fixtures, ``contype``/``conaffinity`` bit 2, not with the fingers it sits
between; fixtures collide with the arm, bit 1, too).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np
from franka_robot_node.core.fr3_description import FR3_READY
from franka_robot_node.core.franka_config import HeldTool
from franky_sim.mujoco_simulator import MujocoSimulator
from qg_common.shaft_task import SHAFT_TASK_SECTION, TOOL_DOWN, ShaftTaskGeometry
from robot_bridge_node.core.arm_model import ArmModel
from sim_robot_node.core.arm_imperfections import RESIDUAL_FRICTION_SHARE
from sim_robot_node.core.mujoco_world import add_shaft_cell, set_cell_physics
from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig

from franka_sim_node.core.franky_sim_host import HAND_BODY, TCP_IN_HAND, SceneExtension

__all__ = ["fixture_box", "held_cylinder", "residual_joint_friction", "shaft_cell",
           "shaft_scene", "parked_q", "demo_scene", "HELD_BODY", "FIXTURE_BODY", "CELL_PREFIX",
           "SCENE_CONFIG_FILES", "PARK_HEIGHT"]

#: Names of the demo's bodies in the MJCF.
HELD_BODY = "held_part"
FIXTURE_BODY = "fixture"
#: The prefix of the shaft cell's elements in the MJCF.
CELL_PREFIX = "shaft_cell/"
#: [m] How far above the bearing face the shaft's tip is when franky-sim starts.
PARK_HEIGHT = 0.05
#: The config files a scene's parameters come from (``(package, file)``, later ones win):
#: the held part's, the cell's geometry and the cell's physics. The section of the physics is
#: ``panda_scene``: the cell's, whichever arm holds the shaft.
SCENE_CONFIG_FILES = (("franka_robot_node", "franka.yaml"), ("qg_common", "shaft_task.yaml"),
                      ("sim_robot_node", "panda_scene.yaml"))


def _vector(values: Sequence[float]) -> str:
    return " ".join(f"{v:.6g}" for v in values)


def fixture_box(center: Sequence[float], half_size: Sequence[float],
                name: str = FIXTURE_BODY) -> SceneExtension:
    """A static box (welded to the world) centred at ``center`` [m], base frame."""
    def extend(sim: MujocoSimulator) -> None:
        body = ET.SubElement(sim.worldbody, "body", name=name, pos=_vector(center))
        ET.SubElement(body, "geom", name=f"{name}_geom", type="box", size=_vector(half_size),
                      contype="3", conaffinity="3", rgba="0.55 0.55 0.6 1")
    return extend


def held_cylinder(tool: HeldTool, radius: float, length: float,
                  name: str = HELD_BODY) -> SceneExtension:
    """A cylinder fixed in the hand along the tool axis, its centre of mass where ``tool``
    says (``offset + com`` from the tool centre point), ``tool.mass`` heavy.

    :raises ValueError: if the scene has no hand to hold it.
    """
    center = TCP_IN_HAND + [a + b for a, b in zip(tool.offset, tool.com)]

    def extend(sim: MujocoSimulator) -> None:
        hand = sim.worldbody.find(f".//body[@name='{HAND_BODY}']")
        if hand is None:
            raise ValueError(f"no body {HAND_BODY!r} in the scene: add the robot first")
        body = ET.SubElement(hand, "body", name=name, pos=_vector(center))
        ET.SubElement(body, "inertial", pos="0 0 0", mass=f"{tool.mass:.6g}",
                      diaginertia=_vector([1e-5, 1e-5, 1e-5]))
        ET.SubElement(body, "geom", name=f"{name}_geom", type="cylinder",
                      size=_vector([radius, length / 2]), contype="2", conaffinity="2",
                      mass="0", rgba="0.8 0.6 0.2 1")
    return extend


def residual_joint_friction(share: float) -> SceneExtension:
    """The arm's joint friction scaled to ``share`` of franky-sim's (0.25-1.14 Nm a joint): what
    a real Franka's own friction compensation leaves of it. libfranka's torque commands are
    joint torques without gravity and friction, which the robot adds itself; franky-sim adds
    gravity but simulates the raw friction, against which the bridge's holding stiffness of
    10 Nm/rad leaves the wrist up to 6 deg from where it should be. The simulated Panda takes
    the same share of its identified friction (``arm_imperfections.RESIDUAL_FRICTION_SHARE``).

    :raises ValueError: unless ``0 <= share <= 1``.
    """
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"the residual friction share must be in [0, 1], got {share}")

    def extend(sim: MujocoSimulator) -> None:
        # every <joint> of the scene: the arm's own and its class defaults' (joints 1-4)
        for joint in sim.scene.iter("joint"):
            if joint.get("frictionloss") is not None:
                joint.set("frictionloss", f"{share * float(joint.get('frictionloss')):.6g}")
    return extend


def shaft_cell(geometry: ShaftTaskGeometry, config: ShaftSceneConfig,
               tool: HeldTool) -> SceneExtension:
    """The shaft task's cell (``mujoco_world.add_shaft_cell``): the shaft in the hand with its
    grasp point at the tool frame (the hand's tool centre point plus ``tool.offset``), the
    housing at ``geometry.fixture()``, and the options the cell's contacts were tuned with
    (``set_cell_physics``: the time step and gravity are franky-sim's 1 ms and 9.81 too).

    The cell is described on a ``mujoco.MjSpec`` of the scene so far and written back into the
    scene's tree in place: apply it after every extension that edits ``sim.worldbody``
    (afterwards that element is no longer the scene's).

    :raises ValueError: if the scene has no hand to hold the shaft.
    """
    def extend(sim: MujocoSimulator) -> None:
        spec = mujoco.MjSpec.from_string(ET.tostring(sim.scene, encoding="unicode"))
        hand = spec.body(HAND_BODY)
        if hand is None:
            raise ValueError(f"no body {HAND_BODY!r} in the scene: add the robot first")
        set_cell_physics(spec, config)
        cell = add_shaft_cell(spec, hand, geometry, config,
                              grasp_position=TCP_IN_HAND + np.asarray(tool.offset, float),
                              prefix=CELL_PREFIX)
        fixture = geometry.fixture()
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, np.asarray(fixture.rotation, float).ravel())
        housing = spec.body(cell.housing_body)
        housing.pos, housing.quat = fixture.position.tolist(), quat.tolist()
        written = ET.fromstring(spec.to_xml())
        sim.scene.clear()
        sim.scene.attrib.update(written.attrib)
        sim.scene.extend(list(written))
    return extend


def shaft_scene(tool: HeldTool, params: dict[str, Any]) -> list[SceneExtension]:
    """The shaft task's cell in franky-sim (``SCENE_CONFIG_FILES``' sections ``shaft_task`` and
    ``panda_scene``), the arm's friction what a real Franka leaves of it."""
    geometry = ShaftTaskGeometry.from_dict(params.get(SHAFT_TASK_SECTION.prefix, {}))
    config = ShaftSceneConfig.from_dict(params.get("panda_scene", {}))
    return [residual_joint_friction(RESIDUAL_FRICTION_SHARE), shaft_cell(geometry, config, tool)]


def parked_q(model: ArmModel, geometry: ShaftTaskGeometry) -> np.ndarray:
    """(7,) The FR3's joints with the shaft upright on the bore's axis, its tip ``PARK_HEIGHT``
    above the bearing face: where franky-sim starts the arm, clear of the housing (at the
    ready pose the tip would rest on the bearing face), the posture nearest the ready pose.

    :param model: the bridge's model of the arm holding the shaft (its tool frame the grasp
        point).
    """
    fixture = geometry.fixture()
    rotation = fixture.rotation @ TOOL_DOWN
    tip_above = fixture.position + fixture.rotation @ np.array([0.0, 0.0, PARK_HEIGHT])
    return model.inverse_kinematics(tip_above - rotation @ np.array([0.0, 0.0,
                                                                      geometry.grasp_height]),
                                    rotation, np.array(FR3_READY))


def demo_scene(tool: HeldTool, params: dict[str, Any] | None = None) -> list[SceneExtension]:
    """The extension mechanism's proof: a 10 x 10 x 20 cm block on the floor 0.45 m in front of
    the arm (its top 5 cm below the held part's tip at the ready pose, 10 cm where
    ``parked_q`` starts the arm) and the shaft-sized cylinder in the hand (0.1 m long, 5.9 mm
    radius, gripped 6 cm above its tip, exactly the load the plugin declares: no unknown
    payload), the arm's friction what a real Franka leaves of it. ``params`` are unused."""
    return [residual_joint_friction(RESIDUAL_FRICTION_SHARE),
            fixture_box(center=(0.45, 0.0, 0.1), half_size=(0.05, 0.05, 0.1)),
            held_cylinder(tool, radius=0.0059, length=0.1)]
