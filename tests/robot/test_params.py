"""ROS 2 parameter files read without rclpy, and the shipped configs match the code defaults."""
from __future__ import annotations

from pathlib import Path

import pytest
from qg_common.params import ConfigError, config_file, load_ros_params, unflatten
from qg_common.shaft_task import ShaftTaskGeometry
from robot_bridge_node.core.impedance import ImpedanceConfig
from robot_bridge_node.core.loop_core import LoopConfig
from robot_bridge_node.core.rest_detector import RestConfig
from robot_bridge_node.core.safety import SafetyLimits
from robot_bridge_node.core.start_motion import ResetConfig
from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig


def test_node_section_overrides_the_wildcard(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    a: {b: 1, c: 2}\n    d.e: 3\n"
        "bridge:\n  ros__parameters:\n    a: {c: 20}\n"
        "other:\n  ros__parameters:\n    a: {b: 99}\n")
    assert load_ros_params(path, "bridge") == {"a": {"b": 1, "c": 20}, "d": {"e": 3}}
    assert load_ros_params(path, "/bridge") == {"a": {"b": 1, "c": 20}, "d": {"e": 3}}
    assert load_ros_params(path) == {"a": {"b": 1, "c": 2}, "d": {"e": 3}}


def test_malformed_files_raise_config_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_ros_params(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**:\n  a: 1\n")
    with pytest.raises(ConfigError, match="ros__parameters"):
        load_ros_params(bad)


def test_unflatten_nests_dotted_names() -> None:
    assert unflatten({"x.y": 1, "x.z": 2, "w": 3}) == {"x": {"y": 1, "z": 2}, "w": 3}


def test_shipped_configs_equal_the_defaults() -> None:
    """The YAML files and the dataclass defaults must not drift apart."""
    scene = load_ros_params(config_file("panda_scene.yaml"), "sim")
    assert ShaftSceneConfig.from_dict(scene["panda_scene"]) == ShaftSceneConfig()
    cell = load_ros_params(config_file("shaft_task.yaml"), "executor")
    assert ShaftTaskGeometry.from_dict(cell["shaft_task"]) == ShaftTaskGeometry()
    start_motion = load_ros_params(config_file("bridge.yaml"), "bridge")["reset"]
    assert ResetConfig.from_dict(start_motion) == ResetConfig()
    bridge = load_ros_params(config_file("bridge.yaml"), "bridge")
    assert ImpedanceConfig.from_dict(bridge["impedance"]) == ImpedanceConfig()
    assert SafetyLimits.from_dict(bridge["safety"]) == SafetyLimits()
    assert RestConfig.from_dict(bridge["rest"]) == RestConfig()
    assert LoopConfig.from_dict(bridge["loop"]) == LoopConfig()


@pytest.mark.parametrize("config,params,match", [
    (ShaftTaskGeometry, {"shaft_radius": 0.0061}, "shaft_radius"),
    (ShaftTaskGeometry, {"hole_position": [0.4, 0.0]}, "hole_position"),
    (ShaftSceneConfig, {"plunger_friction": -1.0}, "plunger_friction"),
    (ShaftTaskGeometry, {"start_tilt": 1.0}, "start_tilt"),
    (ShaftTaskGeometry, {"success_tolerance": 0.005}, "success_tolerance"),
    (ShaftSceneConfig, {"engine": "ode"}, "engine"),
    (ShaftSceneConfig, {"mujoco": {"cone": "round"}}, "cone"),
    (ShaftSceneConfig, {"shaft_radius": 0.005}, "unknown"),
    (ShaftTaskGeometry, {"shaft_radiu": 0.005}, "unknown")])
def test_scene_config_validation(config: type, params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        config.from_dict(params)


def test_impedance_config_validation() -> None:
    with pytest.raises(ValueError, match="k_trans needs 3"):
        ImpedanceConfig(k_trans=(250.0, 250.0))
    with pytest.raises(ValueError, match="d_joint"):
        ImpedanceConfig(d_joint=-0.1)
