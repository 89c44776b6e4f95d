"""What every node executable of the stack shares: parameters from ``config/``, spin, clean exit.

``ros2 run`` and ``qgl up`` both call a node's ``main()``. Without a ``--params-file`` on the
command line the node reads its YAML from the project's ``config/`` folder, so a bare
``ros2 run sim_robot_node sim`` behaves like the configured stack. SIGINT and SIGTERM end the
process with exit code 0 after the nodes are destroyed (rclpy turns both into a shutdown).
"""
from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node

from sim_robot_node.core.params import ConfigError, config_dir, unflatten

__all__ = ["node_args", "node_params", "run_nodes"]


def node_args(config_files: Sequence[str], argv: Sequence[str] | None = None) -> list[str]:
    """``argv`` with ``--params-file config/<f>`` added for each file unless one is given."""
    args = list(sys.argv if argv is None else argv)
    if "--params-file" in args:
        return args
    extra: list[str] = []
    for name in config_files:
        path = config_dir() / name
        if not path.is_file():
            raise ConfigError(f"config file not found: {path}")
        extra += ["--params-file", str(path)]
    if "--ros-args" in args:
        i = args.index("--ros-args") + 1
        return args[:i] + extra + args[i:]
    return args + ["--ros-args"] + extra


def node_params(node: Node) -> dict[str, Any]:
    """All parameters of ``node`` (declared from the params file) as a nested dict."""
    flat = {name: p.value for name, p in node.get_parameters_by_prefix("").items()
            if name != "use_sim_time"}
    return unflatten(flat)


def run_nodes(factories: Sequence[Callable[[], Node]], config_files: Sequence[str],
              argv: Sequence[str] | None = None,
              background: Callable[[list[Node]], Callable[[], None]] | None = None) -> int:
    """Create the nodes, spin them until SIGINT/SIGTERM, and tear down cleanly.

    :param factories: callables returning the nodes to run in this process (composition).
    :param config_files: YAML files under ``config/`` read when no ``--params-file`` is given.
    :param background: optional; given the nodes, starts extra work (e.g. the 1 kHz loop
        thread) and returns a function that stops it.
    :returns: the process exit code.
    """
    try:
        args = node_args(config_files, argv)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rclpy.init(args=args)
    nodes: list[Node] = []
    stop_background: Callable[[], None] | None = None
    code = 0
    try:
        nodes = [make() for make in factories]
        executor = MultiThreadedExecutor(num_threads=max(2, len(nodes)))
        for node in nodes:
            executor.add_node(node)
        if background is not None:
            stop_background = background(nodes)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        code = 2
    finally:
        if stop_background is not None:
            stop_background()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
