"""The ``torque`` interface kind: joint torques in, the hybrid force/impedance law and the EKF.

Any arm whose plugin gives a ``RobotDescription`` with its URDF and flange runs here: the model
(``ArmModel.from_description``) sizes the controller, the EKF and the safety filter's joint
limits, and the compiled kernels take it as Pinocchio's serialisation. Registered as
``torque`` in ``robot_bridge_node.interfaces`` (``setup.py``).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from qg_common.params import POSITIVE, ParameterSection
from qg_common.types import JointState

from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import Robot, RobotDescription
from robot_bridge_node.core.impedance import ImpedanceConfig
from robot_bridge_node.core.interface_kinds import STEP_SECTIONS, InterfaceKind
from robot_bridge_node.core.loop_clock import LoopClock
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from robot_bridge_node.core.safety import HARD_LIMITS, SafetyLimits
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig
from robot_bridge_node.core.wrench_source import WrenchEstimator

__all__ = ["TORQUE", "EKF_SECTION", "GravityHold", "build_ekf"]

#: The EKF's noise model (``config/wrench_estimator.yaml``): a torque robot's wrench estimate.
EKF_SECTION = ParameterSection("ekf", WrenchEKFConfig, ranges={
    name: POSITIVE for name in WrenchEKFConfig.__dataclass_fields__})


def build_ekf(params: dict[str, Any], model: ArmModel) -> WrenchEKF:
    """The EKF from the node parameters (``ekf`` section of ``config/wrench_estimator.yaml``)."""
    return WrenchEKF(WrenchEKFConfig.from_dict(params.get("ekf", {})), model)


def _build_torque_loop(robot: Robot, bridge_params: dict[str, Any],
                       estimator_params: dict[str, Any], *, wrench: WrenchEstimator | None = None,
                       clock: LoopClock | None = None) -> RobotLoop:
    """The hybrid force/impedance loop; its wrench the EKF's unless ``wrench`` is given."""
    if wrench is not None:
        return build_loop(robot, bridge_params, lambda robot, model: wrench, clock)
    return build_loop(robot, bridge_params,
                      lambda robot, model: build_ekf(estimator_params, model), clock)


class GravityHold:
    """Gravity compensated by the robot's model (tool payload included), motion damped: the arm
    floats in place, as a torque-controlled arm's firmware holds it without commands. An
    unmodelled load makes it drift slowly; the separate sim holds it for at most a few ms between
    the bridge's commands.

    :param damping: [Nms/rad] joint damping.
    """

    def __init__(self, model: ArmModel, damping: float) -> None:
        self.model = model
        self.damping = damping

    def reset(self, state: JointState) -> None:
        del state

    def command(self, state: JointState, last: np.ndarray | None) -> np.ndarray:
        del last
        return self.model.gravity(state.q) - self.damping * state.dq


def _separate_ekf(description: RobotDescription, params: dict[str, Any]) -> WrenchEKF:
    return build_ekf(params, ArmModel.from_description(description))


#: ``interface="torque"``: the Panda, the xArm 7, any arm described by its URDF.
TORQUE = InterfaceKind(
    name="torque", command_field="effort",
    controller_sections=(
        ParameterSection("impedance", ImpedanceConfig, ranges={
            "k_null": POSITIVE, "d_null": POSITIVE, "d_joint": POSITIVE}),
        ParameterSection("safety", SafetyLimits, ranges={
            **{name: (0.0, ceiling) for name, ceiling in HARD_LIMITS.items()},
            "tilt_margin": (0.0, HARD_LIMITS["tilt_max"]), "tilt_stiffness": POSITIVE}),
        *STEP_SECTIONS),
    estimator_sections=(EKF_SECTION,),
    build_loop=_build_torque_loop,
    hold=lambda description, damping: GravityHold(ArmModel.from_description(description),
                                                  damping),
    separate_estimator=_separate_ekf)
