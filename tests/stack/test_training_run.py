"""``qgl run`` through the real stack: a learner killed with SIGKILL mid-episode is restarted
from its checkpoint and the cut episode runs again; the run stopped with Ctrl-C in its third
episode and started again with the same command ends with exactly N training episodes, and the
learner holds the completed episodes' transitions, counted continuously across both restarts.

The stack is the real one (robot, learner, executor processes under ``qgl run``'s launcher) on a
private ROS domain, with short episodes and the 0.25 s step: the subject is the run, not the
learning.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import SHORT_STEP
from qg_common.process_info import child_processes

pytestmark = [pytest.mark.ros, pytest.mark.slow]

EPISODES, MAX_STEPS = 4, 4


def _stack_file(folder: Path) -> Path:
    path = folder / "stack.yaml"
    path.write_text(
        "respawn: {enabled: true, delay: 0.5, max_restarts: 3, window: 120}\n"
        "processes:\n"
        "  - {name: robot, package: robot_bridge_node, executable: robot,\n"
        f"     args: [--ros-args, {', '.join(SHORT_STEP)}]}}\n"
        "  - {name: learner, package: qg_learning_node, executable: learner,\n"
        "     respawn_args: [-p, 'resume:=true']}\n"
        "  - {name: executor, package: qg_learning_node, executable: executor}\n")
    return path


def _journal(run_dir: Path) -> dict:
    try:
        return json.loads((run_dir / "journal.json").read_text())
    except (OSError, ValueError):
        return {}


def _child_pid(parent: int, executable: str) -> int:
    """The pid of ``parent``'s child process running ``lib/<package>/<executable>``."""
    for pid, argv in child_processes(parent).items():
        if any(a.endswith(f"/{executable}") for a in argv):
            return pid
    raise LookupError(f"no {executable} child of {parent}")


def _wait(predicate, timeout: float, run: subprocess.Popen, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert run.poll() is None, f"qgl run ended ({run.returncode}) before {what}"
        assert time.monotonic() < deadline, f"no {what} within {timeout:.0f} s"
        time.sleep(0.02)


@pytest.mark.alone
def test_a_run_survives_a_killed_learner_and_ctrl_c_and_ends_with_exactly_n(
        stack, tmp_path, machine_to_itself) -> None:
    # (the stack fixture holds this test's private ROS domain until it ends; ``qgl run``
    # starts the processes itself)
    env, run_dir = stack.env, tmp_path / "run"
    command = [str(Path(sys.executable).parent / "qgl"), "run", "--episodes", str(EPISODES),
               "--test-poses", "0", "--train-max-steps", str(MAX_STEPS),
               "--episode-timeout", "120", "--config", str(_stack_file(tmp_path)),
               "--run-dir", str(run_dir), "--recording", "mode=rl_rate"]
    # Three stacks' starts and a respawn: the machine to itself, so that neither this run nor
    # the other workers' timed tests are slowed past their limits by the other.
    with machine_to_itself():
        _first_session(command, env, run_dir)
    _second_session(command, env, run_dir)


def _first_session(command: list[str], env: dict, run_dir: Path) -> None:
    first = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True)
    try:
        # The learner dies with the second episode under way ...
        _wait(lambda: (_journal(run_dir).get("running") or {}).get("slot") == 1, 180.0, first,
              "the second episode running")
        learner = _child_pid(first.pid, "learner")
        subprocess.run(["kill", "-9", str(learner)], check=True)
        # ... and the run goes on: Ctrl-C in the third episode (two slots are left to run).
        _wait(lambda: (_journal(run_dir).get("running") or {}).get("slot") == 2, 180.0, first,
              "the third episode running")
        first.send_signal(signal.SIGINT)
        code = first.wait(timeout=60)
    finally:
        if first.poll() is None:
            first.kill()
        out = first.stdout.read()
    assert code == 130, out[-4000:]
    stopped = _journal(run_dir)
    done_before = len(stopped["completed"])
    assert done_before == 2, (stopped, out)
    # The second slot's first attempt was cut short by the learner's death.
    assert any(c["slot"] == 1 and "learner" in c["reason"] for c in stopped["cut_short"]), \
        (stopped["cut_short"], out)
    # Each cut names the death once (the guard's stop and the launcher's report are one event).
    assert all(c["reason"].count("exited with code") <= 1 for c in stopped["cut_short"]), \
        stopped["cut_short"]


def _second_session(command: list[str], env: dict, run_dir: Path) -> None:
    done_before = len(_journal(run_dir)["completed"])
    second = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert second.returncode == 0, second.stdout[-4000:]
    journal = _journal(run_dir)
    completed = journal["completed"]
    # Exactly N training episodes, one per slot, in order, none twice.
    assert [(o["index"], o["mode"]) for o in completed] == \
        [(i, "train") for i in range(EPISODES)], completed
    assert journal["training_done"] == EPISODES and journal["running"] is None
    assert len({o["episode_id"] for o in completed}) == EPISODES
    # (the third slot runs again, or, had it ended and been checkpointed just before the stop,
    # the resume takes it from the learner's record)
    assert len(journal["sessions"]) == 2 \
        and journal["sessions"][1]["at_slot"] in (done_before, done_before + 1), journal["sessions"]
    assert all(1 <= o["steps"] <= MAX_STEPS for o in completed)
    # The learner holds the completed episodes' transitions and no others (the learner that
    # died took the cut attempt's with it; the one stopped by Ctrl-C resumed from its
    # checkpoint), and its count after each episode is the running sum of their steps.
    running = 0
    for o in completed:
        running += o["steps"]
        assert o["learner_transitions"] == running, completed
    record = json.loads((run_dir / "checkpoints" / "learner.json").read_text())
    assert record["transitions"] == running and record["episode_id"] == completed[-1]["episode_id"]
    assert "resumed from" in (run_dir / "logs" / "learner.log").read_text()
    # The same command once more: nothing left to run.
    again = subprocess.run(command, env=env, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and f"all {EPISODES} slots are complete" in again.stdout, \
        again.stdout
    assert _journal(run_dir)["completed"] == completed
