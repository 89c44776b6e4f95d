"""``ros2 param set`` on real executor and learner processes: what may change between episodes or
training cycles does, from the next one on, and is logged; the rest is refused as read-only,
and ``ros2 param describe`` says why and shows the shipped value."""
from __future__ import annotations

import numpy as np
import pytest
from param_client import describe, get, integer, set_double, set_value, string
from task_spec import announce_task
from test_episodes import ROBOT, Episodes

pytestmark = pytest.mark.ros


def test_learner_takes_iterations_batch_size_and_learning_rates_from_the_next_cycle(
        stack, tmp_path):
    import torch
    from qg_common.topics import LATCHED, RELIABLE_DEEP
    from qg_interfaces.msg import EpisodeStatus, LearnerDiagnostics, Transition
    checkpoints = tmp_path / "checkpoints"
    stack.start(("learner", "qg_learning_node", "learner",
                 ("--ros-args", "-p", "learner.cycle_steps:=5",
                  "-p", "learner.iterations_per_cycle:=2", "-p", "learner.batch_size:=4",
                  "-p", f"checkpoint_dir:={checkpoints}")))
    with stack.client() as cli:
        beats: list[LearnerDiagnostics] = []
        cli.node.create_subscription(LearnerDiagnostics, "/learner/diagnostics", beats.append, 10)
        transitions = cli.node.create_publisher(Transition, "/transitions", RELIABLE_DEEP)
        statuses = cli.node.create_publisher(EpisodeStatus, "/episode_status", LATCHED)
        task = announce_task(cli, state_dim=2, observation="tilt_only")
        assert cli.spin_until(lambda: beats and transitions.get_subscription_count() > 0,
                              60.0), stack.logs()

        gamma = describe(cli, "/learner", "learner.ddpg.gamma")
        assert gamma.read_only
        assert "Default 0.9 (config/learner.yaml)" in gamma.description, gamma.description
        assert "read-only: the networks, Q-Graph and replay memory" in gamma.description
        refused = set_double(cli, "/learner", "learner.ddpg.gamma", 0.5)
        assert not refused.successful and "read-only" in refused.reason
        batch = describe(cli, "/learner", "learner.batch_size")
        assert not batch.read_only
        assert "settable with `ros2 param set`, applies from the next training cycle" \
            in batch.description, batch.description

        def feed(episode: str, steps: int) -> None:
            for step in range(steps):
                transitions.publish(Transition(episode_id=episode, step=step,
                                               state=[0.1 * step, 0.0], action=[0.0, 0.1],
                                               reward=-1.0, next_state=[0.1 * step + 0.1, 0.0]))

        def updates(n: int) -> bool:
            return cli.spin_until(lambda: beats[-1].updates == n, 60.0)

        feed("one", 5)
        assert updates(2), stack.logs()                      # one cycle of 2
        assert set_value(cli, "/learner", "learner.iterations_per_cycle", integer(7)).successful
        assert set_value(cli, "/learner", "learner.batch_size", integer(16)).successful
        assert set_double(cli, "/learner", "learner.ddpg.critic_lr", 1e-4).successful
        assert set_double(cli, "/learner", "learner.ddpg.actor_lr", 3e-5).successful
        assert get(cli, "/learner", "learner.iterations_per_cycle", "learner.batch_size") == \
            [7, 16]
        feed("one", 5)
        assert updates(9), stack.logs()                      # the next cycle: 7 more, no burst
        cli.spin_for(1.0)
        assert beats[-1].updates == 9

        # An ended episode is checkpointed: the optimizers' step sizes and the config in it.
        statuses.publish(EpisodeStatus(episode_id="one", mode="train", state="running"))
        cli.spin_for(0.3)
        statuses.publish(EpisodeStatus(episode_id="one", mode="train", state="done", step=10))
        checkpoint = checkpoints / "learner.pt"
        assert cli.spin_until(checkpoint.exists, 30.0), stack.logs()
        del task
    saved = torch.load(checkpoint, weights_only=False)
    assert saved["config"]["batch_size"] == 16 and saved["config"]["iterations_per_cycle"] == 7
    assert [g["lr"] for g in saved["agent"]["critic_opt"]["param_groups"]] == [1e-4]
    assert [g["lr"] for g in saved["agent"]["actor_opt"]["param_groups"]] == [3e-5]
    log = (stack.log_dir / "learner.log").read_text()
    assert "parameter learner.iterations_per_cycle: 2 -> 7, applies from the next training " \
           "cycle" in log, log
    assert "parameter learner.ddpg.critic_lr: 0.001 -> 0.0001" in log, log
    assert "task of the executor: residual, observation tilt_only, 2-D states, 2-D actions; " \
           "networks built for it" in log, log


def test_executor_noise_set_between_episodes_applies_to_the_next_one(stack, tmp_path):
    """Noise off: a training episode's actions are the actor's own; noise back on: they are
    not. The actor does not change (no training cycle within these short episodes)."""
    from qg_common.topics import LATCHED, RELIABLE_DEEP
    from qg_interfaces.msg import ActorParameters, Transition
    from qg_learning_node.conversions import actor_tensors_from_msg
    from qg_learning_node.learner.actor_mlp import ActorMLP
    stack.start(ROBOT, ("learner", "qg_learning_node", "learner",
                        ("--ros-args", "-p", f"checkpoint_dir:={tmp_path / 'checkpoints'}")),
                ("executor", "qg_learning_node", "executor",
                 ("--ros-args", "-p", "task.train_max_steps:=3")))
    with stack.client() as cli:
        actors: list[ActorParameters] = []
        steps: list[Transition] = []
        cli.node.create_subscription(ActorParameters, "/actor_parameters", actors.append, LATCHED)
        cli.node.create_subscription(Transition, "/transitions", steps.append, RELIABLE_DEEP)
        episodes = Episodes(cli)
        episodes.wait_for_learner()
        episodes.wait_for_robot()
        assert cli.spin_until(lambda: actors, 30.0), stack.logs()
        actor = ActorMLP.from_tensors(actor_tensors_from_msg(actors[-1]))

        def run() -> list[float]:
            """One training episode; each step's |action - actor(state)|."""
            response = episodes.start(mode="train", initial_pose=1)
            assert response.success, response.message + stack.logs()
            assert episodes.final(response.episode_id, 120.0).state == "done", stack.logs()
            cli.spin_for(0.3)
            mine = [t for t in steps if t.episode_id == response.episode_id]
            assert len(mine) == 3, stack.logs()
            return [float(np.max(np.abs(np.asarray(t.action) - actor(np.asarray(t.state)))))
                    for t in mine]

        assert set_value(cli, "/executor", "noise.kind", string("none")).successful
        assert max(run()) < 1e-6                          # the actor's actions exactly
        assert set_value(cli, "/executor", "noise.kind", string("gaussian")).successful
        assert set_double(cli, "/executor", "noise.sigma", 0.5).successful
        assert max(run()) > 0.05                          # perturbed again
        frozen = set_value(cli, "/executor", "task.observation", string("thesis"))
        assert not frozen.successful and "read-only" in frozen.reason
        why = describe(cli, "/executor", "task.observation").description
        assert "Default 'tilt_motion' (config/executor.yaml)" in why, why
        assert "the learner's networks" in why, why
    log = (stack.log_dir / "executor.log").read_text()
    assert "parameter noise.kind: 'gaussian' -> 'none', applies from the next episode" in log, log
    assert "parameter noise.sigma: 0.3 -> 0.5" in log, log
    assert len(actors) == 1                              # one actor all along: v0
