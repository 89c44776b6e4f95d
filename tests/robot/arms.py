"""The simulated Panda's parameters for tests: the ideal arm, for tests that hold the bridge's
control law, estimator or the scene's geometry against the model they were built on (the
default realistic arm's unknown payload, friction and sensor errors are tested on their own in
test_arm_imperfections.py and by the task-property tests)."""
from __future__ import annotations

from typing import Any

from qg_common.params import config_file, load_ros_params, merge_params


def ideal(**scene: Any) -> dict[str, Any]:
    """``load_robot("sim_panda", ...)`` parameters of the ideal arm with ``scene`` overrides."""
    return merge_params(load_ros_params(config_file("panda_ideal.yaml")), {"panda_scene": scene})
