"""The policy file: a learner's actor exported and loaded gives the same actions bit for bit,
and a file that does not fit the stack (state or action size, observation, robot, a setting)
is refused with the reason; a damaged or foreign file is refused by name."""
from __future__ import annotations

import dataclasses
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from qg_bringup.policy import export_core, frozen_stack, stack_robot
from qg_bringup.stack_file import ProcessSpec, StackConfigError
from qg_common.peg_task import PegCell
from qg_common.shaft_task import ShaftTaskGeometry
from qg_learning_node.executor.peg_task import PegTask, PegTaskConfig
from qg_learning_node.executor.residual_task import ResidualTask, TaskConfig
from qg_learning_node.learner.actor_mlp import ActorMLP
from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore
from qg_learning_node.policy_file import (
    FORMAT_VERSION,
    PolicyFileError,
    frozen_policy,
    load_policy,
    mismatches,
    save_policy,
    spec_for_task,
)

torch.set_num_threads(1)
CELL = ShaftTaskGeometry()


def _task(observation: str = "tilt_only", **config) -> ResidualTask:
    return ResidualTask(TaskConfig(observation=observation, **config), CELL)


def _trained_core(state_dim: int, steps: int = 60, seed: int = 3) -> LearnerCore:
    """A learner that took ``steps`` random transitions and trained on them (its actor is not
    the initial one)."""
    config = LearnerConfig.from_dict({"ddpg": {"actor_hidden": [32, 32],
                                               "critic_hidden": [32, 32], "seed": seed},
                                      "zero_action": [0.0, 0.0], "iterations_per_cycle": 5})
    core = LearnerCore(config, state_dim, 2)
    rng = np.random.default_rng(seed)
    s = rng.uniform(-1, 1, state_dim)
    for t in range(steps):
        s2 = rng.uniform(-1, 1, state_dim)
        if core.add_transition(s, rng.uniform(-1, 1, 2), -1.0, s2, t % 20 == 19):
            core.train_cycle()
        s = s2
    assert core.actor_version == steps // 20
    return core


def test_export_then_load_gives_bit_identical_actions(tmp_path: Path) -> None:
    core = _trained_core(2)
    path = export_core(core, "residual", _task(), "sim_panda", tmp_path / "actor", "test run")
    assert path == tmp_path / "actor.npz"
    policy = load_policy(path)
    trained = ActorMLP.from_tensors(core.agent.actor_tensors())  # what the executor ran
    states = np.random.default_rng(7).uniform(-1.2, 1.2, (5000, 2))
    frozen = np.array([policy(s) for s in states])
    live = np.array([trained(s) for s in states])
    assert np.array_equal(frozen, live)                  # bit for bit, every state
    assert np.ptp(frozen[:, 0]) > 0.01                   # a real, state-dependent policy
    with torch.no_grad():                                # and torch's actor agrees to float32
        torch_actions = core.agent.actor(torch.tensor(states, dtype=torch.float32)).numpy()
    assert np.max(np.abs(torch_actions - frozen)) < 1e-5
    spec = policy.spec
    assert (spec.task, spec.observation, spec.state_dim, spec.action_dim, spec.robot) == \
        ("residual", "tilt_only", 2, 2, "sim_panda")
    assert spec.settings == {"base_force": -15.0, "max_residual_torque": 3.0, "tilt_range": 0.5}
    assert spec.provenance["steps"] == 60 and spec.provenance["actor_version"] == 3
    assert spec.provenance["updates"] == 15 and spec.provenance["source"] == "test run"


def test_the_file_is_numpy_without_pickle_and_says_what_it_is(tmp_path: Path) -> None:
    path = export_core(_trained_core(6), "residual", _task("tilt"), "sim_panda",
                       tmp_path / "tilt.npz", "x")
    with np.load(path, allow_pickle=False) as archive:      # no pickle needed to read it
        names = sorted(archive.files)
        header = json.loads(str(archive["header"]))
    assert names == ["header", "layer0.bias", "layer0.weight", "layer1.bias", "layer1.weight",
                     "layer2.bias", "layer2.weight"]
    assert header["format"] == "qg-policy" and header["format_version"] == FORMAT_VERSION
    assert header["settings"] == {"base_force": -15.0, "force_range": 20.0,
                                  "max_residual_torque": 3.0, "tilt_range": 0.5,
                                  "torque_range": 3.0}


