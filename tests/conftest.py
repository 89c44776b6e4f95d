"""Shared fixtures: real node processes on a private ROS domain, always torn down.

Tests marked ``ros`` need the stack's ROS environment (what ``scripts/test.sh`` sets up). Started
any other way (``.venv/bin/python -m pytest``), pytest re-executes itself once in that
environment, built as ``scripts/test.sh`` builds it (``qg_bringup.ros_env``): the
interface libraries must be on ``LD_LIBRARY_PATH`` before Python starts, so setting variables
here would not do. If the environment cannot be built (no ``scripts/setup.sh`` yet), the header
says why and every ``ros`` test fails with that reason.
"""
from __future__ import annotations

import contextlib
import itertools
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO

import pytest

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
ROS_READY = os.environ.get("QG_STACK_ENV") == "1"
#: Why the stack environment could not be set up (None: it is set up, or about to be).
_NO_STACK_ENV: str | None = None
#: The test being set up: a Stack started for a test without the ``ros`` mark is refused.
_current_test: pytest.Item | None = None



def _domains() -> Iterator[int]:
    """Domains 150..229 are ours, split evenly between the pytest-xdist workers; each test that
    starts processes takes its worker's next free one (``_take_domain``), so a straggler of one
    test can never answer another test's service calls, on this worker or another."""
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:])
    share = 80 // int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    first, offset = 150 + worker * share, os.getpid() % share
    return itertools.cycle([first + (offset + i) % share for i in range(share)])


_DOMAINS = _domains()
#: One lock file per domain, machine-wide: another pytest run on this host (another checkout's
#: suite, a loop of --count runs) holds the domains it uses, and this run skips them. (Two runs
#: once met on one domain: a learner got the other run's executor's task.)
_DOMAIN_LOCKS = Path(tempfile.gettempdir()) / "qg-ros-domains"


def _take_domain() -> tuple[int, IO[str]]:
    """The next domain of this worker's share that no test on this host holds, and its held
    lock (released when the file is closed: when the ``Stack`` holding it goes)."""
    import fcntl
    _DOMAIN_LOCKS.mkdir(exist_ok=True)
    for _ in range(80):
        domain = next(_DOMAINS)
        lock = open(_DOMAIN_LOCKS / f"{domain}.lock", "a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.close()
            continue
        return domain, lock
    raise RuntimeError(f"every ROS domain of this worker is held by other test runs "
                       f"({_DOMAIN_LOCKS})")


def _run_as_the_pytest_command() -> bool:
    """True for ``python -m pytest`` and the ``pytest`` script; False when another program
    called ``pytest.main()``, whose process is not ours to replace."""
    return Path(sys.argv[0]).name in ("pytest", "py.test", "__main__.py") \
        and len(sys.orig_argv) > 1


def pytest_configure(config: pytest.Config) -> None:
    """Outside the stack environment, re-execute this pytest run inside it (once: the new
    process has ``QG_STACK_ENV=1``)."""
    global _NO_STACK_ENV
    if ROS_READY:
        return
    try:
        from qg_bringup.ros_env import stack_env
        # what scripts/test.sh exports before it builds the same environment
        os.environ.setdefault("QG_ROS_INSTALL", str(ROOT / "ros_ws" / "install"))
        os.environ.setdefault("ROS_LOG_DIR", str(ROOT / "runs" / "ros_log"))
        env = stack_env()
    except Exception as exc:   # whatever is missing is the reason the ros tests give
        _NO_STACK_ENV = (f"{type(exc).__name__}: {exc} (run `bash scripts/setup.sh`, or the "
                         "tests through `bash scripts/test.sh`)")
        return
    if not _run_as_the_pytest_command():
        _NO_STACK_ENV = ("pytest was started by another program, which cannot be restarted in "
                         "the stack environment: run `bash scripts/test.sh` or "
                         "`.venv/bin/python -m pytest`")
        return
    capture = config.pluginmanager.getplugin("capturemanager")
    if capture is not None:
        capture.stop_global_capturing()   # give the new process this one's stdout and stderr
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], env)


