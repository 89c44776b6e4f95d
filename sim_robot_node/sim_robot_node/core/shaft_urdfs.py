"""The two URDFs of the shaft scene: any torque arm holding the shaft, and the housing.

``arm_with_shaft_urdf`` takes an arm's own URDF as its package ships it and makes the simulated
arm of the scene: joints other than the driven ones fixed (a gripper's fingers), no meshes (only
the shaft collides), links without inertia massless (as Pinocchio reads them), the URDF's joint
friction left to the scene's imperfections, and the shaft
(plus, on the realistic arm, the payload the bridge's model does not know) welded to the flange
as fixed links: a fixed joint in the multibody is exact, unlike a soft pybullet constraint.
``housing_urdf`` is the arm-independent fixture: the bore, the counterbore and the plunger.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any
from xml.etree import ElementTree

from qg_common.arm_description import ArmDescription

from qg_common.shaft_task import ShaftTaskGeometry

if TYPE_CHECKING:                      # (shaft_scene imports this module's users)
    from sim_robot_node.core.shaft_scene import ShaftSceneConfig

__all__ = ["arm_with_shaft_urdf", "housing_urdf", "SHAFT_JOINT"]

#: The fixed joint (and link index) of the shaft in the arm's multibody.
SHAFT_JOINT = "shaft_joint"

#: The inertial of a massless link.
_MASSLESS = ('<inertial><mass value="0"/>'
             '<inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial>')

#: URDF joint types that move: everything else is fixed already.
_MOVABLE = ("revolute", "continuous", "prismatic", "floating", "planar")


def _fmt(values: Any) -> str:
    return " ".join(f"{float(v):.9f}" for v in values)


def arm_with_shaft_urdf(arm: ArmDescription, geometry: ShaftTaskGeometry,
                        scene: ShaftSceneConfig) -> ElementTree.ElementTree:
    """The arm's URDF with the shaft at its flange (the grasp point), ready for pybullet.

    :param geometry: the shaft's size and grasp point.
    :param scene: the shaft's mass; its imperfections' ``payload_*_error`` adds a link the
        bridge's model does not have.
    """
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
    g, c, imperfections = geometry, scene, scene.imperfections
    com_z = g.shaft_centre[2]
    ixx = c.shaft_mass * (3 * g.shaft_radius ** 2 + g.shaft_length ** 2) / 12
    izz = c.shaft_mass * g.shaft_radius ** 2 / 2
    links = f"""
  <link name="shaft">
    <inertial><origin xyz="0 0 {com_z:.9f}"/><mass value="{c.shaft_mass:.9f}"/>
      <inertia ixx="{ixx:.9f}" iyy="{ixx:.9f}" izz="{izz:.9f}" ixy="0" ixz="0" iyz="0"/>
    </inertial>
    <collision><origin xyz="0 0 {com_z:.9f}"/>
      <geometry><cylinder radius="{g.shaft_radius:.9f}" length="{g.shaft_length:.9f}"/></geometry>
    </collision>
  </link>
  <joint name="{SHAFT_JOINT}" type="fixed"><parent link="{arm.flange}"/><child link="shaft"/>
    </joint>"""
    if imperfections.payload_mass_error > 0.0:
        # The real arm's unmodelled load: on the hand, never in the bridge's model.
        links += f"""
  <link name="payload_error">
    <inertial><origin xyz="{_fmt(imperfections.payload_com_error)}"/>
      <mass value="{imperfections.payload_mass_error:.9f}"/>
      <inertia ixx="1e-5" iyy="1e-5" izz="1e-5" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="payload_error_joint" type="fixed"><parent link="{arm.flange}"/>
    <child link="payload_error"/></joint>"""
    for element in ElementTree.fromstring(f"<r>{links}</r>"):
        root.append(element)
    return tree


def housing_urdf(g: ShaftTaskGeometry, c: ShaftSceneConfig) -> str:
    """Housing: bore (ring of boxes), counterbore above it, plunger on a prismatic joint below.

    Origin at the bearing face centre; the plunger joint axis points down, so its position is
    the travel already pushed. :param g: the sizes; :param c: masses and the rings' segments.
    """
    boxes: list[str] = []

    def ring(radius: float, thickness: float, z_low: float, height: float, n: int) -> None:
        width = 2.0 * radius * math.tan(math.pi / n) * 1.05  # slight overlap: no gaps
        for i in range(n):
            a = 2.0 * math.pi * i / n
            r = radius + thickness / 2
            centre = _fmt([r * math.cos(a), r * math.sin(a), z_low + height / 2])
            size = _fmt([thickness, width, height])
            boxes.append(f'<collision><origin xyz="{centre}" rpy="0 0 {a:.9f}"/>'
                         f'<geometry><box size="{size}"/></geometry></collision>')

    bore_thickness = g.counterbore_extra_radius + 0.002  # reaches under the counterbore wall
    ring(g.hole_radius, bore_thickness, -g.bore_depth, g.bore_depth, c.bore_segments)
    ring(g.hole_radius + g.counterbore_extra_radius, 0.003, 0.0, g.counterbore_depth,
         c.counterbore_segments)
    plunger = _fmt([2 * g.hole_radius + 0.004, 2 * g.hole_radius + 0.004, 0.01])
    # One element per line: pybullet's URDF parser fails on very long lines.
    return f"""<?xml version="1.0"?>
<robot name="housing">
  <link name="housing">
    <inertial><mass value="0"/><inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial>
    {chr(10).join(boxes)}
  </link>
  <link name="plunger">
    <inertial><origin xyz="0 0 -0.005"/><mass value="{c.plunger_mass:.9f}"/>
      <inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 -0.005"/>
      <geometry><box size="{plunger}"/></geometry></collision>
  </link>
  <joint name="plunger_joint" type="prismatic">
    <parent link="housing"/><child link="plunger"/>
    <origin xyz="0 0 {-g.bore_depth:.9f}"/><axis xyz="0 0 -1"/>
    <limit lower="0" upper="{g.plunger_travel:.9f}" effort="1000" velocity="1"/>
  </joint>
</robot>"""
