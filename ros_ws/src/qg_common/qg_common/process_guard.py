"""A child process that cannot outlive the process that started it.

``qgl up`` starts the node processes, and the robot process starts its loop process; if the
parent is killed (SIGKILL runs no cleanup), its children would go on holding the robot, a ROS
domain and a core. Linux sends a child a signal when its parent dies if the child asked for it
(``prctl(PR_SET_PDEATHSIG)``), which ``subprocess.Popen(preexec_fn=die_with_parent(...))`` does
between fork and exec.
"""
from __future__ import annotations

import ctypes
import os
import signal
from collections.abc import Callable

__all__ = ["die_with_parent"]

_PR_SET_PDEATHSIG = 1     # prctl option (linux/prctl.h)


def die_with_parent(parent: int) -> Callable[[], None]:
    """What the child runs before exec: SIGTERM when ``parent`` goes away (the thread that
    started the child, strictly), and exit at once if it already went between fork and here."""
    def arm() -> None:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        if os.getppid() != parent:
            os._exit(1)
    return arm
