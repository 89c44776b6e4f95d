"""When the learner node checkpoints after a training episode: once all of its transitions are
in, or once they have stopped coming (published while the learner was down).

The node's callbacks are called directly, in this process, in the order and at the pace a
loaded machine delivers them: the episode's end first, its transitions after it, slowly.
"""
from __future__ import annotations

import time

import pytest

pytestmark = pytest.mark.ros

GRACE = 0.4         # [s] the grace of this test (the node's is 3 s)


@pytest.fixture
def learner(tmp_path, monkeypatch):
    import rclpy
    from qg_learning_node import learner_node

    monkeypatch.setattr(learner_node, "CHECKPOINT_GRACE", GRACE)
    context_args = ["--ros-args", "-p", f"checkpoint_dir:={tmp_path}", "-p", "resume:=false"]
    rclpy.init(args=context_args, domain_id=232)        # no test's processes use it
    node = learner_node.LearnerNode()
    try:
        from qg_interfaces.msg import TaskSpec
        node._on_task(TaskSpec(kind="residual", observation="tilt_only", state_dim=2,
                               action_dim=2))
        yield node
    finally:
        node.destroy_node()
        rclpy.shutdown()


def _end(node, episode_id: str, steps: int) -> None:
    from qg_interfaces.msg import EpisodeStatus
    for state in ("running", "done"):
        node._on_status(EpisodeStatus(episode_id=episode_id, state=state, mode="train",
                                      step=steps))


def _take(node, episode_id: str, step: int) -> None:
    from qg_interfaces.msg import Transition
    node._on_transition(Transition(episode_id=episode_id, step=step, state=[0.1, -0.2],
                                   action=[0.0, 0.5], reward=-0.3, next_state=[0.1, -0.1]))


def _saved_steps(node) -> int | None:
    from qg_learning_node.learner.learner_core import LearnerCore
    return LearnerCore.load(node.checkpoint).steps if node.checkpoint.exists() else None


def test_a_slow_learner_checkpoints_only_once_every_transition_is_in(learner) -> None:
    # Six transitions taken 0.25 s apart after the end: the last comes 1.5 s after it, well
    # past the grace, yet each within the grace of the one before.
    _end(learner, "slow", 6)
    for step in range(6):
        time.sleep(0.25)
        learner._checkpoint_pending()
        assert _saved_steps(learner) is None, step
        _take(learner, "slow", step)
    assert _saved_steps(learner) == 6


def test_transitions_that_stop_coming_are_checkpointed_without_the_rest(learner) -> None:
    _end(learner, "down", 5)
    _take(learner, "down", 0)
    _take(learner, "down", 1)
    time.sleep(GRACE / 2)
    learner._checkpoint_pending()
    assert _saved_steps(learner) is None
    time.sleep(GRACE)
    learner._checkpoint_pending()
    assert _saved_steps(learner) == 2
    assert "down" in learner.checkpointed and "down" not in learner.pending_checkpoint


def test_an_aborted_episode_is_not_checkpointed_a_completed_test_episode_is(learner) -> None:
    import json

    from qg_interfaces.msg import EpisodeStatus
    from qg_learning_node.learner_node import CHECKPOINT_INFO_NAME
    for step in range(3):
        _take(learner, "cut", step)
    for state in ("running", "aborted"):
        learner._on_status(EpisodeStatus(episode_id="cut", state=state, mode="train", step=3,
                                         message="shutdown"))
    learner._checkpoint_pending()
    assert _saved_steps(learner) is None                  # the aborted one: no checkpoint
    learner._on_status(EpisodeStatus(episode_id="exam", state="running", mode="test"))
    for step in range(2):
        _take(learner, "exam", step)
    learner._on_status(EpisodeStatus(episode_id="exam", state="done", mode="test", step=2,
                                     episode_return=-1.5, success=True, initial_pose=4))
    assert _saved_steps(learner) == 5                     # the aborted part stays in memory
    info = json.loads((learner.checkpoint.parent / CHECKPOINT_INFO_NAME).read_text())
    assert {k: info[k] for k in ("episode_id", "mode", "state", "steps", "episode_return",
                                 "success", "initial_pose", "received", "transitions")} == {
        "episode_id": "exam", "mode": "test", "state": "done", "steps": 2,
        "episode_return": -1.5, "success": True, "initial_pose": 4, "received": 2,
        "transitions": 5}


def test_transitions_before_the_task_are_held_and_taken_when_it_comes(tmp_path) -> None:
    """A restarted learner may hear an episode's first transition before the executor's
    latched task (discovery brings it later): it is held, not dropped, and the episode is
    checkpointed whole."""
    import rclpy
    from qg_interfaces.msg import TaskSpec
    from qg_learning_node import learner_node

    rclpy.init(args=["--ros-args", "-p", f"checkpoint_dir:={tmp_path}", "-p", "resume:=false"],
               domain_id=232)
    node = learner_node.LearnerNode()
    try:
        _take(node, "early", 0)
        _take(node, "early", 1)
        assert node.core is None                    # no networks before the task
        node._on_task(TaskSpec(kind="residual", observation="tilt_only", state_dim=2,
                               action_dim=2))
        assert node.core.steps == 2 and node.received["early"] == 2    # both taken
        _take(node, "early", 2)
        _end(node, "early", 3)
        assert _saved_steps(node) == 3      # every transition in: checkpointed at once
    finally:
        node.destroy_node()
        rclpy.shutdown()