@pytest.mark.parametrize("stack, reason", [
    (dict(observation="tilt"),
     "state size: the file's actor takes 2-D states, this executor's are 6-D"),
    (dict(observation="tilt"),
     "observation kind: the file's is 'tilt_only', this executor's task.observation is 'tilt'"),
    (dict(robot="sim_nextage"),
     "robot: the file was trained on 'sim_panda' (family 'franka'), this stack drives "
     "'sim_nextage'"),
    (dict(robot="sim_xarm7"), "robot: the file was trained on 'sim_panda'"),
    (dict(max_residual_torque=2.0),
     "setting max_residual_torque: the file's actor was trained with 3.0, this executor has 2.0"),
])
def test_a_file_that_does_not_fit_is_refused_with_the_reason(tmp_path: Path, stack: dict,
                                                             reason: str) -> None:
    path = export_core(_trained_core(2, steps=20), "residual", _task(), "sim_panda",
                       tmp_path / "p.npz", "x")
    robot = stack.pop("robot", "sim_panda")
    with pytest.raises(PolicyFileError) as refused:
        frozen_policy(str(path), robot, "residual", _task(**stack))
    assert reason in str(refused.value)
    assert str(path) in str(refused.value)


def test_the_action_size_and_task_kind_are_checked(tmp_path: Path) -> None:
    """A peg actor (3-D actions) on the Panda's residual task: kind, observation, both sizes."""
    peg = PegTask(PegTaskConfig(), PegCell())
    core = LearnerCore(LearnerConfig.from_dict({"ddpg": {"actor_hidden": [8]},
                                               "zero_action": [0.0, 0.0, 0.0]}), 3, 3)
    path = export_core(core, "peg", peg, "sim_nextage", tmp_path / "peg.npz", "x")
    reasons = mismatches(load_policy(path).spec, spec_for_task("residual", _task(), "sim_panda"))
    assert any(r.startswith("action size: the file's actor gives 3-D actions, this executor's "
                            "task takes 2-D") for r in reasons), reasons
    assert any(r.startswith("task kind: the file's actor runs the 'peg' task") for r in reasons)
    assert len(reasons) == 5        # kind, observation, state size, action size, robot
    # ... and on its own stack it fits
    assert frozen_policy(str(path), "sim_nextage", "peg", peg) is not None


def test_the_panda_family_runs_on_the_fr3_and_an_unset_file_is_the_learners(
        tmp_path: Path) -> None:
    path = export_core(_trained_core(2, steps=20), "residual", _task(), "sim_panda_mujoco",
                       tmp_path / "p.npz", "x")
    for robot in ("franka", "sim_panda", "sim_panda_pybullet"):
        assert frozen_policy(str(path), robot, "residual", _task()) is not None
    assert frozen_policy("", "sim_panda", "residual", _task()) is None


def test_sizes_the_checkpoint_does_not_have_are_not_exported(tmp_path: Path) -> None:
    with pytest.raises(PolicyFileError, match="the learner's actor maps 2-D states to 2-D "
                       "actions; the residual task with observation 'tilt' has 6-D states"):
        export_core(_trained_core(2, steps=20), "residual", _task("tilt"), "sim_panda",
                    tmp_path / "p.npz", "x")
    assert not (tmp_path / "p.npz").exists()


def test_damaged_and_foreign_files_are_refused_by_name(tmp_path: Path) -> None:
    good = export_core(_trained_core(2, steps=20), "residual", _task(), "sim_panda",
                       tmp_path / "good.npz", "x")
    with pytest.raises(PolicyFileError, match="policy file not found"):
        load_policy(tmp_path / "missing.npz")
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(PolicyFileError, match="is not a policy file"):
        load_policy(tmp_path / "text.npz")
    np.savez(tmp_path / "plain.npz", w=np.zeros(3))
    with pytest.raises(PolicyFileError, match="has no policy header"):
        load_policy(tmp_path / "plain.npz")
    # one weight changed: the digest finds it
    with np.load(good) as archive:
        arrays = {name: archive[name] for name in archive.files}
    arrays["layer1.weight"] = arrays["layer1.weight"].copy()
    arrays["layer1.weight"][0, 0] += 1e-3
    np.savez(tmp_path / "edited.npz", **arrays)
    with pytest.raises(PolicyFileError, match="do not match the header's digest"):
        load_policy(tmp_path / "edited.npz")
    # a newer format than this reader's
    header = json.loads(str(arrays["header"]))
    arrays["header"] = np.array(json.dumps({**header, "format_version": FORMAT_VERSION + 1}))
    np.savez(tmp_path / "newer.npz", **arrays)
    with pytest.raises(PolicyFileError, match="format version 2; this stack reads up to 1"):
        load_policy(tmp_path / "newer.npz")
    assert zipfile.is_zipfile(good)


