"""What every node executable of the stack shares: spin, refuse unknown parameters, clean exit.

``ros2 run`` and ``qgl up`` both call a node's ``main()``. Each node declares its own parameters
(``node_parameters.declare_parameters``) with its package's YAML as the defaults, so a bare
``ros2 run robot_bridge_node robot`` behaves like the configured stack and a ``--params-file``
or ``-p`` overrides only what it names. A given parameter that no node of the process declares
(a misspelt name) stops the start with exit code 2, as does a value of the wrong type or out of
range. SIGINT and SIGTERM end the process with exit code 0: spinning stops, the nodes' shutdown
work runs while ROS is still up (the executor publishes its last status), then the nodes are
destroyed and ROS is shut down.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from qg_common.callback_executor import CallbackThreadPool
from qg_common.node_parameters import unknown_overrides
from qg_common.params import ConfigError

__all__ = ["LoopThread", "REALTIME_SWITCH_INTERVAL", "run_nodes", "favour_loop_thread"]

#: [s] Python's GIL hand-over interval in a process with a wall-clock 1 kHz thread. The default
#: 5 ms lets a ROS callback thread hold the GIL for five ticks before the loop thread gets it back.
REALTIME_SWITCH_INTERVAL = 1e-4


def favour_loop_thread() -> None:
    """Hand the GIL over every ``REALTIME_SWITCH_INTERVAL`` instead of every 5 ms, for the
    process's wall-clock 1 kHz thread. Without it the separate sim, whose executor threads run
    Python beside its loop, stepped 60-430 times a second on an idle machine (and held the arm
    in gravity compensation when the bridge's commands came 60-290 ms late); with it 800-930.
    """
    sys.setswitchinterval(REALTIME_SWITCH_INTERVAL)


def run_nodes(factories: Sequence[Callable[[], Node]], argv: Sequence[str] | None = None,
              background: Callable[[list[Node]], Callable[[], None]] | None = None, *,
              blocking_callbacks: bool = True) -> int:
    """Create the nodes, spin them until SIGINT/SIGTERM, and tear down cleanly.

    :param factories: callables returning the nodes to run in this process (composition), called
        in order (a later one may use what an earlier node declared).
    :param argv: the command line (default ``sys.argv``), ``--ros-args`` included.
    :param background: optional; given the nodes, starts extra work (e.g. the 1 kHz loop
        thread) and returns the function run at shutdown, before the nodes are destroyed and
        while they can still publish: it stops that work or ends what the nodes are doing (the
        executor's running episode); it raises ``RuntimeError`` if the work failed, which makes
        the exit code 1.
    :param blocking_callbacks: False promises that no callback of the nodes waits for another
        one (as a service that waits for a topic would): the callbacks then run one at a time
        on rclpy's C++ ``EventsExecutor``, which takes about twice as many 1 kHz messages per
        second as the Python executors on a loaded machine (the separate bridge ticks once per
        state it takes). True runs them on a thread pool (``CallbackThreadPool``).
    :returns: never: the process exits with the code (0 on SIGINT/SIGTERM, 2 on bad parameters).
    """
    # rclpy's own signal handlers shut ROS down at once, under the nodes' feet: nothing could
    # be published any more and threads still using a node crash on its destroyed handles.
    rclpy.init(args=list(sys.argv if argv is None else argv),
               signal_handler_options=SignalHandlerOptions.NO)
    stopping = _stop_on_signals()
    nodes: list[Node] = []
    stop_background: Callable[[], None] | None = None
    code = 0
    try:
        for make in factories:
            nodes.append(make())
        unknown = unknown_overrides(nodes)
        if unknown:
            raise ConfigError("; ".join(unknown))
        executor = (CallbackThreadPool(num_threads=max(2, len(nodes))) if blocking_callbacks
                    else EventsExecutor())
        for node in nodes:
            executor.add_node(node)
        if background is not None:
            try:
                stop_background = background(nodes)
            except (RuntimeError, TimeoutError) as exc:   # the work could not start: say why
                print(f"error: {exc}", file=sys.stderr)
                code = 1
                stopping.set()
        stopping.spinning = True
        # Until a signal (noticed within 0.1 s) or a failed background thread shuts ROS down.
        while not stopping.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, ValueError) as exc:
        if rclpy.ok():
            print(f"error: {exc}", file=sys.stderr)
            code = 2
    except Exception:
        # A failed background thread shuts ROS down under the nodes; that thread reports it.
        if rclpy.ok():
            raise
    finally:
        if stop_background is not None:
            try:
                stop_background()
            except RuntimeError as exc:  # the background work died: not a clean exit
                print(f"error: {exc}", file=sys.stderr)
                code = 1
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    # Nodes are destroyed and ROS is shut down; the interpreter's own teardown (torch, DDS
    # threads) would take seconds more, so end the process here to stop within the promised 5 s.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


class _StopRequest(threading.Event):
    """Set by SIGINT or SIGTERM; ``spinning`` says whether the nodes are up yet."""
    spinning = False


def _stop_on_signals() -> _StopRequest:
    """SIGINT and SIGTERM set the returned event once the nodes spin (the spin loop then ends
    and the shutdown work runs); while the nodes are still being built they interrupt that.
    Python runs the handler in the main thread."""
    stopping = _StopRequest()

    def handle(signum: int, frame: object) -> None:
        stopping.set()
        if not stopping.spinning:
            raise KeyboardInterrupt

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, handle)
    return stopping


class LoopThread:
    """A node's dedicated work thread (e.g. the 1 kHz loop), outside the rclpy executor.

    ``body(stop)`` runs until ``stop`` is set, with ``SCHED_FIFO`` priority ``priority`` if
    that is > 0 and the system allows it (a 1 kHz loop on a busy machine needs its core on
    time, as on a real-time kernel). If it raises, the traceback is logged and rclpy
    is shut down so the process ends; ``stop()`` then raises ``RuntimeError`` (exit code 1).
    An exception after rclpy was shut down (SIGINT arriving mid-publish) is a normal stop.
    """

    def __init__(self, name: str, body: Callable[[threading.Event], None], node: Node,
                 priority: int = 0) -> None:
        self._body = body
        self._node = node
        self._priority = priority
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> LoopThread:
        self._thread.start()
        return self

    def _run(self) -> None:
        if self._priority > 0:
            try:   # this thread only (Linux: pid 0 is the calling thread)
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self._priority))
            except (OSError, AttributeError) as exc:
                self._node.get_logger().warn(f"{self._thread.name}: no realtime priority "
                                             f"{self._priority} ({exc}); running unprioritised")
        try:
            self._body(self._stop)
        except BaseException as exc:  # noqa: BLE001 - reported, then the process ends
            if not rclpy.ok():   # SIGINT shut rclpy down under a publish: a normal stop
                return
            self.error = exc
            self._node.get_logger().fatal(
                f"{self._thread.name} thread failed:\n{traceback.format_exc()}")
            rclpy.try_shutdown()

    def stop(self) -> None:
        """Stop and join the thread; raises ``RuntimeError`` if it had failed."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        if self.error is not None:
            raise RuntimeError(f"{self._thread.name} thread failed: {self.error!r}")
