"""Running episodes by service call on one robot or on many at once (``qgl demo --robots N``).

Each robot has a queue of episodes (a *lane*): it runs them one after another, each started by
its ``<ns>/executor/start_episode`` and ended by its final ``<ns>/episode_status``; all lanes
advance together in one spin loop of one node, so N robots run N episodes at the same time and
the progress bar, fed from the same loop, needs no locking. One lane at the root namespace is
the single robot of ``qgl up``: its episodes run exactly as a loop of service calls would.
"""
from __future__ import annotations

import time
import uuid
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

__all__ = ["EpisodeJob", "EpisodeOutcome", "EpisodeObserver", "Lane", "robot_name",
           "split_over_robots",
           "run_lanes", "run_episode_by_service"]

#: [s] how long a lane waits for its robot's start_episode service to appear and answer.
SERVICE_TIMEOUT = 30.0


@dataclass(frozen=True)
class EpisodeJob:
    """One episode to request: ``index`` in the whole schedule, pose -1 = the robot's rotation."""
    index: int
    mode: str
    pose: int
    seed: int


@dataclass
class EpisodeOutcome:
    """What the executor reported at the end of one episode."""
    index: int
    mode: str
    episode_id: str
    initial_pose: int
    steps: int
    episode_return: float
    success: bool
    wall_time: float
    robot: str = ""          # its namespace ("" = one robot at the root)
    started: float = 0.0     # [s] Unix time of the start request
    state: str = "done"      # the final state: done | aborted
    message: str = ""        # the executor's reason (why it ended, why it was aborted)


def robot_name(robot: str, name: str) -> str:
    """The absolute name of topic or service ``name`` of ``robot``: ``/robot1/transitions``,
    ``/transitions`` for the robot at the root (as a client at the root names them)."""
    from qg_common.topics import robot_topic
    return "/" + robot_topic(robot, name).lstrip("/")


class EpisodeObserver(Protocol):
    """What follows the lanes (the demo's progress bar and training log). An observer may also
    have ``started(index, episode_id, robot)``, called when the executor has named the episode
    (a training run's journal notes which episode its slot is running)."""

    def begin(self, index: int, mode: str, robot: str = "") -> None: ...

    def end(self, outcome: EpisodeOutcome) -> None: ...


def split_over_robots(jobs: Sequence[EpisodeJob],
                      robots: Sequence[str]) -> dict[str, list[EpisodeJob]]:
    """Deal ``jobs`` to ``robots`` in turn (job i to robot i mod N), each keeping their order."""
    if not robots:
        raise ValueError("no robot to run episodes on")
    return {robot: list(jobs[k::len(robots)]) for k, robot in enumerate(robots)}


