"""The ``learner`` node: QG-DDPG on the transitions the executor publishes.

It builds its networks for the executor's task: the executor owns the state definition and
publishes the sizes on its latched ``executor/task_spec``, so a learner started before or after
it learns them from the one place they are set (a resumed learner checks its checkpoint's
against them; a robot whose task does not fit is logged and its transitions are not used). Until
then it has no networks and sends no heartbeat, so the executor does not count on it yet. A
robot's transitions that come before its task (a restarted learner hears the next episode's
first transition before the latched task, which discovery brings later) are held and taken once
the task arrives: a suite run under load lost one that way.

With ``learner.schedule: cycle`` (the thesis) it trains ``iterations_per_cycle`` times every
``cycle_steps`` transitions, in the transition callback; with ``async`` a training thread keeps
training while the robot moves (``updates_per_step`` per transition, see ``learner_core``).
Each time it publishes the new actor (latched, so a restarted executor gets it at once) and its
diagnostics. At the end of
every episode that ended ``done`` (training or test: it learns from both) it checkpoints
networks, optimizers, Q-Graph and replay memory, then writes ``learner.json`` beside the
checkpoint (the episode it follows, the transitions in it), which a training run's journal
waits for (``qg_bringup/run_journal.py``); with ``resume: true`` a restarted learner continues from
the last checkpoint. An ``aborted`` episode is not checkpointed: a training run reruns its slot,
and a learner restarted from the checkpoint then holds exactly the completed episodes'
transitions (one that runs on keeps the aborted part in memory, and in its next checkpoint).
Only episodes it saw running are checkpointed: the latched final status of an episode that
ended before it started is not news. Its heartbeat has a callback group of its own, so a long training cycle never
silences it (the executor would run degraded). ``ros2 param set`` changes the training settings
of ``learner_config.RUNTIME_FIELDS`` from the next cycle on. PyTorch is loaded only to build
the networks, so a learner whose parameters are refused says so within a second.
"""
from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from qg_common import topics
from qg_common.node_parameters import declare_parameters, on_parameter_change
from qg_common.node_runtime import run_nodes
from qg_common.params import runs_dir
from qg_common.topics import LATCHED, RELIABLE_DEEP
from qg_interfaces.msg import (
    ActorParameters,
    EpisodeStatus,
    LearnerDiagnostics,
    TaskSpec,
    Transition,
)
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from qg_learning_node.conversions import actor_to_msg
from qg_learning_node.executor.episode import TransitionRecord
from qg_learning_node.learner.learner_config import with_runtime_settings
from qg_learning_node.learner.learner_params import LEARNER_SECTIONS, learner_config_from_params

if TYPE_CHECKING:     # torch is loaded only to build the networks: see _core_class
    from qg_learning_node.learner.learner_core import LearnerCore

CHECKPOINT_NAME = "learner.pt"
#: Beside the checkpoint: what it holds (the episode it was written after, its transitions).
CHECKPOINT_INFO_NAME = "learner.json"
#: [s] how long an ended episode may go without one of its transitions taken before the
#: checkpoint is written without the rest (they were published while the learner was down).
CHECKPOINT_GRACE = 3.0
#: [s] at most one warning this often about transitions the learner cannot use.
WARN_PERIOD = 5.0
#: Transitions held per robot until its executor's task arrives (more are not used).
EARLY_LIMIT = 10_000


def _core_class() -> type[LearnerCore]:
    """``LearnerCore``, imported when the networks are built: with it comes PyTorch (1.5 s of
    CPU), so a learner whose parameters are refused, or that never gets a task, never loads
    it."""
    from qg_learning_node.learner.learner_core import LearnerCore
    return LearnerCore


