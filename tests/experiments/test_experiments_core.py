"""The experiments' core (``qg_experiments.core``): every default from the config dataclass that
owns it, the ideal arm only for the robot it describes, and the runner's names unchanged."""
from __future__ import annotations

import dataclasses

import pytest
import qg_experiments.runner as runner
from qg_experiments.core import ARMS, InsertionRobot, StackSettings
from qg_experiments.core.stack_settings import IDEAL_ARM_FILE
from qg_experiments.run_spec import RunSpec
from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig


def _without_engine(settings: StackSettings, section: str) -> StackSettings:
    scene = {k: v for k, v in settings.robot[section].items() if k != "engine"}
    return dataclasses.replace(settings, robot={**settings.robot, section: scene})


def test_the_engine_left_unset_is_the_scene_configs_default() -> None:
    panda = StackSettings.load(robot="sim_panda_pybullet")
    assert panda.engine == "pybullet"                       # the file names it
    assert _without_engine(panda, "panda_scene").engine == ShaftSceneConfig().engine == "mujoco"
    xarm = StackSettings.load(robot="sim_xarm7")
    assert "engine" not in xarm.robot["xarm_scene"]          # its file leaves it to the scene
    assert xarm.engine == ShaftSceneConfig.from_dict(xarm.robot["xarm_scene"]).engine
    assert xarm.step_record == {"engine": "mujoco", "step_limit": xarm.step_limit}


def test_the_ideal_arm_is_the_pandas_only() -> None:
    realistic, ideal = (StackSettings.load(arm=arm).robot["panda_scene"]["imperfections"]
                        for arm in ARMS)
    assert realistic["torque_noise"] > 0 and ideal["torque_noise"] == 0.0
    assert StackSettings.load(arm="ideal", robot="sim_panda_pybullet").engine == "pybullet"
    with pytest.raises(ValueError, match=f"{IDEAL_ARM_FILE}: panda_scene.*'sim_xarm7'"):
        StackSettings.load(arm="ideal", robot="sim_xarm7")
    assert "panda_scene" not in StackSettings.load(robot="sim_xarm7").robot
    with pytest.raises(ValueError, match="arm must be one of"):
        StackSettings.load(arm="perfect")


def test_a_runs_name_is_the_one_its_saved_file_has() -> None:
    """The names of saved runs (``<experiment>/<name>.json``): every field that shows, in order."""
    assert RunSpec("qgddpg", 1e-2, 10, 0).name == "qgddpg_lr0.01_it10_s0"
    every = RunSpec("ddpg", 3e-3, 50, 7, reward="sparse", replay_capacity=5000,
                    observation="tilt_only", test_housing_yaw=1.5708, test_housing_tilt=0.1745,
                    graph_resolution=0.01, schedule="async", updates_per_step=2.5,
                    publish_every=10, eval_every=5, arm="ideal", gamma=0.95,
                    robot="sim_panda_mujoco", stall_recovery=True)
    assert every.name == ("ddpg_lr0.003_it50_sparse_cap5000_tilt_only_yaw1.5708_tilt0.1745"
                          "_res0.01_async2.5x10_eval5_g0.95_ideal_sim_panda_mujoco_recovery_s7")
    assert len(dataclasses.fields(RunSpec)) == 26
    with pytest.raises(ValueError, match="estimator must be one of"):
        RunSpec("qgddpg", 1e-2, 10, 0, estimator="force_sensor")


def test_the_runner_names_are_the_split_modules_objects() -> None:
    assert runner.StackSettings is StackSettings and runner.InsertionRobot is InsertionRobot
    assert runner.RunSpec is RunSpec
    assert [name for name in runner.__all__ if not hasattr(runner, name)] == []
    assert len(runner.__all__) == 18


def test_the_core_robot_refuses_an_unknown_estimator() -> None:
    with pytest.raises(ValueError, match="estimator must be one of"):
        InsertionRobot(StackSettings.load(), estimator="force_sensor")