class _Lane:
    """One robot's queue: its next episode starts when its last one has ended."""

    def __init__(self, cli: Any, robot: str, jobs: Sequence[EpisodeJob],
                 observer: EpisodeObserver | None, timeout: float) -> None:
        from qg_common.ros_client import RESEND_AFTER
        from qg_common.topics import EPISODE_STATUS, LATCHED, START_EPISODE
        from qg_interfaces.msg import EpisodeStatus
        from qg_interfaces.srv import StartEpisode

        from qg_bringup.episode_wait import FINAL_STATES
        self.cli, self.robot, self.observer, self.timeout = cli, robot, observer, timeout
        self.resend_after = RESEND_AFTER   # [s] unanswered this long, a start is asked again
        self.request_type = StartEpisode.Request
        self.service = robot_name(robot, START_EPISODE)
        self.client = cli.client(StartEpisode, self.service)
        self.queue = deque(jobs)
        self.job: EpisodeJob | None = None
        self.requested = False
        self.future, self.episode_id = None, ""
        self.request_id, self.sent = "", 0.0      # the job's StartEpisode id, last sent at
        self.t0, self.started = 0.0, 0.0
        # Keyed by id: the final status may arrive while the service call is still being answered.
        self.final: dict[str, Any] = {}

        def on_status(msg: EpisodeStatus) -> None:
            if msg.state in FINAL_STATES:
                self.final[msg.episode_id] = msg

        self.subscription = cli.node.create_subscription(
            EpisodeStatus, robot_name(robot, EPISODE_STATUS), on_status, LATCHED)

    @property
    def finished(self) -> bool:
        return self.job is None and not self.queue

    def advance(self) -> EpisodeOutcome | None:
        """Take the lane one state further if it can; the outcome of an episode that ended.

        :raises RuntimeError: if the executor refuses the episode.
        :raises TimeoutError: if the service is missing or the episode outlives the timeout.
        """
        if self.job is None and self.queue:
            self.job, self.requested = self.queue.popleft(), False
            if self.observer is not None:
                self.observer.begin(self.job.index, self.job.mode, self.robot)
            self.t0, self.started = time.monotonic(), time.time()
        if self.job is None:
            return None
        waited = time.monotonic() - self.t0
        if not self.requested:
            if self.client.service_is_ready():
                self.requested, self.request_id = True, uuid.uuid4().hex
                self._send()
            elif waited > SERVICE_TIMEOUT:
                raise TimeoutError(f"service {self.service} is not available (is the stack up? "
                                   "`qgl up`)")
            return None
        if self.future is not None and not self.future.done():
            if waited > SERVICE_TIMEOUT:
                raise TimeoutError(f"service {self.service} did not answer within "
                                   f"{SERVICE_TIMEOUT:.0f} s")
            if time.monotonic() - self.sent > self.resend_after:   # the reply may be lost
                self.client.remove_pending_request(self.future)
                self._send()
        if self.future is not None and self.future.done():
            response = self.future.result()
            self.future = None
            if not response.success:
                raise RuntimeError(f"StartEpisode refused ({self.service}): {response.message}")
            self.episode_id = response.episode_id
            started = getattr(self.observer, "started", None)
            if started is not None:
                started(self.job.index, self.episode_id, self.robot)
        if self.episode_id and self.episode_id in self.final:
            outcome = self._outcome(self.final.pop(self.episode_id))
            self.job, self.episode_id = None, ""
            if self.observer is not None:
                self.observer.end(outcome)
            return outcome
        if waited > self.timeout:
            raise TimeoutError(f"episode {self.episode_id or '(not yet started)'}"
                               f"{' of ' + self.robot if self.robot else ''} did not end within "
                               f"{self.timeout:.0f} s")
        return None

    def _send(self) -> None:
        """Ask for the job's episode; the same ``request_id`` again gets the first reply."""
        self.future = self.client.call_async(self.request_type(
            mode=self.job.mode, initial_pose=self.job.pose, seed=self.job.seed,
            request_id=self.request_id))
        self.sent = time.monotonic()

    def _outcome(self, msg: Any) -> EpisodeOutcome:
        job = self.job
        return EpisodeOutcome(job.index, job.mode, msg.episode_id, msg.initial_pose,
                              int(msg.step), float(msg.episode_return), bool(msg.success),
                              time.monotonic() - self.t0, self.robot, self.started,
                              str(msg.state), str(msg.message))

    def forget(self) -> EpisodeJob | None:
        """Give up on the running episode (its executor died: no final status will come);
        the job it was running, for the caller to queue again."""
        job, self.job, self.episode_id, self.future = self.job, None, "", None
        return job

    def close(self) -> None:
        self.cli.node.destroy_subscription(self.subscription)


#: One robot's queue of episodes, for a caller that runs its own loop (``training_run.py``).
Lane = _Lane


def run_lanes(cli: Any, lanes: dict[str, Sequence[EpisodeJob]],
              observer: EpisodeObserver | None = None, timeout: float = 900.0,
              check: Callable[[], None] = lambda: None) -> list[EpisodeOutcome]:
    """Run every robot's episodes, all robots at once, each robot's one after another.

    :param lanes: robot namespace ("" = the root) -> its episodes, in order.
    :param timeout: [s] per episode, from its start request to its final status.
    :param check: called on every turn of the loop; raises to abort (a stack process died).
    :returns: the outcomes by ``index``.
    """
    running = [_Lane(cli, robot, jobs, observer, timeout) for robot, jobs in lanes.items()]
    outcomes: list[EpisodeOutcome] = []
    try:
        while not all(lane.finished for lane in running):
            check()
            for lane in running:
                outcome = lane.advance()
                if outcome is not None:
                    outcomes.append(outcome)
            cli.executor.spin_once(timeout_sec=0.01)
    finally:
        for lane in running:
            lane.close()
    return sorted(outcomes, key=lambda o: o.index)


def run_episode_by_service(cli: Any, index: int, mode: str, pose: int, seed: int,
                           timeout: float, robot: str = "") -> EpisodeOutcome:
    """Start one episode by ``<robot>/executor/start_episode`` and wait for its final status."""
    (outcome,) = run_lanes(cli, {robot: [EpisodeJob(index, mode, pose, seed)]}, timeout=timeout)
    return outcome
