"""The shaft scene's bodies as an engine reads them: the bare arm, the shaft and the housing.

``bare_arm_urdf`` takes an arm's own URDF as its package ships it and makes the simulated arm of
the scene: joints other than the driven ones fixed (a gripper's fingers), no meshes (only the
shaft collides), links without inertia massless (as Pinocchio reads them), the URDF's joint
friction left to the scene's imperfections. ``arm_with_shaft_urdf`` welds the shaft (plus, on
the realistic arm, the payload the bridge's model does not know) to its flange as fixed links,
for pybullet: a fixed joint in the multibody is exact, unlike a soft pybullet constraint.
``housing_urdf`` is the arm-independent fixture: the bore, the counterbore and the plunger.
The shapes themselves (``shaft_inertia``, ``housing_boxes``, ``plunger_box``) are the one
description every engine builds its bodies from (``mujoco_world`` too).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any
from xml.etree import ElementTree

from qg_common.arm_description import ArmDescription
from qg_common.shaft_task import ShaftTaskGeometry

from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig

__all__ = ["bare_arm_urdf", "arm_with_shaft_urdf", "housing_urdf", "SHAFT_JOINT", "Box",
           "shaft_inertia", "housing_boxes", "plunger_box"]

#: The fixed joint (and link index) of the shaft in the arm's multibody.
SHAFT_JOINT = "shaft_joint"

#: The inertial of a massless link.
_MASSLESS = ('<inertial><mass value="0"/>'
             '<inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial>')

#: [kg m^2] the payload error's inertia about each axis (a small lump).
PAYLOAD_INERTIA = 1e-5
#: [m] the inner ring's slab; [kg m^2] its inertia about each axis (it only slides).
PLUNGER_THICKNESS = 0.01
PLUNGER_INERTIA = 1e-4

#: URDF joint types that move: everything else is fixed already.
_MOVABLE = ("revolute", "continuous", "prismatic", "floating", "planar")


def _fmt(values: Any) -> str:
    return " ".join(f"{float(v):.9f}" for v in values)


def bare_arm_urdf(arm: ArmDescription) -> ElementTree.ElementTree:
    """The arm's URDF as the scene simulates it, without the shaft: the driven joints only
    (others fixed), no meshes, every link with an inertial, no joint friction."""
    tree = ElementTree.parse(arm.urdf)
    root = tree.getroot()
    for link in root.findall("link"):
        for element in link.findall("collision") + link.findall("visual"):
            link.remove(element)
        if link.find("inertial") is None:
            # A link without one is a massless frame (as Pinocchio reads it); pybullet would
            # give it 1 kg (the xArm's link_eef).
            link.append(ElementTree.fromstring(_MASSLESS))
    for joint in root.findall("joint"):
        if joint.get("type") in _MOVABLE and joint.get("name") not in arm.joint_names:
            joint.set("type", "fixed")       # e.g. the fingers: locked at 0 as in the model
        for dynamics in joint.findall("dynamics"):
            if float(dynamics.get("friction", "0") or 0.0) != 0.0:
                # The friction that reaches the links is the scene's (ArmImperfections).
                dynamics.set("friction", "0")
    return tree


def shaft_inertia(geometry: ShaftTaskGeometry, scene: ShaftSceneConfig) -> tuple[float, float]:
    """(ixx = iyy, izz) [kg m^2] of the shaft, a solid cylinder, about its centre of mass."""
    g, mass = geometry, scene.shaft_mass
    return (mass * (3 * g.shaft_radius ** 2 + g.shaft_length ** 2) / 12,
            mass * g.shaft_radius ** 2 / 2)


def arm_with_shaft_urdf(arm: ArmDescription, geometry: ShaftTaskGeometry,
                        scene: ShaftSceneConfig) -> ElementTree.ElementTree:
    """The arm's URDF (``bare_arm_urdf``) with the shaft at its flange (the grasp point), ready
    for pybullet.

    :param geometry: the shaft's size and grasp point.
    :param scene: the shaft's mass; its imperfections' ``payload_*_error`` adds a link the
        bridge's model does not have.
    """
    tree = bare_arm_urdf(arm)
    root = tree.getroot()
    g, c, imperfections = geometry, scene, scene.imperfections
    com_z = g.shaft_centre[2]
    ixx, izz = shaft_inertia(g, c)
    links = f"""
  <link name="shaft">
    <inertial><origin xyz="0 0 {com_z:.9f}"/><mass value="{c.shaft_mass:.9f}"/>
      <inertia ixx="{ixx:.9f}" iyy="{ixx:.9f}" izz="{izz:.9f}" ixy="0" ixz="0" iyz="0"/>
    </inertial>
    <collision><origin xyz="0 0 {com_z:.9f}"/>
      <geometry><cylinder radius="{g.shaft_radius:.9f}" length="{g.shaft_length:.9f}"/></geometry>
    </collision>
  </link>
  <joint name="{SHAFT_JOINT}" type="fixed"><parent link="{arm.tool_mount}"/><child link="shaft"/>
    </joint>"""
    if imperfections.payload_mass_error > 0.0:
        # The real arm's unmodelled load: on the hand, never in the bridge's model.
        links += f"""
  <link name="payload_error">
    <inertial><origin xyz="{_fmt(imperfections.payload_com_error)}"/>
      <mass value="{imperfections.payload_mass_error:.9f}"/>
      <inertia ixx="{PAYLOAD_INERTIA:g}" iyy="{PAYLOAD_INERTIA:g}" izz="{PAYLOAD_INERTIA:g}" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="payload_error_joint" type="fixed"><parent link="{arm.tool_mount}"/>
    <child link="payload_error"/></joint>"""
    for element in ElementTree.fromstring(f"<r>{links}</r>"):
        root.append(element)
    return tree


@dataclass(frozen=True)
class Box:
    """A box of the housing, in the housing frame (origin: the bearing face centre).

    :param centre: (3,) [m]; :param yaw: [rad] its turn about the bore axis;
    :param size: (3,) [m] full edge lengths (radial, tangential, axial for a ring's box).
    """
    centre: tuple[float, float, float]
    yaw: float
    size: tuple[float, float, float]


def housing_boxes(g: ShaftTaskGeometry, c: ShaftSceneConfig) -> list[Box]:
    """The fixed part of the housing: the bore (a ring of ``bore_segments`` boxes, reaching
    under the counterbore's wall) and the counterbore's wall above the bearing face."""
    boxes: list[Box] = []

    def ring(radius: float, thickness: float, z_low: float, height: float, n: int) -> None:
        width = 2.0 * radius * math.tan(math.pi / n) * 1.05  # slight overlap: no gaps
        for i in range(n):
            a = 2.0 * math.pi * i / n
            r = radius + thickness / 2
            boxes.append(Box((r * math.cos(a), r * math.sin(a), z_low + height / 2), a,
                             (thickness, width, height)))

    bore_thickness = g.counterbore_extra_radius + 0.002  # reaches under the counterbore wall
    ring(g.hole_radius, bore_thickness, -g.bore_depth, g.bore_depth, c.bore_segments)
    ring(g.hole_radius + g.counterbore_extra_radius, 0.003, 0.0, g.counterbore_depth,
         c.counterbore_segments)
    return boxes


def plunger_box(g: ShaftTaskGeometry) -> Box:
    """The bearing's inner ring, in the frame of its joint (at the bore's bottom, the travel
    along -z): a slab under the whole bore whose top face the shaft's tip pushes."""
    return Box((0.0, 0.0, -PLUNGER_THICKNESS / 2), 0.0,
               (2 * g.hole_radius + 0.004, 2 * g.hole_radius + 0.004, PLUNGER_THICKNESS))


def housing_urdf(g: ShaftTaskGeometry, c: ShaftSceneConfig) -> str:
    """Housing: bore (ring of boxes), counterbore above it, plunger on a prismatic joint below.

    Origin at the bearing face centre; the plunger joint axis points down, so its position is
    the travel already pushed. :param g: the sizes; :param c: masses and the rings' segments.
    """
    boxes = [f'<collision><origin xyz="{_fmt(b.centre)}" rpy="0 0 {b.yaw:.9f}"/>'
             f'<geometry><box size="{_fmt(b.size)}"/></geometry></collision>'
             for b in housing_boxes(g, c)]
    plunger = plunger_box(g)
    # One element per line: pybullet's URDF parser fails on very long lines.
    return f"""<?xml version="1.0"?>
<robot name="housing">
  <link name="housing">
    <inertial><mass value="0"/><inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial>
    {chr(10).join(boxes)}
  </link>
  <link name="plunger">
    <inertial><origin xyz="{_fmt(plunger.centre)}"/><mass value="{c.plunger_mass:.9f}"/>
      <inertia ixx="{PLUNGER_INERTIA:g}" iyy="{PLUNGER_INERTIA:g}" izz="{PLUNGER_INERTIA:g}" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="{_fmt(plunger.centre)}"/>
      <geometry><box size="{_fmt(plunger.size)}"/></geometry></collision>
  </link>
  <joint name="plunger_joint" type="prismatic">
    <parent link="housing"/><child link="plunger"/>
    <origin xyz="0 0 {-g.bore_depth:.9f}"/><axis xyz="0 0 -1"/>
    <limit lower="0" upper="{g.plunger_travel:.9f}" effort="1000" velocity="1"/>
  </joint>
</robot>"""
