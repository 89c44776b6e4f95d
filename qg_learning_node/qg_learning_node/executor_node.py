"""The ``executor`` node: runs episodes of the residual force policy on request.

At start it publishes its task on the latched ``executor/task_spec`` (kind, observation, state
and action sizes): the executor owns the state definition, and the learner builds its networks
for it. State machine idle -> resetting -> running -> done (or aborted), published on
``/episode_status``. One RL step: choose the action (local actor from the latest
``/actor_parameters``, plus exploration noise in training), send the wrench setpoint, wait for
the robot's at-rest event, turn it into (s', r, terminal), publish the transition (reliable QoS).
When the learner goes silent the robot stays safe: the zero residual is sent, the status says
``degraded``, and the episode goes on. SIGINT or SIGTERM mid-episode aborts the episode (reason
``shutdown``): zero residual and final status go out before the node is destroyed.
"""
from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

from qg_common import topics
from qg_common.conversions import setpoint_msg, start_pose_request
from qg_common.node_parameters import declare_parameters, on_parameter_change
from qg_common.node_runtime import run_nodes
from qg_common.params import ParameterSection
from qg_common.peg_task import PegCell
from qg_common.retried_requests import answered_once
from qg_common.shaft_task import ShaftTaskGeometry
from qg_common.topics import LATCHED, RELIABLE_DEEP
from qg_common.types import WrenchSetpoint as Setpoint
from qg_interfaces.msg import (
    ActorParameters,
    AtRest,
    EpisodeStatus,
    LearnerDiagnostics,
    TaskSpec,
    Transition,
    WrenchSetpoint,
)
from qg_interfaces.srv import MoveToStart, StartEpisode, StopEpisode
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node

from qg_learning_node.conversions import (
    actor_tensors_from_msg,
    observation_from_msg,
    transition_to_msg,
)
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.episode_id import episode_id as make_episode_id
from qg_learning_node.executor.episode_request import N_POSES, EpisodeRequest
from qg_learning_node.executor.noise import ActionNoise, NoiseConfig
from qg_learning_node.executor.parameters import (
    CELL_SECTIONS,
    EXECUTOR_SECTIONS,
    TASK_CHOICE_SECTION,
    TASK_SECTIONS,
    ExecutorConfig,
)
from qg_learning_node.executor.peg_task import PegTask, PegTaskConfig
from qg_learning_node.executor.residual_task import ResidualTask, TaskConfig
from qg_learning_node.executor.stall_recovery import StallRecovery, StallRecoveryConfig
from qg_learning_node.executor.transition_readers import learner_reads_transitions
from qg_learning_node.learner.actor_mlp import ActorMLP
from qg_learning_node.policy_file import Policy, frozen_policy

#: [s] how long shutdown waits for the episode thread to abort the episode.
SHUTDOWN_GRACE = 2.0
#: [s] a reset unanswered this long is asked for again (same request id: no second reset).
RESET_RETRY = 5.0


class EpisodeAborted(Exception):
    """The episode cannot go on (stop request, robot gone, reset refused)."""


#: Each task kind's parameter section (``executor/parameters.py``), how its task is built from
#: the section's values and its cell's, and the ``observation`` it tells the learner
#: (``TaskSpec``).
TASKS: dict[str, tuple[ParameterSection, Callable[[dict[str, Any], dict[str, Any]], Any],
                       Callable[[Any], str]]] = {
    "residual": (TASK_SECTIONS["residual"],
                 lambda values, cell: ResidualTask(TaskConfig.from_dict(values),
                                                   ShaftTaskGeometry.from_dict(cell)),
                 lambda task: task.config.observation),
    "peg": (TASK_SECTIONS["peg"],
            lambda values, cell: PegTask(PegTaskConfig.from_dict(values), PegCell.from_dict(cell)),
            lambda task: "peg"),
}


