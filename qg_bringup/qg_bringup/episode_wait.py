"""Follow ``/episode_status`` until an episode ends (used by ``qgl episode start --wait``)."""
from __future__ import annotations

from qg_common import topics
from qg_common.ros_client import CliNode
from qg_common.topics import LATCHED
from qg_interfaces.msg import EpisodeStatus

__all__ = ["wait_for_episode", "FINAL_STATES"]

FINAL_STATES = ("done", "aborted")


def wait_for_episode(cli: CliNode, episode_id: str, timeout: float, namespace: str = "") -> int:
    """Print status changes of ``episode_id`` until it ends; 0 if it ended, 1 on timeout.

    :param namespace: the robot's namespace (``robot1``), "" for a robot at the root.
    """
    last: list[EpisodeStatus] = []

    def on_status(msg: EpisodeStatus) -> None:
        if msg.episode_id == episode_id:
            if not last or ((msg.state, msg.step // 50, msg.recoveries)
                            != (last[-1].state, last[-1].step // 50, last[-1].recoveries)):
                recovered = f"recoveries={msg.recoveries} " if msg.recoveries else ""
                print(f"  {msg.state:<9} step {msg.step:>4}/{msg.max_steps} "
                      f"return {msg.episode_return:8.2f} success={msg.success} "
                      f"degraded={msg.degraded} {recovered}{msg.message}", flush=True)
            last.append(msg)

    sub = cli.node.create_subscription(
        EpisodeStatus, topics.robot_topic(namespace, topics.EPISODE_STATUS), on_status, LATCHED)
    try:
        ended = cli.spin_until(lambda: bool(last) and last[-1].state in FINAL_STATES, timeout)
    finally:
        cli.node.destroy_subscription(sub)
    return 0 if ended else 1