def pytest_report_header(config: pytest.Config) -> str:
    if _NO_STACK_ENV is not None:
        return f"stack environment: MISSING, every `ros` test fails: {_NO_STACK_ENV}"
    return "stack environment: set up (QG_STACK_ENV=1)"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Files in the order workers that take whole files finish together: those holding an
    ``alone`` test first (its alone part waits only for the other workers' first tests, not for
    a minute-long one in full swing), then those holding a ``slow`` test, then the other ``ros``
    files, then the in-process ones, small enough to even out the end. Within a file its
    ``alone`` tests come first; the order is otherwise kept. (``scripts/test.sh`` passes
    ``--no-loadscope-reorder``: pytest-xdist would otherwise order the files by their number of
    tests.)"""
    def files(marker: str) -> set:
        return {item.path for item in items if item.get_closest_marker(marker)}

    alone, slow, ros = files("alone"), files("slow"), files("ros")
    rank = {path: 0 if path in alone else 1 if path in slow else 2 if path in ros else 3
            for path in {item.path for item in items}}
    items.sort(key=lambda item: (rank[item.path], item.get_closest_marker("alone") is None))


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    global _current_test
    _current_test = item
    if "ros" in item.keywords and not ROS_READY:
        pytest.fail(f"needs the stack environment: {_NO_STACK_ENV}", pytrace=False)
    if item.get_closest_marker("alone") and "machine_to_itself" not in item.fixturenames:
        pytest.fail("marked `alone` but never takes the machine: time it inside "
                    "`with machine_to_itself():`", pytrace=False)


#: ``--ros-args`` of the robot process for tests whose subject is not the RL step (processes,
#: transport, recording, faults): the pre-rest 0.25 s step limit. The default step ends at rest
#: within ``rest.max_time`` 3 s, which made a realtime step of separate processes last tens of
#: seconds of wall time on two loaded cores and the stack tests 40 % slower.
SHORT_STEP = ("-p", "rest.max_time:=0.25")


class Stack:
    """Node processes started for one test (see :class:`qg_bringup.launcher.Launcher`)."""

    def __init__(self, tmp_path: Path) -> None:
        if _current_test is not None and "ros" not in _current_test.keywords:
            pytest.fail(f"{_current_test.nodeid} starts ROS processes: mark it `ros` (the fast "
                        "tier, scripts/test.sh --fast, must not start any)", pytrace=False)
        from qg_bringup.launcher import Launcher
        from qg_bringup.ros_env import stack_env
        self.domain_id, self._domain_lock = _take_domain()
        self.log_dir = tmp_path / "logs"
        self.env = stack_env(domain_id=str(self.domain_id), log_dir=tmp_path / "ros_log")
        self.env["QG_RUNS_DIR"] = str(tmp_path / "runs")
        self.launcher = Launcher(env=self.env, out=None, log_dir=self.log_dir)

    def start(self, *specs: tuple[str, str, str] | tuple[str, str, str, tuple[str, ...]]) -> None:
        from qg_bringup.stack_file import ProcessSpec
        self.launcher.start([ProcessSpec(*s) for s in specs])

    def client(self, name: str = "test"):
        from qg_common.ros_client import CliNode
        return CliNode(name, domain_id=self.domain_id)

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()}" for p in sorted(self.log_dir.glob("*.log")))

    def stop(self, grace: float = 5.0) -> dict[str, int]:
        return self.launcher.stop(grace)


#: The running test's hold on the shared lock (see ``_machine_lock``): (turnstile, lock).
_held: tuple[IO[str], IO[str]] | None = None


@pytest.fixture(autouse=True)
def _machine_lock(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Under pytest-xdist, the part of a test that times itself by the wall clock (a realtime
    loop's pace, a heartbeat's gaps: ``machine_to_itself``) runs while no other worker runs a
    test, and everything else side by side. A readers-writer lock on a file all workers share:
    every test holds it shared, the timed part exclusive; the turnstile, taken briefly by
    every test and held by a timed part while it waits, keeps the other workers from taking the
    lock shared again and again ahead of it. A long test lets a waiting timed part in between
    its parts (``let_alone_tests_in``)."""
    global _held
    if "PYTEST_XDIST_WORKER" not in os.environ:
        yield
        return
    import fcntl
    shared = tmp_path_factory.getbasetemp().parent
    with open(shared / "alone.turnstile", "a") as turnstile, \
            open(shared / "alone.lock", "a") as lock:
        _held = (turnstile, lock)
        _take(fcntl.LOCK_SH)
        try:
            yield
        finally:
            _held = None


def _take(mode: int) -> None:
    """Let go of the lock, then take it again in ``mode`` (shared or exclusive) through the
    turnstile. Holding nothing while it waits, two tests doing this cannot deadlock."""
    import fcntl
    turnstile, lock = _held
    fcntl.flock(lock, fcntl.LOCK_UN)
    fcntl.flock(turnstile, fcntl.LOCK_EX)     # held by a timed part until it has the lock
    fcntl.flock(lock, mode)
    fcntl.flock(turnstile, fcntl.LOCK_UN)


@pytest.fixture
def machine_to_itself(request: pytest.FixtureRequest
                      ) -> Callable[[], contextlib.AbstractContextManager[None]]:
    """For a test marked ``alone``: ``with machine_to_itself(): ...`` runs the block, the part
    the test times by the wall clock, while no other worker runs a test. Starting its processes
    beforehand, side by side with the other workers, keeps that part, and their idle time,
    short."""
    if request.node.get_closest_marker("alone") is None:
        pytest.fail("machine_to_itself is for tests marked `alone` (they run first)",
                    pytrace=False)

    @contextlib.contextmanager
    def alone() -> Iterator[None]:
        if _held is None:          # not under pytest-xdist: nothing else runs anyway
            yield
            return
        import fcntl
        _take(fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(_held[1], fcntl.LOCK_SH)     # the others may go on
    return alone


@pytest.fixture
def let_alone_tests_in() -> Callable[[], None]:
    """For a test of many parts (episodes): called between two, it lets a timed part waiting
    on another worker run first (without it, one waited 26 s for a 43 s test)."""
    def pause() -> None:
        if _held is None:
            return
        import fcntl
        _take(fcntl.LOCK_SH)
    return pause


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[Stack]:
    s = Stack(tmp_path)
    try:
        yield s
    finally:
        s.stop(grace=3.0)
