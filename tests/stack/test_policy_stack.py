"""A policy file run by real processes: ``qgl up --policy FILE`` starts no learner and runs a
test episode in which every action is the file's actor of its state, bit for bit; an executor
given a file that does not fit its stack exits at start with code 2 and the reason (no
traceback); ``qgl export-policy`` writes the file from a checkpoint."""
from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.ros

STEPS = 6       # [steps] the test episode's cap here


def _export(tmp_path: Path, name: str, state_dim: int, observation: str, kind: str = "residual",
            robot: str = "sim_panda") -> Path:
    """A policy file of a seeded, untrained actor (its actions still vary with the state)."""
    from qg_bringup.policy import executor_task, export_core
    from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore
    action_dim = 3 if kind == "peg" else 2
    config = LearnerConfig.from_dict({"ddpg": {"actor_hidden": [16, 16], "seed": 5},
                                      "zero_action": [0.0] * action_dim})
    overrides = {"task.kind": kind} if kind == "peg" else {"task.observation": observation}
    kind, task = executor_task(overrides=overrides)
    return export_core(LearnerCore(config, state_dim, action_dim), kind, task, robot,
                       tmp_path / name, "test")


def _qgl(env: dict, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "qg_bringup.main", *args], env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_an_executor_refuses_a_file_that_does_not_fit_at_start(stack, tmp_path):
    from qg_bringup.stack_file import ProcessSpec
    executor = ProcessSpec("executor", "qg_learning_node", "executor").command()
    tilt = _export(tmp_path, "tilt.npz", 6, "tilt")
    thesis = _export(tmp_path, "thesis.npz", 4, "thesis")
    peg = _export(tmp_path, "peg.npz", 3, "peg", kind="peg", robot="sim_nextage")
    fitting = _export(tmp_path, "tilt_motion.npz", 3, "tilt_motion")   # the default state
    cases = [
        (tilt, (), "state size: the file's actor takes 6-D states, this executor's are 3-D"),
        (peg, (), "action size: the file's actor gives 3-D actions, this executor's task "
                  "takes 2-D"),
        (thesis, ("-p", "task.observation:=tilt_force"),
         "observation kind: the file's is 'thesis', this executor's task.observation is "
         "'tilt_force'"),
        (fitting, ("-p", "policy.robot:=sim_xarm7"),
         "robot: the file was trained on 'sim_panda' (family 'franka'), this stack drives "
         "'sim_xarm7'"),
        (tmp_path / "missing.npz", (), "policy file not found"),
    ]
    for path, extra, reason in cases:
        run = subprocess.run([*executor, "--ros-args", "-p", f"policy.file:={path}", *extra],
                             env=stack.env, capture_output=True, text=True, timeout=60.0)
        assert run.returncode == 2, (reason, run.stdout, run.stderr)
        assert reason in run.stderr, (reason, run.stderr)
        assert "Traceback" not in run.stderr, run.stderr
    # Through qgl up: the stack stops at once, with the executor's reason and its code.
    config = tmp_path / "stack.yaml"
    config.write_text("processes:\n"
                      "  - {name: executor, package: qg_learning_node, executable: executor,\n"
                      "     respawn: true}\n"
                      "  - {name: learner, package: qg_learning_node, executable: learner}\n")
    up = _qgl(stack.env, "up", "--config", str(config), "--policy", str(peg))
    assert up.returncode == 2, up.stdout + up.stderr
    assert "action size: the file's actor gives 3-D actions" in up.stdout, up.stdout
    assert "[qgl] started executor" in up.stdout and "learner" not in up.stdout.split(
        "[qgl] started")[1].splitlines()[0], up.stdout
    # The file that fits: the same executor starts (and stops on SIGINT with code 0).
    fits = subprocess.Popen([*executor, "--ros-args", "-p", f"policy.file:={fitting}"],
                            env=stack.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    try:
        line = fits.stdout.readline()
        while "frozen policy" not in line:
            assert line, "the executor ended before loading the policy"
            line = fits.stdout.readline()
        assert "observation tilt_motion (3-D states, 2-D actions), trained on sim_panda" in line
    finally:
        fits.send_signal(signal.SIGINT)
        assert fits.wait(timeout=20.0) == 0


def test_qgl_up_policy_runs_the_frozen_actor_without_a_learner(stack, tmp_path):
    from qg_common.topics import RELIABLE_DEEP
    from qg_interfaces.msg import Transition
    from qg_learning_node.policy_file import load_policy
    from test_episodes import Episodes
    # A file of another state than the shipped default: qgl up runs its executor in the file's.
    path = _export(tmp_path, "policy.npz", 2, "tilt_only")
    policy = load_policy(path)
    config = tmp_path / "stack.yaml"       # the shipped stack, with a short test episode
    config.write_text(
        "processes:\n"
        "  - {name: robot, package: robot_bridge_node, executable: robot}\n"
        "  - {name: learner, package: qg_learning_node, executable: learner}\n"
        "  - {name: executor, package: qg_learning_node, executable: executor,\n"
        f"     args: [--ros-args, -p, 'task.test_max_steps:={STEPS}']}}\n")
    up = subprocess.Popen([sys.executable, "-m", "qg_bringup.main", "up", "--config",
                           str(config), "--policy", str(path), "--log-dir", str(tmp_path / "up")],
                          env=stack.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          text=True)
    try:
        with stack.client() as cli:
            transitions: list = []
            cli.node.create_subscription(Transition, "/transitions", transitions.append,
                                         RELIABLE_DEEP)
            episodes = Episodes(cli)
            episodes.wait_for_robot(timeout=90.0)
            response = episodes.start(mode="test", initial_pose=2)
            assert response.success, response.message
            final = episodes.final(response.episode_id, timeout=120.0)
            assert final.state == "done", final.message
            assert not final.degraded and 1 <= final.step <= STEPS
            assert final.actor_version == policy.spec.provenance["actor_version"]
            assert cli.spin_until(lambda: len(transitions) == final.step, 10.0), transitions
            assert "/learner" not in cli.node_names() and "/executor" in cli.node_names()
        states = np.array([t.state for t in transitions])
        assert states.shape == (final.step, 2)                 # tilt_only's, not the default's
        actions = np.array([t.action for t in transitions])
        assert [t.step for t in transitions] == list(range(final.step))
        # Every action is the file's actor of the state it saw, bit for bit (no noise in test).
        assert np.array_equal(actions, np.array([policy(s) for s in states]))
        assert np.abs(actions).max() > 1e-3            # not the zero residual of a lost learner
    finally:
        up.send_signal(signal.SIGINT)
        out, _ = up.communicate(timeout=60.0)   # three processes stopped in turn, loaded
    assert "frozen policy" in out and "no learner" in out, out
    started = next(line for line in out.splitlines() if "[qgl] started" in line)
    assert "learner" not in started and "executor" in started and "robot" in started, started
    assert up.returncode == 0, out


def test_export_policy_writes_a_checkpoints_actor(stack, tmp_path):
    """The command line: a checkpoint in, a file whose actor is the checkpoint's out; sizes the
    checkpoint does not have are refused."""
    from qg_learning_node.learner.actor_mlp import ActorMLP
    from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore
    from qg_learning_node.policy_file import load_policy
    core = LearnerCore(LearnerConfig.from_dict({"ddpg": {"actor_hidden": [8], "seed": 2}}), 3, 2)
    (tmp_path / "run" / "checkpoints").mkdir(parents=True)
    core.save(tmp_path / "run" / "checkpoints" / "learner.pt")
    done = _qgl(stack.env, "export-policy", "--run", str(tmp_path / "run"), "-o",
                str(tmp_path / "out.npz"), "--robot", "sim_panda_mujoco")
    assert done.returncode == 0, done.stderr
    policy = load_policy(tmp_path / "out.npz")
    assert (policy.spec.robot, policy.spec.observation) == ("sim_panda_mujoco", "tilt_motion")
    states = np.random.default_rng(1).uniform(-1, 1, (500, 3))
    actor = ActorMLP.from_tensors(core.agent.actor_tensors())
    assert np.array_equal([policy(s) for s in states], [actor(s) for s in states])
    wrong = _qgl(stack.env, "export-policy", "--checkpoint",
                 str(tmp_path / "run" / "checkpoints" / "learner.pt"), "-o",
                 str(tmp_path / "tilt.npz"), "--set", "task.observation=tilt")
    assert wrong.returncode == 2
    assert "the learner's actor maps 3-D states to 2-D actions; the residual task with " \
           "observation 'tilt' has 6-D states" in wrong.stderr, wrong.stderr
    assert not (tmp_path / "tilt.npz").exists()
    # A run whose executor logged another state: its checkpoint is exported for that state.
    tilt_run = tmp_path / "tilt_run"
    (tilt_run / "logs").mkdir(parents=True)
    LearnerCore(LearnerConfig.from_dict({"ddpg": {"actor_hidden": [8]}}), 6, 2).save(
        tilt_run / "learner.pt")
    (tilt_run / "logs" / "executor.log").write_text(
        "[INFO] [1795888735.798370886] [executor]: task residual, observation tilt: 6-D states, "
        "2-D actions\n")
    done = _qgl(stack.env, "export-policy", "--run", str(tilt_run), "-o", str(tmp_path / "t"))
    assert done.returncode == 0, done.stderr
    spec = load_policy(tmp_path / "t.npz").spec
    assert (spec.observation, spec.state_dim) == ("tilt", 6)
    assert set(spec.settings) == {"base_force", "max_residual_torque", "force_range",
                                  "torque_range", "tilt_range"}
