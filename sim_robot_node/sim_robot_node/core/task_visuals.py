"""The simulated tasks as viewers draw them (``qg_common.task_scene``): frames and parts from
the same parameters the simulation is built from.

Registered by robot name under the entry-point group ``robot_bridge_node.task_scenes``
(``setup.py``): the robot process publishes the scene of its robot on ``/tf_static`` and
``/scene_markers`` and records it in every bag; the episode renderer draws it.

The shaft task (``sim_panda`` on either engine, ``sim_xarm7``, ``franka``): the ``shaft`` frame
at the shaft's tip (z along the shaft towards the tip, as the tool frame, which holds the shaft
``grasp_height`` above its tip), the ``housing`` frame at the bearing face's centre (z out of
the bore, turned by the cell's housing yaw and fixture tilt), and the ``bore`` frame where the
tip ends fully inserted: the cell's ``shaft_task`` parameters (``qg_common.shaft_task``). Parts: the shaft, the bore's wall, the counterbore's wall and the bearing's inner ring
at its start (it travels ``plunger_travel`` down as the shaft presses it in). The nominal
housing pose is drawn: a realistic arm's housing error (``arm_imperfections``) is a few tenths
of a millimetre, invisible at a viewer's scale.

The Nextage peg (``sim_nextage``): the ``peg`` frame at the peg's tip (the peg hangs from the
tool, z down), the ``block`` frame at the workspace origin (hole axis, block base) and the
``hole`` frame at the hole's bottom; parts: the peg, the block's base and its walls around the
hole, and the table: the cell's ``peg_task`` parameters (``qg_common.peg_task``).
"""
from __future__ import annotations

from typing import Any

from qg_common.peg_task import PEG_TASK_SECTION, PegCell
from qg_common.rotations import quaternion_from_matrix
from qg_common.shaft_task import SHAFT_TASK_SECTION, ShaftTaskGeometry
from qg_common.task_scene import BASE, CUBE, CYLINDER, TOOL, TaskFrame, TaskPart, TaskScene, tube

__all__ = ["shaft_task_scene", "nextage_task_scene"]

STEEL = (0.62, 0.64, 0.68, 1.0)
HOUSING = (0.16, 0.27, 0.55, 1.0)
BEARING = (0.85, 0.65, 0.13, 1.0)
TABLE = (0.45, 0.42, 0.38, 1.0)


def shaft_task_scene(params: dict[str, Any]) -> TaskScene:
    """The shaft task's scene of a robot whose parameters hold the cell (``shaft_task``; what
    is missing keeps ``ShaftTaskGeometry``'s default)."""
    c = ShaftTaskGeometry.from_dict(params.get(SHAFT_TASK_SECTION.prefix, {}))
    fixture = c.fixture()
    wall = c.hole_radius + c.counterbore_extra_radius + 0.003   # the housing URDF's rings
    side = 2 * c.hole_radius + 0.004                             # the plunger's box
    frames = (TaskFrame(TOOL, "shaft", (0.0, 0.0, c.grasp_height)),
              TaskFrame(BASE, "housing", tuple(map(float, fixture.position)),
                        quaternion_from_matrix(fixture.rotation)),
              TaskFrame("housing", "bore", (0.0, 0.0, -c.full_depth)))
    parts = (TaskPart("shaft", "shaft", CYLINDER,
                      (2 * c.shaft_radius, 2 * c.shaft_radius, c.shaft_length), STEEL,
                      position=(0.0, 0.0, -c.shaft_length / 2)),
             tube("bore", "housing", c.hole_radius, wall, -c.bore_depth, 0.0, HOUSING),
             tube("counterbore", "housing", c.hole_radius + c.counterbore_extra_radius,
                  wall, 0.0, c.counterbore_depth, HOUSING),
             TaskPart("bearing", "housing", CUBE, (side, side, 0.01), BEARING,
                      position=(0.0, 0.0, -c.bore_depth - 0.005)))
    return TaskScene(frames, parts)


def nextage_task_scene(params: dict[str, Any]) -> TaskScene:
    """``sim_nextage``'s scene: the peg and the holed block of its cell (``peg_task``)."""
    config = PegCell.from_dict(params.get(PEG_TASK_SECTION.prefix, {}))
    g = config.geometry
    bottom = g.block_height - g.hole_depth
    frames = (TaskFrame(TOOL, "peg", (0.0, 0.0, g.peg_length)),
              TaskFrame(BASE, "block", tuple(map(float, config.workspace_origin))),
              TaskFrame("block", "hole", (0.0, 0.0, bottom)))
    parts = (TaskPart("peg", "peg", CYLINDER, (2 * g.peg_radius, 2 * g.peg_radius, g.peg_length),
                      STEEL, position=(0.0, 0.0, -g.peg_length / 2)),
             TaskPart("block_base", "block", CUBE, (g.block_width, g.block_width, bottom),
                      HOUSING, position=(0.0, 0.0, bottom / 2)),
             tube("block_wall", "block", g.hole_radius, g.block_width / 2, bottom,
                  g.block_height, HOUSING, segments=max(16, g.ring_segments)),
             TaskPart("table", "block", CUBE, (0.4, 0.4, 0.02), TABLE,
                      position=(0.0, 0.0, -0.01)))
    return TaskScene(frames, parts)
