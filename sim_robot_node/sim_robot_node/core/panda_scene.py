"""The simulated Panda pressing the shaft into the bearing: the shaft scene with the Panda.

All that is the Panda's is its description (``qg_common.panda_description``: the
example-robot-data URDF, its seven joints with the fingers locked, the flange ``panda_hand_tcp``
and the ready pose) and its numbers in ``config/panda_scene.yaml`` (the task, and the realistic
Panda's imperfections); the scene is ``shaft_scene.ShaftScene``.
"""
from __future__ import annotations

from qg_common.panda_description import panda_arm

from sim_robot_node.core.shaft_scene import ShaftScene, ShaftSceneConfig

__all__ = ["PandaSceneConfig", "PandaShaftScene"]

#: The Panda's scene config (``panda_scene`` section): the shaft scene's, whose defaults it gives.
PandaSceneConfig = ShaftSceneConfig


class PandaShaftScene(ShaftScene):
    """pybullet world: the torque-controlled Panda holding the shaft above the bearing."""

    def __init__(self, config: ShaftSceneConfig | None = None) -> None:
        super().__init__(config or ShaftSceneConfig(), panda_arm())
