"""Short-lived rclpy clients for the CLI: call a service, list the graph.

This rclpy's ``spin_until_future_complete`` costs 4-21 ms per call, so we spin the executor
ourselves until the future is done.
"""
from __future__ import annotations

import time
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

__all__ = ["CliNode", "call_service"]


class CliNode:
    """A context manager owning an rclpy context, one node and an executor."""

    def __init__(self, name: str = "qgl", domain_id: int | None = None) -> None:
        self.name = name
        self.domain_id = domain_id

    def __enter__(self) -> "CliNode":
        self.context = rclpy.Context()
        if self.domain_id is None:
            rclpy.init(context=self.context)
        else:
            rclpy.init(context=self.context, domain_id=self.domain_id)
        self.node = Node(f"{self.name}_{int(time.time() * 1000) % 100000}", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        return self

    def __exit__(self, *exc: Any) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

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
                 timeout: float = 10.0) -> Any:
    """Call ``name`` and return the response.

    :raises TimeoutError: naming the service, when it is not available or does not answer.
    """
    client = cli.node.create_client(srv_type, name)
    try:
        if not cli.spin_until(client.service_is_ready, timeout):
            raise TimeoutError(f"service {name} is not available (is the stack up? `qgl up`)")
        future = client.call_async(request)
        if not cli.spin_until(future.done, timeout):
            raise TimeoutError(f"service {name} did not answer within {timeout:.0f} s")
        return future.result()
    finally:
        cli.node.destroy_client(client)
