"""The suite's lock between pytest-xdist workers (``tests/conftest.py``): the timed part of an
``alone`` test never overlaps another test, its untimed part does, and a test marked ``alone``
that never takes the machine fails with the reason. An inner pytest run of two workers on
small test files that log when their parts start and end."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

TIMED = '''
import time, pytest
from spans import span

@pytest.mark.alone
def test_timed(machine_to_itself):
    with span("untimed"):
        time.sleep(1.0)
    with machine_to_itself(), span("timed"):
        time.sleep(1.0)

@pytest.mark.alone
def test_marked_but_untimed():
    pass
'''

OTHERS = '''
import time, pytest
from spans import span

@pytest.mark.parametrize("k", range(12))
def test_other(k):
    with span(f"other{k}"):
        time.sleep(0.25)
'''

SPANS = '''
import contextlib, os, time

@contextlib.contextmanager
def span(name):
    start = time.monotonic()
    yield
    with open(os.environ["SPANS"], "a") as f:
        f.write(f"{name} {start} {time.monotonic()}\\n")
'''


@pytest.mark.ros      # full tier only: two pytest-xdist workers of its own (5 s), for a lock
                      # that only the full tier's `alone` tests take
def test_only_the_timed_part_of_an_alone_test_has_the_machine_to_itself(tmp_path: Path) -> None:
    shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "conftest.py")
    shutil.copy(ROOT / "pytest.ini", tmp_path / "pytest.ini")
    (tmp_path / "pytest.ini").write_text((tmp_path / "pytest.ini").read_text()
                                         .replace("testpaths = tests", "testpaths = ."))
    (tmp_path / "spans.py").write_text(SPANS)
    (tmp_path / "test_timed.py").write_text(TIMED)
    (tmp_path / "test_others.py").write_text(OTHERS)
    spans = tmp_path / "spans.txt"
    env = {"PATH": "/usr/bin:/bin", "QG_STACK_ENV": "1", "SPANS": str(spans),
           "PYTHONPATH": str(tmp_path)}
    result = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "--dist", "loadfile",
                             "--no-loadscope-reorder", "-p", "no:cacheprovider", "-q", "-rA"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert "13 passed, 1 error" in result.stdout, result.stdout[-3000:] + result.stderr[-2000:]
    assert "marked `alone` but never takes the machine" in result.stdout
    parts = {name: (float(a), float(b))
             for name, a, b in (line.split() for line in spans.read_text().splitlines())}
    timed, untimed = parts.pop("timed"), parts.pop("untimed")
    assert not [n for n, (a, b) in parts.items() if a < timed[1] and timed[0] < b], parts
    assert [n for n, (a, b) in parts.items() if a < untimed[1] and untimed[0] < b], parts
