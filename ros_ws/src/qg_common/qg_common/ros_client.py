"""Short-lived rclpy clients (command line, tools, tests): call a service, list the graph.

This rclpy's ``spin_until_future_complete`` costs 4-21 ms per call, so we spin the executor
ourselves until the future is done.

A service client is kept for the life of the ``CliNode``: a new client is matched by the
server a moment after the client sees the server (discovery is not symmetric), and a reply
sent in that moment is lost, more often on a loaded machine. Reusing one client pays that
once; ``resend_after`` covers it for requests that are safe to send twice.
"""
from __future__ import annotations

import time
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

__all__ = ["CliNode", "RESEND_AFTER", "call_service"]

#: [s] how long a request that is safe to repeat (``call_service``'s ``resend_after``) waits for
#: its reply before it is sent again: a lost reply is not answered later.
RESEND_AFTER = 5.0


class CliNode:
    """A context manager owning an rclpy context, one node and an executor."""

    def __init__(self, name: str = "qgl", domain_id: int | None = None) -> None:
        self.name = name
        self.domain_id = domain_id

    def __enter__(self) -> CliNode:
        self.context = rclpy.Context()
        if self.domain_id is None:
            rclpy.init(context=self.context)
        else:
            rclpy.init(context=self.context, domain_id=self.domain_id)
        self.node = Node(f"{self.name}_{int(time.time() * 1000) % 100000}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._clients: dict[tuple[Any, str], Any] = {}
        return self

    def client(self, srv_type: Any, name: str) -> Any:
        """The node's client of service ``name``, created on first use and then kept."""
        key = (srv_type, name)
        if key not in self._clients:
            self._clients[key] = self.node.create_client(srv_type, name)
        return self._clients[key]

    def __exit__(self, *exc: Any) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def node_names(self) -> set[str]:
        """The full names (``/namespace/name``) of the nodes discovered so far, this one's
        included."""
        return {f"{ns.rstrip('/')}/{n}" for n, ns in self.node.get_node_names_and_namespaces()}

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)

    def spin_until(self, predicate, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.01)
        return predicate()


def call_service(cli: CliNode, srv_type: Any, name: str, request: Any,
                 timeout: float = 10.0, resend_after: float | None = None) -> Any:
    """Call ``name`` and return the response.

    :param resend_after: [s] send the request again when it is unanswered this long; only for
        requests that are safe to repeat (queries, refused requests, parameter sets, a
        ``move_to_start`` or ``start_episode`` with a ``request_id``), e.g. ``RESEND_AFTER``.
    :raises TimeoutError: naming the service, when it is not available or does not answer.
    """
    client = cli.client(srv_type, name)
    deadline = time.monotonic() + timeout
    if not cli.spin_until(client.service_is_ready, timeout):
        raise TimeoutError(f"service {name} is not available (is the stack up? `qgl up`)")
    while True:
        future = client.call_async(request)
        attempt = min(deadline - time.monotonic(), resend_after or timeout)
        if cli.spin_until(future.done, max(attempt, 0.0)):
            return future.result()
        client.remove_pending_request(future)
        if time.monotonic() >= deadline:
            raise TimeoutError(f"service {name} did not answer within {timeout:.0f} s")