def test_a_frozen_stack_has_no_learner_and_its_executor_gets_the_file(tmp_path: Path) -> None:
    path = export_core(_trained_core(2, steps=20), "residual", _task(), "sim_panda",
                       tmp_path / "p.npz", "x")
    specs = [ProcessSpec("franka_sim", "franka_sim_node", "franka_sim"),
             ProcessSpec("robot", "robot_bridge_node", "robot", ("--ros-args", "-p",
                                                                   "robot:=franka")),
             ProcessSpec("learner", "qg_learning_node", "learner"),
             ProcessSpec("executor", "qg_learning_node", "executor")]
    assert stack_robot(specs) == "franka" and stack_robot(specs[2:]) == "sim_panda"
    frozen = frozen_stack(specs, path)
    assert [s.name for s in frozen] == ["franka_sim", "robot", "executor"]
    # The file's state definition first (the stack file's own arguments, after it, would win),
    # then the file and the robot.
    assert frozen[-1].args == ("--ros-args", "-p", "task.observation:=tilt_only", "--",
                               "--ros-args", "-p", f"policy.file:={path.resolve()}",
                               "-p", "policy.robot:=franka")
    with pytest.raises(StackConfigError, match="policy file not found"):
        frozen_stack(specs, tmp_path / "none.npz")
    with pytest.raises(StackConfigError, match="needs a stack with an executor"):
        frozen_stack(specs[:3], path)


def test_a_relu_actor_runs_as_trained(tmp_path: Path) -> None:
    """The hidden activation travels with the weights (SB3's preset uses ReLU)."""
    config = LearnerConfig.from_dict({"ddpg": {"actor_hidden": [16], "actor_activation": "relu",
                                               "seed": 1}})
    core = LearnerCore(config, 2, 2)
    policy = load_policy(export_core(core, "residual", _task(), "sim_panda",
                                     tmp_path / "r.npz", "x"))
    assert policy.spec.hidden_activation == "relu"
    states = np.random.default_rng(0).uniform(-1, 1, (200, 2))
    with torch.no_grad():
        expected = core.agent.actor(torch.tensor(states, dtype=torch.float32)).numpy()
    assert np.max(np.abs(np.array([policy(s) for s in states]) - expected)) < 1e-5
    spec = dataclasses.replace(policy.spec, state_dim=3)
    with pytest.raises(PolicyFileError, match="the actor maps 2-D states to 2-D actions, its "
                       "spec says 3 -> 2"):
        save_policy(tmp_path / "bad.npz", policy, spec)


def test_a_runs_task_is_read_from_its_executors_logs(tmp_path: Path) -> None:
    """``export-policy --run`` takes the state the run's executor logged at start, from the
    launcher's logs or the ROS logs; two different tasks in one run are refused, not guessed."""
    from qg_bringup.policy import logged_task
    line = "[INFO] [1795888735.798370886] [executor]: task residual, observation {}: {}-D " \
           "states, 2-D actions\n"
    assert logged_task(tmp_path) is None
    (tmp_path / "ros_log").mkdir()
    (tmp_path / "ros_log" / "python3_1_2.log").write_text(
        "[INFO] [1.0] [learner]: learning\n" + line.format("tilt_force", 4))
    assert logged_task(tmp_path) == {"kind": "residual", "observation": "tilt_force"}
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "executor.log").write_text(line.format("tilt_force", 4))
    assert logged_task(tmp_path) == {"kind": "residual", "observation": "tilt_force"}
    (tmp_path / "ros_log" / "python3_3_4.log").write_text(line.format("tilt_only", 2))
    with pytest.raises(ValueError, match=r"ran several tasks \(residual tilt_force, residual "
                       r"tilt_only\): name the one to export with --set"):
        logged_task(tmp_path)
