"""What the in-process environments show for ``render_mode``: ``qgl render``'s picture of the
robot, drawn from the robot in process.

``rgb_array``: ``render()`` returns the frame (the arm as its joints are now, the task's parts,
the bore up close, the step's numbers written on it), so ``gymnasium.wrappers.RecordVideo``,
SB3's ``VecVideoRecorder`` and RL Zoo's ``record_video`` record episodes unchanged. ``human``:
the same scene in pybullet's own window, which needs a display.

The renderer is the one ``qgl render`` uses (``qg_learning_node.episode_video``: entry-point
group ``qg_learning_node.renderers``), built from the robot's description and its task's scene
(the frames and parts the robot process publishes, from ``frame_kinematics``), so a video of an
environment and one of a bag look alike. Nothing here needs the ROS message definitions.
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from qg_learning_node.episode_video import renderer
from robot_bridge_node.core.frame_kinematics import FrameKinematics, task_scene
from robot_bridge_node.core.hardware_interface import robot_plugin

__all__ = ["RENDER_MODES", "RENDER_FPS", "RobotView", "RenderedRobot", "check_render_mode"]

RENDER_MODES = ["rgb_array", "human"]
#: One frame per RL step; a step takes 0.02-0.25 s of the robot's time.
RENDER_FPS = 10


def check_render_mode(render_mode: str | None) -> None:
    """:raises ValueError: for a mode the environments do not have, or ``human`` without a
    display."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be one of {RENDER_MODES} or None, "
                         f"got {render_mode!r}")
    if render_mode == "human" and not (os.environ.get("DISPLAY")
                                       or os.environ.get("WAYLAND_DISPLAY")):
        raise ValueError("render_mode='human' needs a display (DISPLAY is not set); "
                         "'rgb_array' renders offscreen")


class RobotView:
    """The renderer of robot plugin ``robot`` with its parameters ``params`` (its cell's among
    them: where the housing is)."""

    def __init__(self, robot: str, params: dict[str, Any], render_mode: str,
                 width: int = 448, height: int = 336) -> None:
        check_render_mode(render_mode)
        description = robot_plugin(robot).describe(params)
        frames = FrameKinematics(description)
        scene = task_scene(robot, params)
        static = [(t.parent, t.child, t.translation, t.rotation)
                  for t in frames.static_transforms(scene)]
        self.joint_names = description.joint_names
        self.mode = render_mode
        self._renderer = renderer().SceneRenderer(frames.urdf, static, scene.parts, width,
                                                  height, gui=render_mode == "human")

    def render(self, q: np.ndarray, lines: Sequence[str]) -> np.ndarray | None:
        """The frame of the arm at ``q`` (``rgb_array``), or None once the window shows it."""
        positions = dict(zip(self.joint_names, np.asarray(q, float).tolist()))
        if self.mode == "human":
            self._renderer.pose(positions)
            return None
        return self._renderer.frame(positions, lines)

    def close(self) -> None:
        self._renderer.close()


class RenderedRobot:
    """``render()`` of an environment whose robot a ``RobotView`` draws (a mixin before
    ``gymnasium.Env``): a subclass says which view (``_view``), where the joints are
    (``_joint_positions``) and what to write on the frame (``_render_lines``)."""

    render_mode: str | None = None
    _robot_view: RobotView | None = None

    def _view(self) -> RobotView:
        raise NotImplementedError(f"{type(self).__name__} has no render modes")

    def _joint_positions(self) -> np.ndarray:
        """The robot's joints now [rad], in the order of its description."""
        raise NotImplementedError(f"{type(self).__name__} has no render modes")

    def _render_lines(self) -> list[str]:
        return []

    def render(self) -> np.ndarray | None:
        """The robot as it is now (``rgb_array``: the frame; ``human``: in the window)."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() without a render_mode: make the environment with "
                                  "render_mode='rgb_array' or 'human'")
            return None
        if self._robot_view is None:
            self._robot_view = self._view()
        return self._robot_view.render(self._joint_positions(), self._render_lines())

    def _close_view(self) -> None:
        """Close the renderer's world, if one was opened."""
        if self._robot_view is not None:
            self._robot_view.close()
            self._robot_view = None
