"""The bridge's and the wrench estimator's parameters as sections: names, ranges.

Pure (no rclpy): the nodes declare exactly these sections, and what builds the same loop without
a node (the in-process experiments) checks its config files against the same ranges
(``qg_common.params.check_section``), so a value a node would refuse is refused there too.
"""
from __future__ import annotations

from qg_common.params import POSITIVE, ParameterSection

from robot_bridge_node.core.impedance import ImpedanceConfig
from robot_bridge_node.core.position_control import PositionControlConfig
from robot_bridge_node.core.rest_detector import RestConfig
from robot_bridge_node.core.robot_loop import LoopConfig
from robot_bridge_node.core.safety import HARD_LIMITS, SafetyLimits
from robot_bridge_node.core.wrench_ekf import WrenchEKFConfig

__all__ = ["CONTROLLER_SECTIONS", "EKF_SECTION"]

_STEP_SECTIONS = (
    ParameterSection("rest", RestConfig, ranges={
        "linear_threshold": (0.0, 1.0), "angular_threshold": (0.0, 10.0),
        "hold_time": (0.0, 10.0), "min_time": (0.0, 10.0), "max_time": (0.0, 10.0)}),
    ParameterSection("loop", LoopConfig, ranges={"dt": (0.0, 0.01), "settle_time": (0.0, 10.0)}))

#: The bridge's parameters by the robot's hardware interface: the controller and its limits,
#: the rest detector that ends an RL step, the loop timing (``config/bridge.yaml``; a position
#: robot's controller gains come with the robot's own files).
CONTROLLER_SECTIONS: dict[str, tuple[ParameterSection, ...]] = {
    "torque": (
        ParameterSection("impedance", ImpedanceConfig, ranges={
            "k_null": POSITIVE, "d_null": POSITIVE, "d_joint": POSITIVE}),
        ParameterSection("safety", SafetyLimits, ranges={
            **{name: (0.0, ceiling) for name, ceiling in HARD_LIMITS.items()},
            "tilt_margin": (0.0, HARD_LIMITS["tilt_max"]), "tilt_stiffness": POSITIVE}),
        *_STEP_SECTIONS),
    "position": (
        ParameterSection("position_control", PositionControlConfig, ranges={
            "damping": (0.0, 1.0), "orientation_weight": POSITIVE, "max_iterations": (1, 10000),
            "max_iteration_step": (0.0, 3.2), "position_tolerance": (0.0, 0.01),
            "orientation_tolerance": (0.0, 0.1), "linear_speed_limit": (0.0, 1.0),
            "angular_speed_limit": (0.0, 10.0), "joint_speed_limit": (0.0, 10.0),
            "dt": (0.0, 0.01)}),
        *_STEP_SECTIONS),
}

#: The EKF's noise model (``config/wrench_estimator.yaml``): a torque robot's wrench estimate.
EKF_SECTION = ParameterSection("ekf", WrenchEKFConfig, ranges={
    name: POSITIVE for name in WrenchEKFConfig.__dataclass_fields__})
