"""The sweep's worker pool gives every result, raises what a task raised, and stops with the
task's name when a worker dies, where ``multiprocessing.Pool`` waits forever."""
from __future__ import annotations

import multiprocessing
import os
import time

import pytest
from qg_experiments.worker_pool import RemoteTraceback, WorkerDied, pool_results


def pid_after(seconds: float) -> int:
    """The worker's pid, after a wait (so that both workers get tasks)."""
    time.sleep(seconds)
    return os.getpid()


def test_every_task_is_done_once_on_reused_workers() -> None:
    pids = list(pool_results(pid_after, [0.05] * 6, workers=2))
    assert len(pids) == 6 and len(set(pids)) == 2 and os.getpid() not in pids
    assert sorted(pool_results(abs, [-3, 1, -2], workers=4)) == [1, 2, 3]   # 3 workers
    assert list(pool_results(abs, [], workers=2)) == []
    assert not multiprocessing.active_children()


def test_a_task_that_raises_stops_the_sweep_with_its_exception_and_traceback() -> None:
    with pytest.raises(ValueError, match="invalid literal") as raised:
        list(pool_results(int, ["1", "2", "three", "4"], workers=2))
    assert isinstance(raised.value.__cause__, RemoteTraceback)
    assert "ValueError" in str(raised.value.__cause__)
    assert not multiprocessing.active_children()


def test_a_worker_that_dies_stops_the_sweep_naming_its_task() -> None:
    start = time.monotonic()
    results = pool_results(os._exit, [7], workers=2)     # the worker exits with code 7
    with pytest.raises(WorkerDied, match=r"exit code 7\) while it ran 7; what the sweep saved"):
        list(results)
    assert time.monotonic() - start < 30.0
    assert not multiprocessing.active_children()
