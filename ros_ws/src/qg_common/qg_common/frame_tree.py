"""A tree of frames as tf2 keeps one: each frame's pose in its parent, any frame's pose in the
root by walking up the tree.

The robot process sends its frames as transforms (``/tf``, ``/tf_static``); whatever draws them
again (the episode renderer from a bag, a Gymnasium environment from its robot, a test comparing
a bag's tool with forward kinematics) puts them into a ``FrameTree`` and asks for a frame's
pose in the robot's base.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from qg_common.rotations import matrix_from_quaternion

__all__ = ["FrameTree", "homogeneous"]


def homogeneous(translation: Sequence[float], quaternion_xyzw: Sequence[float]) -> np.ndarray:
    """The 4x4 transform of a translation and a unit quaternion ``(x, y, z, w)``."""
    pose = np.eye(4)
    pose[:3, :3] = matrix_from_quaternion(*map(float, quaternion_xyzw))
    pose[:3, 3] = np.asarray(translation, float)
    return pose


class FrameTree:
    """Frames by name, each with its parent and its pose there (a later ``set`` of a frame
    replaces the earlier one, as a newer transform does in tf2)."""

    def __init__(self) -> None:
        self._parents: dict[str, tuple[str, np.ndarray]] = {}

    def set(self, parent: str, child: str, translation: Sequence[float],
            quaternion_xyzw: Sequence[float]) -> None:
        """``child``'s pose in ``parent``."""
        self._parents[child] = (parent, homogeneous(translation, quaternion_xyzw))

    def __contains__(self, frame: str) -> bool:
        return frame in self._parents

    def parent_of(self, frame: str) -> str:
        """The frame ``frame`` hangs from.

        :raises KeyError: for a frame without a parent (a root, or an unknown frame).
        """
        return self._parents[frame][0]

    def root_of(self, frame: str) -> str:
        """The frame at the top of ``frame``'s chain (itself if it has no parent)."""
        seen = {frame}
        while frame in self._parents:
            frame = self._parents[frame][0]
            if frame in seen:
                raise ValueError(f"the frames form a loop through {frame!r}")
            seen.add(frame)
        return frame

    def pose(self, frame: str) -> np.ndarray:
        """``frame``'s 4x4 pose in the root of its chain (the identity for the root itself)."""
        pose = np.eye(4)
        seen = {frame}
        while frame in self._parents:
            parent, local = self._parents[frame]
            pose = local @ pose
            if parent in seen:
                raise ValueError(f"the frames form a loop through {parent!r}")
            seen.add(parent)
            frame = parent
        return pose
