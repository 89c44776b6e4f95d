"""The stack's settings and its in-process robot on the shaft task, without ROS or a learner.

Why: the runner, the Gymnasium environments, the demo and the report build the same robot from
the same ``config/`` numbers; this package is that one place. It imports no rclpy, no torch and
no message definitions, and nothing of ``qg_experiments`` outside it (the layout tests check both).

=======================  =================================================================
:mod:`.stack_settings`   ``config/``'s files merged as the nodes read them (``StackSettings``)
                         and the digest a saved run is reused under (``config_digest``)
:mod:`.insertion_robot`  the robot plugin, the bridge's loop and the wrench estimator, with
                         the task's MDP (``InsertionRobot``)
=======================  =================================================================
"""
from __future__ import annotations

from qg_experiments.core.insertion_robot import ESTIMATORS, InsertionRobot
from qg_experiments.core.stack_settings import (
    ARMS,
    DEFAULT_ROBOT,
    STACK_CONFIG_FILES,
    StackSettings,
    config_digest,
    stall_recovery_config,
)

__all__ = ["ARMS", "DEFAULT_ROBOT", "ESTIMATORS", "STACK_CONFIG_FILES", "InsertionRobot",
           "StackSettings", "config_digest", "stall_recovery_config"]
