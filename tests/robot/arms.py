"""The simulated Panda's parameters for tests: the ideal arm, for tests that hold the bridge's
control law, estimator or the scene's geometry against the model they were built on (the
default realistic arm's unknown payload, friction and sensor errors are tested on their own in
test_arm_imperfections.py and by the task-property tests)."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest
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


def pressed_balance(loop, pose: int, residual: tuple[float, float], rest_steps: int,
                    push: float = -15.0) -> np.ndarray:
    """(6,) The contact wrench the arm feels, tool frame, contact convention, from its own
    balance over one control step (``J^T F = M ddq + C dq + g - tau``) after ``loop`` pressed
    the shaft from start ``pose``: two steps with ``residual``, then the base push alone until
    the arm rests (within ``rest_steps`` steps, else the test fails)."""
    from qg_common.types import WrenchSetpoint
    loop.reset(loop.simulation.scene.geometry.start_pose(pose))
    for _ in range(2):
        loop.execute(WrenchSetpoint.residual(push, *residual))
    for _ in range(rest_steps):
        if not loop.execute(WrenchSetpoint.residual(push, 0.0, 0.0)).timed_out:
            break
    else:
        pytest.fail("the arm did not come to rest")
    scene = loop.simulation.scene
    before = scene.joint_state()
    loop.tick()                                       # one step of known torque
    after = scene.joint_state()
    model = loop.controller.model
    kinematics = model.kinematics(before.q)
    ddq = (after.dq - before.dq) / loop.config.dt
    generalised = (model.mass_matrix(before.q) @ ddq
                   + model.nonlinear_effects(before.q, before.dq) - after.tau)
    world = np.linalg.pinv(kinematics.jacobian.T) @ generalised
    return np.concatenate([kinematics.rotation.T @ world[:3], kinematics.rotation.T @ world[3:]])