class ExecutorNode(Node):
    """Episodes by service call; one episode at a time, run on its own thread."""

    def __init__(self) -> None:
        super().__init__("executor")
        self.task_kind = declare_parameters(self, [TASK_CHOICE_SECTION])["task"]["kind"]
        if self.task_kind not in TASKS:
            raise ValueError(f"task.kind must be one of {sorted(TASKS)}, got {self.task_kind!r}")
        self.task_section, self.make_task, observation = TASKS[self.task_kind]
        self.cell_section, cell_file = CELL_SECTIONS[self.task_kind]
        params = declare_parameters(
            self, [*EXECUTOR_SECTIONS, self.task_section, self.cell_section],
            (("qg_learning_node", "executor.yaml"), cell_file))
        self._configure(params)
        # policy.file: a frozen actor, checked against this task and robot now (a file that
        # does not fit stops the start with the reasons, exit code 2), never a learner's.
        self.frozen: Policy | None = frozen_policy(params["policy"]["file"],
                                                   params["policy"]["robot"], self.task_kind,
                                                   self.task)
        on_parameter_change(self, self._configure, "from the next episode (timeouts: next step)")

        # The learner builds its networks from this: the state is set here, and only here.
        spec = TaskSpec(kind=self.task_kind, observation=observation(self.task),
                        state_dim=self.task.state_dim, action_dim=self.task.action_dim)
        self.task_spec_pub = self.create_publisher(TaskSpec, topics.TASK_SPEC, LATCHED)
        self.task_spec_pub.publish(spec)
        self.get_logger().info(f"task {spec.kind}, observation {spec.observation}: "
                               f"{spec.state_dim}-D states, {spec.action_dim}-D actions")
        self.status_pub = self.create_publisher(EpisodeStatus, topics.EPISODE_STATUS, LATCHED)
        self.transition_pub = self.create_publisher(Transition, topics.TRANSITIONS, RELIABLE_DEEP)
        self.setpoint_pub = self.create_publisher(WrenchSetpoint, topics.WRENCH_SETPOINT,
                                                  topics.COMMAND_QOS)
        callbacks = ReentrantCallbackGroup()
        if self.frozen is None:
            self.create_subscription(ActorParameters, topics.ACTOR_PARAMETERS, self._on_actor,
                                     LATCHED, callback_group=callbacks)
        self.heartbeats = self.create_subscription(LearnerDiagnostics, topics.LEARNER_DIAGNOSTICS,
                                                   self._on_learner, 10, callback_group=callbacks)
        self.create_subscription(AtRest, topics.EE_AT_REST, self._on_at_rest, 10,
                                 callback_group=callbacks)
        self.start_client = self.create_client(MoveToStart, topics.MOVE_TO_START,
                                               callback_group=callbacks)
        services = MutuallyExclusiveCallbackGroup()
        self.create_service(StartEpisode, topics.START_EPISODE,
                            answered_once(self._on_start, "start", self.get_logger().info),
                            callback_group=services)
        self.create_service(StopEpisode, topics.STOP_EPISODE, self._on_stop,
                            callback_group=services)
        self.create_timer(0.5, self._publish_status, callback_group=callbacks)

        self.lock = threading.Lock()
        self.actor: ActorMLP | Policy | None = self.frozen
        self.actor_version = 0
        if self.frozen is not None:
            self.actor_version = int(self.frozen.spec.provenance.get("actor_version", 0))
            self.get_logger().info(f"frozen policy {params['policy']['file']}: "
                                   f"{self.frozen.spec.describe()}; no learner is waited for")
        self.last_learner_time = -float("inf")
        self.at_rest: dict[int, AtRest] = {}
        self.at_rest_event = threading.Event()
        self.seq = 0
        self.episode: Episode | None = None
        #: The running test episode's stall recovery (``stall_recovery.enabled``), else None.
        self.recovery: StallRecovery | None = None
        self.state = "idle"
        self.message = ""
        self.degraded = False
        self.episodes_started = 0
        self.stop_requested = threading.Event()
        self.stop_reason = ""
        self.worker: threading.Thread | None = None

    def _configure(self, params: dict[str, Any]) -> None:
        """Build the task, noise and timing from the parameters (all validated before any is
        applied); at start and on ``ros2 param set``. A running episode keeps its task."""
        values = dict(params[self.task_section.prefix])
        values.pop("kind", None)          # task.kind chose the section (residual: the same)
        task = self.make_task(values, params[self.cell_section.prefix])
        noise = NoiseConfig.from_dict(params["noise"])
        config = ExecutorConfig.from_dict(params)
        self.task, self.noise_config, self.config = task, noise, config
        self.recovery_config = StallRecoveryConfig.from_dict(params["stall_recovery"])

    # --- inputs ---------------------------------------------------------------------------
    def _on_actor(self, msg: ActorParameters) -> None:
        try:
            actor = ActorMLP.from_tensors(actor_tensors_from_msg(msg))
        except (ValueError, KeyError) as exc:
            self.get_logger().error(f"ignoring malformed actor parameters v{msg.version}: {exc}")
            return
        if actor.input_dim != self.task.state_dim:
            self.get_logger().error(
                f"ignoring actor v{msg.version}: it takes {actor.input_dim}-D states, the "
                f"{self.task_kind} task's are {self.task.state_dim}-D (a learner of another "
                f"task, or one resumed from another task's checkpoint)")
            return
        with self.lock:
            self.actor, self.actor_version = actor, int(msg.version)
        self._heard_from_learner()

    def _on_learner(self, msg: LearnerDiagnostics) -> None:
        self._heard_from_learner()

    def _heard_from_learner(self) -> None:
        """A sign of life: a restarted learner ends ``degraded`` at once, not at the next step
        (or, between episodes, the next episode)."""
        self.last_learner_time = time.monotonic()
        self._set_degraded(False)

    def _on_at_rest(self, msg: AtRest) -> None:
        with self.lock:
            self.at_rest[int(msg.seq)] = msg
        self.at_rest_event.set()

    def _wait_until(self, condition: Callable[[], bool], timeout: float,
                    poll: float = 0.01) -> bool:
        """Poll ``condition`` every ``poll`` seconds (the episode thread; callbacks run
        elsewhere) until it holds, for at most ``timeout`` seconds or until a stop is
        requested; whether it held."""
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() >= deadline or self.stop_requested.wait(poll):
                return False
        return True

    def _await_learner(self, timeout: float) -> None:
        """Give a learner not heard from lately ``timeout`` seconds to speak: one never heard
        from may not be discovered yet, and a restarted one is often up (the run that restarted
        it has heard it) before this process has discovered it. Its transitions would be lost
        to an episode that ran degraded meanwhile."""
        self._wait_until(self.learner_alive, timeout)

    def _await_learner_reading_transitions(self, timeout: float) -> None:
        """Wait until the learner, once heard from, also reads our transitions.

        Discovery runs per direction: a (re)started learner's heartbeat can reach us seconds
        before our transitions publisher has matched its subscription on a loaded host, and a
        reliable publisher delivers nothing to a reader it has not matched: the episode's
        first transitions would be lost to the learner. A restarted learner's predecessor
        leaves its reader in the graph, matched, for seconds, so the readers are counted per
        process (``transition_readers.py``). After ``timeout`` the episode runs anyway, with a
        warning.
        """
        if not self.learner_alive():
            return
        topic = self.transition_pub.topic_name

        def learner_matched() -> bool:
            return learner_reads_transitions(
                self.get_subscriptions_info_by_topic(topic),
                self.get_publishers_info_by_topic(self.heartbeats.topic_name),
                self.transition_pub.get_subscription_count())

        if not self._wait_until(learner_matched, timeout):
            self.get_logger().warning(f"the learner is alive but not matched on {topic} after "
                                      f"{timeout:.0f} s: it may miss this episode's transitions")

    def learner_alive(self) -> bool:
        return time.monotonic() - self.last_learner_time < self.config.learner_timeout

    # --- services -------------------------------------------------------------------------
    def _on_start(self, request: StartEpisode.Request,
                  response: StartEpisode.Response) -> StartEpisode.Response:
        """Start an episode, or refuse. A retry with the same ``request_id`` (its reply was
        lost) gets the first reply back, and no second episode starts (``answered_once``)."""
        try:
            req = EpisodeRequest(request.mode, request.initial_pose, request.seed, request.reward)
        except ValueError as exc:
            response.success, response.message = False, str(exc)
            return response
        if self.worker is not None and self.worker.is_alive():
            response.success = False
            response.message = f"episode {self.episode.episode_id if self.episode else ''} " \
                               "is still running: stop it first (/executor/stop_episode)"
            return response
        # A robot process that has just come up may not be discovered yet: give it a moment.
        if not self.start_client.wait_for_service(timeout_sec=self.config.robot_grace):
            response.success = False
            response.message = "the robot side is not up (/move_to_start unavailable): start " \
                               "`robot_bridge_node robot`"
            return response
        index = self.episodes_started
        self.episodes_started += 1
        pose = req.initial_pose if req.initial_pose >= 0 else index % N_POSES
        reward = req.reward or self.task.config.reward
        # Under many robots the id names its robot (robot0_..., executor/episode_id.py).
        episode_id = make_episode_id(self.get_namespace(), index, req.mode, pose)
        seed = req.seed if req.seed != 0 else 1000 + index
        self.recovery = (StallRecovery(self.recovery_config, self.task.action_dim, seed,
                                       self.noise_config, self.task.progress_dims)
                         if req.mode == "test" and self.recovery_config.enabled else None)
        self.episode = Episode(episode_id, req.mode, pose, reward, self.task,
                               ActionNoise(self.noise_config, self.task.action_dim, seed))
        self.stop_requested.clear()
        self._set_state("resetting", f"moving to start {pose}")
        self.worker = threading.Thread(target=self._run_episode, args=(self.episode,),
                                       name="episode", daemon=True)
        self.worker.start()
        response.success, response.message, response.episode_id = True, "started", episode_id
        return response

    def _on_stop(self, request: StopEpisode.Request,
                 response: StopEpisode.Response) -> StopEpisode.Response:
        if self.worker is None or not self.worker.is_alive() or self.episode is None:
            response.success, response.message = False, "no episode is running"
            return response
        reason = f"stop requested: {request.reason}" if request.reason else "stop requested"
        self._stop_episode(reason, timeout=self.config.step_timeout + 1.0)
        response.success = True
        response.episode_id = self.episode.episode_id
        response.message = f"aborted: {request.reason}" if request.reason else "aborted"
        return response

    def _stop_episode(self, reason: str, timeout: float) -> bool:
        """Make the running episode abort with ``reason``; True once its thread has ended
        (within ``timeout`` seconds)."""
        self.stop_reason = reason
        self.stop_requested.set()
        self.at_rest_event.set()
        assert self.worker is not None
        self.worker.join(timeout=timeout)
        return not self.worker.is_alive()

    def abort_on_shutdown(self) -> None:
        """Abort a running episode while the node can still publish (``run_nodes`` calls this
        at SIGINT/SIGTERM, before it destroys the node): the episode thread sends the zero
        residual and the final ``aborted`` status; transient-local readers (recorder, learner)
        are given a moment to have that status before the publisher goes."""
        episode = self.episode
        if self.worker is None or not self.worker.is_alive() or episode is None:
            return
        if not self._stop_episode("shutdown", timeout=SHUTDOWN_GRACE):
            self.get_logger().error(f"shutdown: episode {episode.episode_id} did not stop "
                                    f"within {SHUTDOWN_GRACE} s")
            return
        self.status_pub.wait_for_all_acked(Duration(seconds=1.0))
        self.setpoint_pub.wait_for_all_acked(Duration(seconds=1.0))
        self.get_logger().info(f"shutdown: episode {episode.episode_id} aborted at step "
                               f"{episode.step}, zero residual sent")

    # --- the episode ----------------------------------------------------------------------
    def _run_episode(self, episode: Episode) -> None:
        try:
            observation = observation_from_msg(self._reset(episode))
            episode.begin(observation)
            if self.frozen is None:
                self._await_learner(self.config.learner_grace)
                self._await_learner_reading_transitions(self.config.learner_grace)
            self._set_state("running")
            while not episode.done:
                if self.stop_requested.is_set():
                    raise EpisodeAborted(self.stop_reason)
                alive = self.frozen is not None or self.learner_alive()
                self._set_degraded(not alive)
                with self.lock:
                    actor = self.actor if alive else None
                action = episode.choose_action(actor)
                if actor is not None:
                    action = self._recover(episode, action)
                at_rest = self._execute(episode.task.command(action, observation))
                observation = observation_from_msg(at_rest)
                record = episode.observe(action, observation)
                self.transition_pub.publish(transition_to_msg(record))
                self._publish_status()
            self._set_state("done", episode.end_reason)
        except EpisodeAborted as exc:
            episode.abort("aborted")
            self._send_zero_residual()
            self._set_state("aborted", str(exc))
        except Exception as exc:  # noqa: BLE001 - a failed episode must never kill the node
            episode.abort("error")
            self.get_logger().error(f"episode {episode.episode_id} failed: {exc!r}")
            self._send_zero_residual()
            self._set_state("aborted", f"error: {exc}")

    def _reset(self, episode: Episode) -> AtRest:
        """Move the robot to the episode's start (the task's start of its pose); a reply lost on
        the way is asked for again every ``RESET_RETRY`` seconds with the same request id,
        which the robot answers without moving twice (``serve_move_to_start``)."""
        # The episode id is the session: from now on the bridge executes only its setpoints.
        request = start_pose_request(episode.task.start_pose(episode.initial_pose),
                                     session=episode.episode_id, request_id=uuid.uuid4().hex)
        deadline = time.monotonic() + self.config.reset_timeout
        while True:
            future = self.start_client.call_async(request)
            wait = max(min(RESET_RETRY, deadline - time.monotonic()), 0.0)
            if self._wait_until(future.done, wait, poll=0.002):
                break
            self.start_client.remove_pending_request(future)
            if self.stop_requested.is_set():
                raise EpisodeAborted(f"{self.stop_reason} during reset")
            if time.monotonic() >= deadline:
                raise EpisodeAborted(
                    f"/move_to_start did not answer within {self.config.reset_timeout} s")
            self.get_logger().warning(f"/move_to_start unanswered for {RESET_RETRY:.0f} s: "
                                      f"asking again (request {request.request_id})")
        result = future.result()
        if result is None or not result.success:
            raise EpisodeAborted(f"reset refused: {getattr(result, 'message', 'no answer')}")
        return result.observation

    def _execute(self, setpoint: Setpoint) -> AtRest:
        """Send one setpoint and wait for its at-rest event.

        With ``keepalive_period > 0`` the setpoint is re-sent that often while waiting. No robot
        needs it (a step's setpoint holds until the step ends), and every re-sent message costs
        the robot process rclpy callbacks that compete with the 1 kHz loop for the GIL (0.8
        instead of 19 RL steps per second at 5 ms).
        """
        self.seq += 1
        deadline = time.monotonic() + self.config.step_timeout
        resend = self.config.keepalive_period > 0.0
        self._send(setpoint)
        while True:
            self.at_rest_event.wait(self.config.keepalive_period if resend else 0.05)
            with self.lock:
                self.at_rest_event.clear()
                event = self.at_rest.pop(self.seq, None)
                self.at_rest = {k: v for k, v in self.at_rest.items() if k > self.seq}
            if event is not None and event.fault:
                raise EpisodeAborted(f"the robot stopped: {event.fault}")
            if event is not None:
                return event
            if self.stop_requested.is_set():
                raise EpisodeAborted(self.stop_reason)
            if time.monotonic() > deadline:
                raise EpisodeAborted(f"no at-rest event within {self.config.step_timeout} s "
                                     "(is the robot process up?)")
            if resend:
                self._send(setpoint)

    def _send(self, setpoint: Setpoint) -> None:
        """Publish ``setpoint`` as the command ``seq`` (stamped now)."""
        session = self.episode.episode_id if self.episode is not None else ""
        self.setpoint_pub.publish(setpoint_msg(self.seq, setpoint,
                                               self.get_clock().now().to_msg(), session))

    def _send_zero_residual(self) -> None:
        """Leave the robot safe from where it is: the task's hold command (the Panda pushes
        with the base force only, the Nextage stays)."""
        self.seq += 1
        self._send(self.task.hold())

    def _recover(self, episode: Episode, action: Any) -> Any:
        """The action through the episode's stall recovery, if it has one; a recovery that
        starts here is logged and in the status (``message``, ``recoveries``)."""
        recovery = self.recovery
        if recovery is None:
            return action
        before = recovery.recoveries
        action = recovery.act(episode.state, action)
        if recovery.recoveries > before:
            text = (f"stall recovery {recovery.recoveries} at step {episode.step}: "
                    f"{recovery.recovery_steps(recovery.recoveries)} "
                    f"{recovery.config.perturbation} steps")
            self.get_logger().info(f"episode {episode.episode_id}: {text}")
            self._set_state("running", text)
        return action

    # --- status ---------------------------------------------------------------------------
    def _set_degraded(self, degraded: bool) -> None:
        """Say so (log and status) when the learner goes silent or comes back."""
        with self.lock:
            changed, self.degraded = degraded != self.degraded, degraded
        if changed:
            self.get_logger().warning("learner silent: zero residual until it is back"
                                      if degraded else "learner is back")
            self._publish_status()

    def _set_state(self, state: str, message: str = "") -> None:
        self.state, self.message = state, message
        self._publish_status()

    def _publish_status(self) -> None:
        ep = self.episode
        msg = EpisodeStatus(state=self.state, message=self.message, degraded=self.degraded,
                            actor_version=self.actor_version)
        msg.stamp = self.get_clock().now().to_msg()
        if ep is not None:
            msg.episode_id, msg.mode, msg.reward_type = ep.episode_id, ep.mode, ep.reward_kind
            msg.initial_pose, msg.step, msg.max_steps = ep.initial_pose, ep.step, ep.max_steps
            msg.episode_return, msg.success = ep.episode_return, ep.success
            recovery = self.recovery
            msg.recoveries = recovery.recoveries if recovery is not None else 0
        self.status_pub.publish(msg)


def _abort_on_shutdown(nodes: list[Node]) -> Callable[[], None]:
    """What ``run_nodes`` runs at shutdown: the executor's episode abort (no extra work)."""
    node = nodes[0]
    assert isinstance(node, ExecutorNode)
    return node.abort_on_shutdown


def main(args: list[str] | None = None) -> int:
    return run_nodes([ExecutorNode], args, background=_abort_on_shutdown)


if __name__ == "__main__":
    raise SystemExit(main())
