"""Service requests a client may send twice: the same ``request_id`` gets the first reply.

A service reply can be lost: a client that the server has not matched yet does not get it
(discovery runs per direction, more often late on a loaded host). So a client asks again with
the same ``request_id`` (``move_to_start``, ``executor/start_episode``), and the server answers
that from its last reply instead of moving the robot, or starting an episode, a second time.
Pure: no rclpy.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["answered_once"]

#: A service callback: (request, response) -> response.
Handler = Callable[[Any, Any], Any]


def answered_once(handler: Handler, what: str, log: Callable[[str], None]) -> Handler:
    """``handler`` as a service callback that keeps its last reply by ``request.request_id``:
    that id again gets the reply back, logged, without calling ``handler``; an empty id is
    always handled. Only the last id is kept (a client retries until it has its answer).

    :param what: names the request in the log line (``"reset <id> asked again: ..."``).
    :param log: where that line goes (a node logger's ``info``).
    """
    last: dict[str, Any] = {}

    def serve(request: Any, response: Any) -> Any:
        if request.request_id and request.request_id in last:
            log(f"{what} {request.request_id} asked again: its reply again")
            return last[request.request_id]
        response = handler(request, response)
        if request.request_id:
            last.clear()
            last[request.request_id] = response
        return response
    return serve
