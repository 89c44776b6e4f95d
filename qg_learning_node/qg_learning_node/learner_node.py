"""The ``learner`` node: QG-DDPG on the transitions the executor publishes.

With ``learner.schedule: cycle`` (the thesis) it trains ``iterations_per_cycle`` times every
``cycle_steps`` transitions, in the transition callback; with ``async`` a training thread keeps
training while the robot moves (``updates_per_step`` per transition, see ``learner_core``).
Each time it publishes the new actor (latched, so a restarted executor gets it at once) and its
diagnostics. At the end of
every episode it checkpoints networks, optimizers, Q-Graph and replay memory; with
``resume: true`` a restarted learner continues from the last checkpoint. Only episodes it saw
running are checkpointed: the latched final status of an episode that ended before it started
is not news. Its heartbeat has a callback group of its own, so a long training cycle never
silences it (the executor would run degraded).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from qg_common import topics
from qg_common.node_parameters import declare_parameters
from qg_common.node_runtime import run_nodes
from qg_common.params import POSITIVE, ParameterSection, runs_dir
from qg_common.topics import LATCHED, RELIABLE_DEEP
from qg_interfaces.msg import ActorParameters, EpisodeStatus, LearnerDiagnostics, Transition
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from qg_learning_node.conversions import actor_to_msg
from qg_learning_node.executor.episode import TransitionRecord
from qg_learning_node.learner.learner_params import learner_config_from_params
from qg_learning_node.executor.peg_task import PEG_ACTION_DIM, PEG_STATE_DIM
from qg_learning_node.executor.residual_task import ACTION_DIM, state_dim
from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore

CHECKPOINT_NAME = "learner.pt"
#: [s] how long to wait for the last transitions of an ended episode before checkpointing.
CHECKPOINT_GRACE = 3.0


def task_dims(observation: str) -> tuple[int, int]:
    """(state, action) sizes of the executor's task, from the learner's ``observation``."""
    if observation == "peg":
        return PEG_STATE_DIM, PEG_ACTION_DIM
    return state_dim(observation), ACTION_DIM


@dataclass(frozen=True)
class LearnerNodeConfig:
    """The learner node's own parameters (``config/learner.yaml``, top level).

    :param observation: the executor's ``task.observation`` (``thesis``, ``tilt``), or ``peg``
        for the peg task; sets the networks' input and output sizes.
    :param checkpoint_dir: folder of ``learner.pt``; "" = ``<runs>/checkpoints``.
    :param resume: restore networks, optimizers, graph and replay at start.
    :param robot_namespaces: the robots whose ``<ns>/transitions`` and ``<ns>/episode_status``
        this learner learns from; "" is the learner's own namespace (one robot, the default).
        ``qgl up --robots 2`` gives ``[robot0, robot1]`` (see ``cli/fleet.py``).
    """
    observation: str = "thesis"
    checkpoint_dir: str = ""
    resume: bool = False
    robot_namespaces: tuple[str, ...] = ("",)


#: The learner's parameters, all read-only: a running learner keeps its networks' settings.
#: (ROS parameters cannot be null: 0 / [] stand for "none", see ``learner/learner_params.py``.)
LEARNER_SECTIONS = (
    ParameterSection("", LearnerNodeConfig),
    ParameterSection("learner", LearnerConfig, ranges={
        "replay_capacity": (0, 1_000_000_000), "iterations_per_cycle": (1, 1_000_000),
        "cycle_steps": (1, 1_000_000), "batch_size": (1, 1_000_000),
        "census_every": (1, 1_000_000), "graph_resolution": (0.0, 2.0),
        "updates_per_step": POSITIVE, "publish_every": (1, 1_000_000),
        "ddpg.gamma": (0.0, 1.0), "ddpg.critic_lr": (0.0, 1.0), "ddpg.actor_lr": (0.0, 1.0),
        "ddpg.tau": (0.0, 1.0), "ddpg.he_horizon": (1, 100_000), "ddpg.he_lambda": POSITIVE}),
)


class LearnerNode(Node):
    """Keeps the Q-Graph and replay memory, trains every cycle, publishes the actor."""

    def __init__(self) -> None:
        super().__init__(topics.LEARNER_NODE)
        p = declare_parameters(self, LEARNER_SECTIONS, (("qg_learning_node", "learner.yaml"),))
        config = learner_config_from_params(p["learner"])
        self.checkpoint = Path(p["checkpoint_dir"] or runs_dir() / "checkpoints") / CHECKPOINT_NAME
        if p["resume"] and self.checkpoint.is_file():
            self.core = LearnerCore.load(self.checkpoint)
            self.get_logger().info(f"resumed from {self.checkpoint}: {self.core.steps} "
                                   f"transitions, actor v{self.core.actor_version}")
        else:
            self.core = LearnerCore(config, *task_dims(p["observation"]))
        self.lock = threading.Lock()
        self.received: dict[str, int] = {}        # transitions per episode id
        self.seen_running: set[str] = set()       # episodes with a status before their end
        self.pending_checkpoint: dict[str, tuple[int, float]] = {}  # id -> (final steps, ended at)
        self.checkpointed: set[str] = set()
        self.last_diagnostics: dict = {}

        self.actor_pub = self.create_publisher(ActorParameters, topics.ACTOR_PARAMETERS, LATCHED)
        self.diagnostics_pub = self.create_publisher(LearnerDiagnostics, topics.LEARNER_DIAGNOSTICS,
                                                     topics.COMMAND_QOS)
        group = MutuallyExclusiveCallbackGroup()
        robots = [namespace.strip("/") for namespace in p["robot_namespaces"]]
        if len(set(robots)) != len(robots):     # each transition would count twice
            raise ValueError(f"robot_namespaces names a robot twice: {p['robot_namespaces']}")
        for robot in robots:
            self.create_subscription(Transition, topics.robot_topic(robot, topics.TRANSITIONS),
                                     partial(self._on_transition, robot=robot), RELIABLE_DEEP,
                                     callback_group=group)
            self.create_subscription(EpisodeStatus,
                                     topics.robot_topic(robot, topics.EPISODE_STATUS),
                                     self._on_status, LATCHED, callback_group=group)
        self.create_timer(0.5, self._checkpoint_pending, callback_group=group)
        # A heartbeat, so the executor knows the learner is alive while it trains.
        self.create_timer(0.5, self._publish_diagnostics,
                          callback_group=MutuallyExclusiveCallbackGroup())
        self._publish_actor()

    def _on_transition(self, msg: Transition, robot: str = "") -> None:
        t = TransitionRecord.from_message(msg)
        with self.lock:
            cycle_due = self.core.add_transition(t.state, t.action, t.reward, t.next_state,
                                                 t.terminal, robot)
            self.received[t.episode_id] = self.received.get(t.episode_id, 0) + 1
            cycle_due = cycle_due and self.core.config.schedule == "cycle"
            if cycle_due:
                self.last_diagnostics = self.core.train_cycle()
        if cycle_due:
            self._publish_actor()
            self._publish_diagnostics()
        self._maybe_checkpoint(t.episode_id)

    def train_while_running(self, stop: threading.Event) -> None:
        """The ``async`` schedule's training thread: train whenever updates are due."""
        while not stop.is_set():
            with self.lock:
                due = self.core.training_due()
                if due:
                    self.last_diagnostics = self.core.train_cycle()
            if due:
                self._publish_actor()
                self._publish_diagnostics()
            else:
                stop.wait(0.002)

    def _on_status(self, msg: EpisodeStatus) -> None:
        if not msg.episode_id or msg.mode != "train":
            return
        if msg.state not in ("done", "aborted"):
            self.seen_running.add(msg.episode_id)
            return
        seen = msg.episode_id in self.seen_running or msg.episode_id in self.received
        if seen and msg.episode_id not in self.checkpointed:
            self.pending_checkpoint.setdefault(msg.episode_id, (int(msg.step), time.monotonic()))
            self._maybe_checkpoint(msg.episode_id)

    def _checkpoint_pending(self) -> None:
        for episode_id in list(self.pending_checkpoint):
            self._maybe_checkpoint(episode_id)

    def _maybe_checkpoint(self, episode_id: str) -> None:
        """Checkpoint once every transition of the ended episode has arrived.

        Transitions published while this learner was down never arrive; after
        ``CHECKPOINT_GRACE`` seconds the checkpoint is written without them.
        """
        pending = self.pending_checkpoint.get(episode_id)
        if pending is None:
            return
        final, ended_at = pending
        got = self.received.get(episode_id, 0)
        if got < final:
            if time.monotonic() - ended_at < CHECKPOINT_GRACE:
                return
            self.get_logger().warning(f"{episode_id}: {final - got} of {final} transitions never "
                                      "arrived (learner was down?); checkpointing without them")
        del self.pending_checkpoint[episode_id]
        self.checkpointed.add(episode_id)
        self.checkpoint.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.checkpoint.with_suffix(".tmp")
        with self.lock:
            self.core.save(tmp)
        tmp.replace(self.checkpoint)          # atomic: a crash never leaves half a checkpoint
        self.get_logger().info(f"checkpoint after {episode_id}: {self.core.steps} transitions")

    def _publish_actor(self) -> None:
        with self.lock:
            msg = actor_to_msg(self.core.actor_version, self.core.agent.actor_tensors())
        self.actor_pub.publish(msg)

    def _publish_diagnostics(self) -> None:
        d = self.last_diagnostics
        msg = LearnerDiagnostics(actor_version=self.core.actor_version,
                                 updates=self.core.updates,
                                 transitions=self.core.steps)
        msg.stamp = self.get_clock().now().to_msg()
        for key in ("critic_loss", "actor_loss", "mean_q", "frac_raised_lower",
                    "frac_lowered_upper", "frac_outside_range"):
            setattr(msg, key, float(d.get(key, 0.0)))
        msg.graph_transitions = len(self.core.graph) if self.core.graph is not None else 0
        for key in ("directly_connected", "connected", "disconnected", "loose_end"):
            setattr(msg, key, int(d.get(key, 0)))
        self.diagnostics_pub.publish(msg)


def _start_training_thread(nodes: list[Node]) -> Callable[[], None]:
    """The ``async`` schedule trains in its own thread; ``cycle`` needs none."""
    node = nodes[0]
    assert isinstance(node, LearnerNode)
    if node.core.config.schedule != "async":
        return lambda: None
    stop = threading.Event()
    thread = threading.Thread(target=node.train_while_running, args=(stop,),
                              name="learner-training", daemon=True)
    thread.start()

    def stop_training() -> None:
        stop.set()
        thread.join(timeout=5.0)

    return stop_training


def main(args: list[str] | None = None) -> int:
    return run_nodes([LearnerNode], args, background=_start_training_thread)


if __name__ == "__main__":
    raise SystemExit(main())
