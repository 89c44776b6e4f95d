"""Scene extensions for franky-sim's MuJoCo world (``franky_sim_host.SceneExtension``).

Each function returns an extension that adds MJCF elements before the scene is compiled. The
demo scene proves the mechanism with what the shaft task needs in kind: a fixture standing on
the floor in front of the arm, and a cylinder held rigidly in the hand (a child body of the hand,
as a closed gripper holds a part) with the mass and centre of mass the plugin's ``tool``
parameters give, so the simulated load is the one the bridge's model and libfranka's
``setLoad`` know. The shaft task's housing, bore and plunger will be one more extension, from
the same YAML as the pybullet scene.

Contacts: the held part collides only with the fixtures (``contype``/``conaffinity`` bit 2), not
with the fingers it sits between; fixtures collide with the arm (bit 1) too.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence

from franky_sim.mujoco_simulator import MujocoSimulator

from franka_robot_node.core.franka_config import HeldTool

#: The share of a joint's friction a Franka's own compensation leaves (the simulated Panda's
#: ``sim_robot_node.core.arm_imperfections.RESIDUAL_FRICTION_SHARE``, from the same reasoning).
RESIDUAL_FRICTION_SHARE = 0.2
from franka_robot_node.core.franky_sim_host import HAND_BODY, TCP_IN_HAND, SceneExtension

__all__ = ["fixture_box", "held_cylinder", "residual_joint_friction", "demo_scene", "HELD_BODY",
           "FIXTURE_BODY"]

#: Names of the demo's bodies in the MJCF.
HELD_BODY = "held_part"
FIXTURE_BODY = "fixture"


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


def demo_scene(tool: HeldTool) -> list[SceneExtension]:
    """The extension mechanism's proof: a 10 x 10 x 20 cm block on the floor 0.45 m in front of
    the arm (its top 5 cm below the held part's tip at the ready pose) and the shaft-sized
    cylinder in the hand (0.1 m long, 5.9 mm radius, gripped 6 cm above its tip), the arm's
    friction what a real Franka leaves of it."""
    return [residual_joint_friction(RESIDUAL_FRICTION_SHARE),
            fixture_box(center=(0.45, 0.0, 0.1), half_size=(0.05, 0.05, 0.1)),
            held_cylinder(tool, radius=0.0059, length=0.1)]
