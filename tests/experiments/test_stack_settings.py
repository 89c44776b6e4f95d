"""The experiments read the stack's config files through the nodes' own sections: a value a
node would refuse at start is refused by ``StackSettings.load`` too."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from qg_common.params import ConfigError, config_file
from qg_experiments.runner import StackSettings

FILES = ("shaft_task.yaml", "panda_scene.yaml", "panda_ideal.yaml", "bridge.yaml",
         "wrench_estimator.yaml", "executor.yaml", "learner.yaml")


def edited_config(tmp_path: Path, name: str, path: tuple[str, ...], value) -> Path:
    """The installed config files, copied, with ``name``'s ``path`` set to ``value``."""
    for file in FILES:
        shutil.copy(config_file(file), tmp_path / file)
    data = yaml.safe_load((tmp_path / name).read_text())
    node = data["/**"]["ros__parameters"]
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    (tmp_path / name).write_text(yaml.safe_dump(data))
    return tmp_path


def test_the_shipped_files_load() -> None:
    settings = StackSettings.load()
    assert settings.task.observation == "tilt_motion" and settings.learner.ddpg.gamma == 0.9


@pytest.mark.parametrize("name, path, value, message", [
    ("learner.yaml", ("learner", "ddpg", "gamma"), 1.5, "'learner.ddpg.gamma' = 1.5 is out of range"),
    ("learner.yaml", ("learner", "batch_size"), 0, "'learner.batch_size' = 0 is out of range"),
    ("executor.yaml", ("task", "max_residual_torque"), 5.0,
     "'task.max_residual_torque' = 5.0 is out of range"),
    ("executor.yaml", ("noise", "sigma"), 50.0, "'noise.sigma' = 50.0 is out of range"),
    ("executor.yaml", ("noise", "sigmaa"), 0.3, "unknown parameters ['noise.sigmaa']"),
    ("bridge.yaml", ("rest", "max_time"), 20.0, "'rest.max_time' = 20.0 is out of range"),
    ("wrench_estimator.yaml", ("ekf", "process_noise_force"), -1.0,
     "'ekf.process_noise_force' = -1.0 is out of range"),
    ("panda_scene.yaml", ("panda_scene", "time_step"), 0.1,
     "'panda_scene.time_step' = 0.1 is out of range"),
    ("shaft_task.yaml", ("shaft_task", "start_tilt"), 1.0,
     "'shaft_task.start_tilt' = 1.0 is out of range"),
    ("bridge.yaml", ("reset", "joint_speed"), 5.0, "'reset.joint_speed' = 5.0 is out of range"),
])
def test_a_value_a_node_refuses_is_refused(tmp_path, name, path, value, message) -> None:
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")) as err:
        StackSettings.load(edited_config(tmp_path, name, path, value))
    assert name in str(err.value)
