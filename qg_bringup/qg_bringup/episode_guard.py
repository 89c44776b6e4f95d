"""End the episode a dead process was in, ``aborted`` with the reason (``qgl up``, ``qgl run``).

When the launcher restarts a process (``Launcher.take_respawns``), the episode its robot was
running cannot go on as if nothing happened: the learner missed transitions, the robot lost
its state. The guard follows every robot's ``episode_status`` and, for a running episode:

- the robot process or the learner died: asks that robot's executor to stop it
  (``executor/stop_episode`` with the reason; the executor ends it ``aborted``, zero residual);
- the executor itself died: nobody else will ever end it, so the guard publishes its final
  ``aborted`` status with the reason on the executor's latched topic: the recorder closes its
  bag, the learner does not checkpoint it, a client waiting for it is told.

Which robot a process belongs to comes from its ``-r __ns:=/<robot>`` (``fleet.py``).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

from qg_bringup.launcher import Respawn
from qg_bringup.stack_file import ProcessSpec

__all__ = ["EpisodeGuard", "ProcessRole", "process_roles"]

_FINAL = ("done", "aborted")


@dataclass(frozen=True)
class ProcessRole:
    """What a stack process is to the episodes: its robot ("" = the root) and whether it is
    that robot's executor; ``robot`` None: every robot's (the learner)."""
    robot: str | None
    executor: bool


def process_roles(specs: Sequence[ProcessSpec]) -> dict[str, ProcessRole]:
    """Each process's role, from its package/executable and its ``__ns`` remap."""
    roles = {}
    for spec in specs:
        namespace = next((a.split(":=", 1)[1].strip("/") for a in spec.args
                          if a.startswith("__ns:=")), "")
        learner = (spec.package, spec.executable) == ("qg_learning_node", "learner")
        roles[spec.name] = ProcessRole(None if learner else namespace,
                                       (spec.package, spec.executable)
                                       == ("qg_learning_node", "executor"))
    return roles


class EpisodeGuard:
    """Follows the robots' episodes; ``process_died`` ends the ones a dead process was in.

    :param cli: a ``CliNode`` (spun by the caller, or by :meth:`spin`).
    :param roles: :func:`process_roles` of the stack.
    """

    def __init__(self, cli: Any, roles: dict[str, ProcessRole]) -> None:
        from qg_common.topics import EPISODE_STATUS, LATCHED, STOP_EPISODE
        from qg_interfaces.msg import EpisodeStatus
        from qg_interfaces.srv import StopEpisode

        from qg_bringup.episode_schedule import robot_name
        self.cli, self.roles = cli, roles
        self.robots = sorted({r.robot for r in roles.values() if r.robot is not None}) or [""]
        self.last: dict[str, Any] = {}          # robot -> its executor's last status
        self.stop_type = StopEpisode
        self.status_type = EpisodeStatus
        self.publishers, self.stoppers, self.pending = {}, {}, []
        for robot in self.robots:
            topic = robot_name(robot, EPISODE_STATUS)
            cli.node.create_subscription(EpisodeStatus, topic,
                                         partial(self._on_status, robot=robot), LATCHED)
            self.publishers[robot] = cli.node.create_publisher(EpisodeStatus, topic, LATCHED)
            self.stoppers[robot] = cli.client(StopEpisode, robot_name(robot, STOP_EPISODE))

    def _on_status(self, msg: Any, robot: str = "") -> None:
        self.last[robot] = msg

    def running(self, robot: str) -> Any | None:
        """The status of ``robot``'s running episode, None if it runs none."""
        msg = self.last.get(robot)
        return msg if msg is not None and msg.episode_id and msg.state not in _FINAL else None

    def process_died(self, death: Respawn) -> list[str]:
        """End the episodes ``death`` cut short, ``aborted`` with its reason; their ids."""
        role = self.roles.get(death.name, ProcessRole("", False))
        robots = self.robots if role.robot is None else [role.robot]
        ended = []
        for robot in robots:
            status = self.running(robot)
            if status is None:
                continue
            if role.executor:
                final = self.status_type()
                for field in ("episode_id", "mode", "reward_type", "initial_pose", "step",
                              "max_steps", "episode_return", "actor_version"):
                    setattr(final, field, getattr(status, field))
                final.state, final.success, final.message = "aborted", False, death.reason
                final.stamp = self.cli.node.get_clock().now().to_msg()
                self.publishers[robot].publish(final)
                self.last[robot] = final
            else:
                client = self.stoppers[robot]
                if client.service_is_ready():
                    self.pending.append(client.call_async(
                        self.stop_type.Request(reason=death.reason)))
            ended.append(status.episode_id)
        return ended

    def spin(self, seconds: float) -> None:
        """Let the guard hear statuses and its stop requests be answered for ``seconds``."""
        self.cli.spin_for(seconds)
        self.pending = [f for f in self.pending if not f.done()]


def supervise(launcher: Any, specs: Sequence[ProcessSpec], period: float = 0.2) -> tuple[str, int]:
    """``qgl up``'s watch: restart what respawns, end the episodes the dead were in, until a
    process stays dead; its name and exit code (``launcher.reasons`` says why)."""
    if not any(spec.respawn for spec in specs):
        return launcher.wait_any(period)
    from qg_common.ros_client import CliNode
    with CliNode("qgl_up") as cli:
        guard = EpisodeGuard(cli, process_roles(specs))
        while True:
            died = launcher.poll()
            if died:
                return died[0]
            for death in launcher.take_respawns():
                ended = guard.process_died(death)
                if ended:
                    print(f"[qgl] {death.reason}: episode {', '.join(ended)} ended aborted",
                          flush=True)
            guard.spin(period)
