"""The simulated Panda's parameters for tests: the ideal arm, for tests that hold the bridge's
control law, estimator or the scene's geometry against the model they were built on (the
default realistic arm's unknown payload, friction and sensor errors are tested on their own in
test_arm_imperfections.py and by the task-property tests)."""
from __future__ import annotations

from typing import Any

from qg_common.params import config_file, load_ros_params, merge_params
from qg_common.shaft_task import ShaftTaskGeometry
from qg_common.types import StartPose


def ideal(cell_changes: dict[str, Any] | None = None, **scene: Any) -> dict[str, Any]:
    """``load_robot("sim_panda", ...)`` parameters of the ideal arm with ``scene`` overrides, in
    the installed cell (``config/shaft_task.yaml``) with ``cell_changes``."""
    values = {**load_ros_params(config_file("shaft_task.yaml"))["shaft_task"],
              **(cell_changes or {})}
    return merge_params(load_ros_params(config_file("panda_ideal.yaml")),
                        {"panda_scene": scene, "shaft_task": values})


def cell(**changes: Any) -> ShaftTaskGeometry:
    """The shaft task's cell of the installed ``config/shaft_task.yaml``, with ``changes``."""
    values = load_ros_params(config_file("shaft_task.yaml"))["shaft_task"]
    return ShaftTaskGeometry.from_dict({**values, **changes})


def start(index: int, **changes: Any) -> StartPose:
    """The cell's start ``index`` (what the executor sends ``move_to_start``)."""
    return cell(**changes).start_pose(index)
