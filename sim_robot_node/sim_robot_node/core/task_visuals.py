"""The simulated tasks as viewers draw them (``qg_common.task_scene``): frames and parts from
the same parameters the simulation is built from.

Registered by robot name under the entry-point group ``robot_bridge_node.task_scenes``
(``setup.py``): the robot process publishes the scene of its robot on ``/tf_static`` and
``/scene_markers`` and records it in every bag; the episode renderer draws it.

The shaft task (``sim_panda``, ``sim_xarm7``): the ``shaft`` frame at the shaft's tip (z along
the shaft towards the tip, as the tool frame, which holds the shaft ``grasp_height`` above its
tip), the ``housing`` frame at the bearing face's centre (z out of the bore, turned by the
episode's housing yaw and the fixture's tilt), and the ``bore`` frame where the tip ends fully
inserted. Parts: the shaft, the bore's wall, the counterbore's wall and the bearing's inner ring
at its start (it travels ``plunger_travel`` down as the shaft presses it in). The nominal
housing pose is drawn: a realistic arm's housing error (``arm_imperfections``) is a few tenths
of a millimetre, invisible at a viewer's scale.

The Nextage peg (``sim_nextage``): the ``peg`` frame at the peg's tip (the peg hangs from the
tool, z down), the ``block`` frame at the workspace origin (hole axis, block base) and the
``hole`` frame at the hole's bottom; parts: the peg, the block's base and its walls around the
hole, and the table.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from qg_common.rotations import housing_rotation, quaternion_from_matrix
from qg_common.task_scene import (BASE, CUBE, CYLINDER, TOOL, TaskFrame, TaskPart, TaskScene,
                                  tube)

from sim_robot_node.core.nextage_scene import NextageSceneConfig
from sim_robot_node.core.shaft_scene import ShaftSceneConfig

__all__ = ["shaft_task_scene", "SIM_PANDA_SCENE", "SIM_XARM7_SCENE", "nextage_task_scene"]

STEEL = (0.62, 0.64, 0.68, 1.0)
HOUSING = (0.16, 0.27, 0.55, 1.0)
BEARING = (0.85, 0.65, 0.13, 1.0)
TABLE = (0.45, 0.42, 0.38, 1.0)


def shaft_task_scene(section: str) -> Callable[[dict[str, Any], float], TaskScene]:
    """The shaft task's scene of a robot whose parameters have the scene under ``section``
    (``panda_scene``, ``xarm_scene``; what is missing keeps ``ShaftSceneConfig``'s default)."""

    def scene(params: dict[str, Any], housing_yaw: float = 0.0) -> TaskScene:
        c = ShaftSceneConfig.from_dict(params.get(section, {}))
        housing = quaternion_from_matrix(housing_rotation(housing_yaw, c.housing_tilt))
        wall = c.hole_radius + c.counterbore_extra_radius + 0.003   # the housing URDF's rings
        side = 2 * c.hole_radius + 0.004                             # the plunger's box
        frames = (TaskFrame(TOOL, "shaft", (0.0, 0.0, c.grasp_height)),
                  TaskFrame(BASE, "housing", tuple(map(float, c.hole_position)), housing),
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

    return scene


#: ``sim_panda``'s and ``sim_xarm7``'s scenes (their plugins' parameter sections).
SIM_PANDA_SCENE = shaft_task_scene("panda_scene")
SIM_XARM7_SCENE = shaft_task_scene("xarm_scene")


def nextage_task_scene(params: dict[str, Any], housing_yaw: float = 0.0) -> TaskScene:
    """``sim_nextage``'s scene: the peg and the holed block (the block cannot turn: the yaw is
    the reset's argument, always 0 here)."""
    del housing_yaw
    config = NextageSceneConfig.from_dict(params.get("scene", {}))
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