class LearnerNode(Node):
    """Keeps the Q-Graph and replay memory, trains every cycle, publishes the actor."""

    def __init__(self) -> None:
        super().__init__(topics.LEARNER_NODE)
        p = declare_parameters(self, LEARNER_SECTIONS, (("qg_learning_node", "learner.yaml"),))
        self.config = learner_config_from_params(p["learner"])
        self.checkpoint = Path(p["checkpoint_dir"] or runs_dir() / "checkpoints") / CHECKPOINT_NAME
        self.core: LearnerCore | None = None      # built for the executor's task_spec
        if p["resume"] and self.checkpoint.is_file():
            self.core = _core_class().load(self.checkpoint)
            self.get_logger().info(f"resumed from {self.checkpoint}: {self.core.steps} "
                                   f"transitions, actor v{self.core.actor_version}")
        self.lock = threading.Lock()
        self.tasks: dict[str, TaskSpec] = {}      # robot -> its executor's task, if it fits
        self.refused: dict[str, str] = {}         # robot -> why its transitions are not used
        self.early: dict[str, list[Transition]] = {}   # robot -> transitions before its task
        self.last_warning = -float("inf")
        self.received: dict[str, int] = {}        # transitions per episode id
        self.last_taken: dict[str, float] = {}    # episode id -> when its last one was taken
        self.seen_running: set[str] = set()       # episodes with a status before their end
        self.pending_checkpoint: dict[str, tuple[int, float]] = {}  # id -> (final steps, ended at)
        self.ended: dict[str, dict[str, Any]] = {}     # id -> its final status, for learner.json
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
            self.create_subscription(TaskSpec, topics.robot_topic(robot, topics.TASK_SPEC),
                                     partial(self._on_task, robot=robot), LATCHED,
                                     callback_group=group)
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
        on_parameter_change(self, self._reconfigure, "from the next training cycle")
        if self.core is not None:
            self._publish_actor()

    def _on_task(self, msg: TaskSpec, robot: str = "") -> None:
        """The executor of ``robot`` says what its states and actions are: build the networks
        for them (the first robot to say so), or check that they fit the networks built."""
        who = f"robot {robot!r}" if robot else "the executor"
        dims = (int(msg.state_dim), int(msg.action_dim))
        with self.lock:
            built = self.core is None
            if built:
                self.core = _core_class()(self.config, *dims)
            have = (self.core.state_dim, self.core.action_dim)
            if have != dims:
                self.refused[robot] = (f"{who} runs the {msg.kind} task ({msg.observation}) with "
                                       f"{dims[0]}-D states and {dims[1]}-D actions; this "
                                       f"learner's networks take {have[0]}-D and {have[1]}-D")
                self.tasks.pop(robot, None)
            else:
                self.refused.pop(robot, None)
                self.tasks[robot] = msg
        early = self.early.pop(robot, [])
        if robot in self.refused:
            self.get_logger().error(f"{self.refused[robot]}: its transitions are not used"
                                    + (f" ({len(early)} held ones dropped)" if early else ""))
            return
        self.get_logger().info(f"task of {who}: {msg.kind}, observation {msg.observation}, "
                               f"{dims[0]}-D states, {dims[1]}-D actions"
                               + ("; networks built for it" if built else "")
                               + (f"; taking the {len(early)} transition(s) that came before it"
                                  if early else ""))
        if built:
            self._publish_actor()
            self._publish_diagnostics()
        for held in early:                   # in their order, before any later one
            self._on_transition(held, robot)

    def _usable(self, t: TransitionRecord, robot: str) -> bool:
        """Whether the transition fits the networks; a (throttled) error says why not."""
        reason = self.refused.get(robot)
        if reason is None and robot not in self.tasks:
            reason = "no executor/task_spec heard from its executor yet"
        if reason is None and (len(t.state), len(t.action)) != (self.core.state_dim,
                                                                self.core.action_dim):
            reason = (f"a {len(t.state)}-D state and {len(t.action)}-D action; the networks "
                      f"take {self.core.state_dim}-D and {self.core.action_dim}-D")
        if reason is not None and time.monotonic() - self.last_warning > WARN_PERIOD:
            self.last_warning = time.monotonic()
            self.get_logger().error(f"transition of {t.episode_id} not used: {reason}")
        return reason is None

    def _reconfigure(self, params: dict[str, Any]) -> None:
        """``ros2 param set`` of a training setting: taken between two cycles (the lock is
        held while one trains). rclpy has refused read-only ones already."""
        config = learner_config_from_params(params["learner"])
        with self.lock:
            if self.core is not None:
                self.core.reconfigure(with_runtime_settings(self.core.config, config))
            self.config = config

    def _on_transition(self, msg: Transition, robot: str = "") -> None:
        t = TransitionRecord.from_message(msg)
        with self.lock:
            if robot not in self.tasks and robot not in self.refused:
                held = self.early.setdefault(robot, [])
                if len(held) < EARLY_LIMIT:     # taken when the task comes (``_on_task``)
                    held.append(msg)
                    return
            if not self._usable(t, robot):
                return
            cycle_due = self.core.add_transition(t.state, t.action, t.reward, t.next_state,
                                                 t.terminal, robot)
            self.received[t.episode_id] = self.received.get(t.episode_id, 0) + 1
            cycle_due = cycle_due and self.core.config.schedule == "cycle"
            if cycle_due:
                self.last_diagnostics = self.core.train_cycle()
            # After the cycle: a slow cycle is the learner busy, not transitions lost.
            self.last_taken[t.episode_id] = time.monotonic()
        if cycle_due:
            self._publish_actor()
            self._publish_diagnostics()
        self._maybe_checkpoint(t.episode_id)

    def train_while_running(self, stop: threading.Event) -> None:
        """The ``async`` schedule's training thread: train whenever updates are due."""
        while not stop.is_set():
            with self.lock:
                due = self.core is not None and self.core.training_due()
                if due:
                    self.last_diagnostics = self.core.train_cycle()
            if due:
                self._publish_actor()
                self._publish_diagnostics()
            else:
                stop.wait(0.002)

    def _on_status(self, msg: EpisodeStatus) -> None:
        if not msg.episode_id or msg.mode not in ("train", "test"):
            return
        if msg.state not in ("done", "aborted"):
            self.seen_running.add(msg.episode_id)
            return
        if msg.state == "aborted":          # not a completed episode: its slot is rerun
            if msg.episode_id in self.seen_running:
                self.seen_running.discard(msg.episode_id)
                self.get_logger().info(f"{msg.episode_id} aborted ({msg.message}): not "
                                       "checkpointed")
            return
        seen = msg.episode_id in self.seen_running or msg.episode_id in self.received
        if seen and msg.episode_id not in self.checkpointed:
            self.pending_checkpoint.setdefault(msg.episode_id, (int(msg.step), time.monotonic()))
            self.ended.setdefault(msg.episode_id, {
                "episode_id": msg.episode_id, "mode": msg.mode, "state": msg.state,
                "steps": int(msg.step), "episode_return": float(msg.episode_return),
                "success": bool(msg.success), "initial_pose": int(msg.initial_pose)})
            self._maybe_checkpoint(msg.episode_id)

    def _checkpoint_pending(self) -> None:
        for episode_id in list(self.pending_checkpoint):
            self._maybe_checkpoint(episode_id)

    def _maybe_checkpoint(self, episode_id: str) -> None:
        """Checkpoint once every transition of the ended episode has arrived.

        Transitions published while this learner was down never arrive; once
        ``CHECKPOINT_GRACE`` seconds have passed since the episode's end and since the last of its
        transitions was taken, the checkpoint is written without them. A learner that is only
        slow (training, or on a loaded machine) is still taking them and is waited for: with the
        grace counted from the end alone, a loaded test machine checkpointed 20 of 40
        transitions while the rest were still queued.
        """
        pending = self.pending_checkpoint.get(episode_id)
        if pending is None or self.core is None:
            return
        final, ended_at = pending
        got = self.received.get(episode_id, 0)
        if got < final:
            quiet_since = max(ended_at, self.last_taken.get(episode_id, ended_at))
            if time.monotonic() - quiet_since < CHECKPOINT_GRACE:
                return
            self.get_logger().warning(f"{episode_id}: {final - got} of {final} transitions never "
                                      "arrived (learner was down?); checkpointing without them")
        del self.pending_checkpoint[episode_id]
        self.checkpointed.add(episode_id)
        self.checkpoint.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.checkpoint.with_suffix(".tmp")
        with self.lock:
            self.core.save(tmp)
            info = {**self.ended.pop(episode_id, {"episode_id": episode_id}),
                    "received": got, "transitions": self.core.steps,
                    "actor_version": self.core.actor_version, "updates": self.core.updates,
                    "saved_at": time.time()}
        tmp.replace(self.checkpoint)          # atomic: a crash never leaves half a checkpoint
        _write_json_atomically(self.checkpoint.with_name(CHECKPOINT_INFO_NAME), info)
        self.get_logger().info(f"checkpoint after {episode_id}: {self.core.steps} transitions")

    def _publish_actor(self) -> None:
        with self.lock:
            msg = actor_to_msg(self.core.actor_version, self.core.agent.actor_tensors())
        self.actor_pub.publish(msg)

    def _publish_diagnostics(self) -> None:
        if self.core is None:             # no networks yet: nothing to count on
            return
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


def _write_json_atomically(path: Path, data: dict[str, Any]) -> None:
    """``path`` holds ``data`` whole or its old content, whatever stops the process when."""
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(path)


def _start_training_thread(nodes: list[Node]) -> Callable[[], None]:
    """The ``async`` schedule trains in its own thread; ``cycle`` needs none."""
    node = nodes[0]
    assert isinstance(node, LearnerNode)
    if node.config.schedule != "async":
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
