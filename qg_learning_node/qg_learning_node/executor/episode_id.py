"""Episode ids: they name an episode's bag and, under many robots, the robot that ran it.

``[<robot>_]<YYYYmmdd_HHMMSS>_<index>_<mode>_p<pose>``: when the executor started the episode,
how many it had started before, the mode and the initial pose, behind the executor's namespace
(``/robot1`` -> ``robot1_``, ``/lab/robot1`` -> ``lab_robot1_``; none at the root). Ids, bag
folders and the learner's bookkeeping of concurrent episodes never collide, and a bag's
transitions say which robot recorded them (``qgl replay --into-learner`` needs that).
"""
from __future__ import annotations

import re
import time

__all__ = ["episode_id", "robot_of_episode"]

_ID = re.compile(r"(?:(?P<robot>\w+?)_)?\d{8}_\d{6}_\d+_[a-z]+_p\d+", re.ASCII)


def episode_id(namespace: str, index: int, mode: str, pose: int,
               when: float | None = None) -> str:
    """The id of the ``index``-th episode an executor in ``namespace`` starts (at ``when``,
    Unix time; default now)."""
    robot = namespace.strip("/").replace("/", "_")
    stamp = time.strftime("%Y%m%d_%H%M%S", time.localtime(when))
    return f"{robot}_{stamp}_{index:04d}_{mode}_p{pose}" if robot else \
        f"{stamp}_{index:04d}_{mode}_p{pose}"


def robot_of_episode(episode_id: str) -> str:
    """The robot (its namespace with ``/`` as ``_``) whose executor made ``episode_id``; "" for
    a robot at the root and for ids of another form (one robot)."""
    match = _ID.fullmatch(episode_id)
    return (match["robot"] or "") if match else ""
