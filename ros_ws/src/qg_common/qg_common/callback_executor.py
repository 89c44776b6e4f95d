"""rclpy's ``MultiThreadedExecutor`` without its busy loop.

In this rclpy (Jazzy, 7.1.x) the executor re-offers every callback task that is *queued* in its
thread pool but not yet running (``Executor._wait_for_ready_callbacks`` yields any task that is
"not executing and not done"), and ``MultiThreadedExecutor`` submits it again, without waiting.
So while one callback waits for a free worker, the spinning thread loops at full speed, holds the
GIL and keeps the workers from starting it: the busy loop feeds itself (rclpy issues #1223 and
#1452, fixed upstream after this release). Measured here with py-spy during training episodes:
the executor process spent 84 % of its samples in that loop and used 50-106 % of a core, the
robot process 35 % of its samples, beside its 1 kHz loop thread.

``CallbackThreadPool`` submits a task once and, when it is offered again while still in the
pool, waits for the pool to finish something instead of submitting it again.
"""
from __future__ import annotations

import threading
from collections.abc import Callable

from rclpy.context import Context
from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    MultiThreadedExecutor,
    ShutdownException,
    TimeoutException,
)
from rclpy.task import Task

__all__ = ["CallbackThreadPool", "REOFFER_WAIT"]

#: [s] The longest the spinning thread waits when it is offered a task still in the pool; a
#: finished callback wakes it at once.
REOFFER_WAIT = 0.005


class CallbackThreadPool(MultiThreadedExecutor):
    """Runs callbacks in a pool of threads, each task submitted once (see the module doc).

    :param num_threads: worker threads in the pool.
    :param context: the rclpy context (default: the global one).
    """

    def __init__(self, num_threads: int, *, context: Context | None = None) -> None:
        super().__init__(num_threads=num_threads, context=context)
        self._in_pool: set[Task] = set()          # submitted, not yet returned from the pool
        self._pool_moved = threading.Condition()

    def _spin_once_impl(self, timeout_sec: float | None = None,
                        wait_condition: Callable[[], bool] = lambda: False) -> None:
        try:
            handler, _, _ = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ExternalShutdownException, ShutdownException, TimeoutException,
                ConditionReachedException):
            return
        with self._pool_moved:
            if handler in self._in_pool:
                self._pool_moved.wait(REOFFER_WAIT)
                return
            self._in_pool.add(handler)
        self._executor.submit(self._run, handler)
        self._futures.append(handler)
        for task in self._futures[:]:     # as rclpy does: a callback's exception ends the spin
            if task.done():
                self._futures.remove(task)
                task.result()

    def _run(self, handler: Task) -> None:
        """A worker's job: the task, then tell the spinning thread the pool moved."""
        try:
            handler()
        finally:
            with self._pool_moved:
                self._in_pool.discard(handler)
                self._pool_moved.notify_all()
