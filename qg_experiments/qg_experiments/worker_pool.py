"""A pool of worker processes that notices when one of them dies.

``multiprocessing.Pool`` replaces a worker that dies (a crash in native code, the kernel's
out-of-memory killer, a ``kill -9``) and loses the task it held: ``imap_unordered`` then never
yields that result, and a sweep waits forever without a word (a worker that calls ``os._exit``
hangs it; tried on this machine). A sweep of the thesis's budget runs for hours unattended, so
here each worker takes one task at a time over a pipe of its own, and the parent waits on the
pipes and the processes' sentinels together: a worker that exits without its result stops the
sweep at once, naming the task and the exit code. What the sweep saved stays (each finished run,
and a long run's progress: ``run_progress``), so running the same command again continues.

A task that raises stops the sweep with that exception, as ``Pool`` does. Workers are spawned
(not forked: the parent may hold threads and a ROS context) and reused from task to task.
"""
from __future__ import annotations

import multiprocessing
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from typing import Any

__all__ = ["RemoteTraceback", "WorkerDied", "pool_results"]


class WorkerDied(RuntimeError):
    """A worker process ended without the result of the task it held."""


@dataclass
class _Worker:
    process: BaseProcess
    conn: Connection
    task: Any = None


class RemoteTraceback(Exception):
    """Where a task raised, in its worker: the cause of the exception the parent raises."""


def _serve(function: Callable[[Any], Any], conn: Connection) -> None:
    """A worker: take a task, send back ``(True, result)`` or ``(False, what it raised, its
    traceback)``, until ``None`` comes."""
    while (task := conn.recv()) is not None:
        try:
            conn.send((True, function(task), None))
        except BaseException as exc:      # noqa: BLE001 - the parent raises it
            trace = traceback.format_exc()
            try:
                conn.send((False, exc, trace))
            except Exception:             # noqa: BLE001 - it does not pickle: its text does
                conn.send((False, RuntimeError(repr(exc)), trace))


def _name(task: Any) -> str:
    return str(getattr(task, "name", task))


def pool_results(function: Callable[[Any], Any], tasks: Iterable[Any], workers: int
                 ) -> Iterator[Any]:
    """``function(task)`` of every task on ``workers`` spawned processes, each result as it
    comes (in no fixed order); the workers end with the iteration, or when it is abandoned.

    :raises WorkerDied: a worker exited (a crash, a kill) before it sent its task's result.
    """
    context = multiprocessing.get_context("spawn")
    queue = list(tasks)[::-1]
    pool: list[_Worker] = []
    try:
        for _ in range(min(workers, len(queue))):
            parent, child = context.Pipe()
            process = context.Process(target=_serve, args=(function, child), daemon=True)
            process.start()
            child.close()
            pool.append(_Worker(process, parent))
        for worker in pool:
            worker.task = queue.pop()
            worker.conn.send(worker.task)
        while busy := [w for w in pool if w.task is not None]:
            wait([w.conn for w in busy] + [w.process.sentinel for w in busy])
            for worker in busy:
                if worker.conn.poll():
                    try:
                        ok, value, trace = worker.conn.recv()
                    except EOFError:          # it died while it sent
                        ok = None
                    if ok is not None:
                        if not ok:
                            raise value from RemoteTraceback(trace)
                        worker.task = queue.pop() if queue else None
                        if worker.task is not None:
                            worker.conn.send(worker.task)
                        yield value
                        continue
                if not worker.process.is_alive():
                    worker.process.join()
                    raise WorkerDied(
                        f"a worker process died (exit code {worker.process.exitcode}) while "
                        f"it ran {_name(worker.task)}; what the sweep saved stays: run the same "
                        "command again to continue")
    finally:
        for worker in pool:
            if worker.task is None and worker.process.is_alive():
                try:
                    worker.conn.send(None)    # done: it ends by itself
                except OSError:
                    pass
            else:                             # abandoned mid-task: an exception, Ctrl-C
                worker.process.terminate()
        for worker in pool:
            worker.process.join(timeout=5.0)
            if worker.process.is_alive():
                worker.process.kill()
                worker.process.join()
            worker.conn.close()
