"""The launcher's respawn (``qgl up``): a process that exits on its own comes back after its
delay, with its respawn arguments; one that keeps dying is given up on with the reason.

The processes here are tiny Python programs (``ProcessSpec`` with package ""), so the timing
of exits and restarts is the launcher's alone; the real stack's respawn is tested in
``test_training_run.py``.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest
from qg_bringup.launcher import Launcher
from qg_bringup.stack_file import ProcessSpec, RespawnPolicy, StackConfigError, load_stack


def _python(name: str, code: str, **respawn) -> ProcessSpec:
    return ProcessSpec(name, "", sys.executable, ("-c", code), **respawn)


def _launcher(tmp_path: Path, **policy) -> Launcher:
    return Launcher(env={"PATH": "/usr/bin:/bin"}, out=None, log_dir=tmp_path / "logs",
                    policy=RespawnPolicy(**policy))


def test_a_process_that_always_exits_is_restarted_with_backoff_then_stops_the_stack(tmp_path):
    launcher = _launcher(tmp_path, max_restarts=2, window=60.0, backoff=2.0)
    launcher.start([_python("flaky", "exit(3)", respawn=True, respawn_delay=0.1),
                    _python("steady", "import time; time.sleep(60)")])
    t0 = time.monotonic()
    try:
        name, code = launcher.wait_any(period=0.01)
        elapsed = time.monotonic() - t0
        announced = launcher.take_respawns()
    finally:
        codes = launcher.stop(grace=2.0)
    assert (name, code) == ("flaky", 3)
    assert launcher.restarts() == {"flaky": 2, "steady": 0}
    assert [(r.restart, round(r.delay, 3)) for r in announced] == [(1, 0.1), (2, 0.2)]
    assert "keeps dying: it exited 3 times within 60 s (last code 3)" in launcher.reasons["flaky"]
    assert elapsed >= 0.3          # the two delays, 0.1 s then 0.2 s
    assert set(codes) == {"flaky", "steady"}
    assert launcher.take_respawns() == []


def test_a_restarted_process_gets_its_respawn_args_and_runs_on(tmp_path):
    marker, argv_log = tmp_path / "died_once", tmp_path / "argv.txt"
    code = (f"import sys, time, pathlib; m = pathlib.Path({str(marker)!r}); "
            f"open({str(argv_log)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n'); "
            "exit(9) if not m.exists() and not m.touch() else time.sleep(60)")
    launcher = _launcher(tmp_path, max_restarts=1)
    launcher.start([_python("learner", code, respawn=True, respawn_delay=0.05,
                            respawn_args=("-p", "resume:=true"))])
    try:
        deadline = time.monotonic() + 10.0
        while launcher.restarts()["learner"] == 0 and time.monotonic() < deadline:
            assert launcher.poll() == []
            time.sleep(0.01)
        time.sleep(0.5)
        assert launcher.poll() == [], launcher.reasons
        first_pid = launcher.pids()["learner"]
        assert launcher.running[0].popen.poll() is None        # the second one runs on
    finally:
        launcher.stop(grace=2.0)
    assert argv_log.read_text().splitlines() == ["", "--ros-args -p resume:=true"]
    assert first_pid > 0
    log = (tmp_path / "logs" / "learner.log").read_text()
    assert "restarted by the launcher" in log


def test_a_continued_runs_launcher_appends_to_the_logs_of_its_earlier_sessions(tmp_path):
    def session(said: str, **launcher) -> None:
        run = Launcher(env={"PATH": "/usr/bin:/bin"}, out=None, log_dir=tmp_path / "logs",
                       **launcher)
        run.start([_python("learner", f"print({said!r})")])
        assert run.wait_any(period=0.01) == ("learner", 0)
        run.stop(grace=2.0)

    log = tmp_path / "logs" / "learner.log"
    session("crashed in the first session")
    session("continued", append_logs=True)
    lines = log.read_text().splitlines()
    assert lines[0] == "crashed in the first session" and lines[-1] == "continued", lines
    assert len(lines) == 3 and lines[1].startswith("--- started by the launcher (pid "), lines
    session("a new run in the same folder")        # without append_logs: a fresh log
    assert log.read_text() == "a new run in the same folder\n"


def test_a_process_refusing_its_parameters_or_without_respawn_is_not_restarted(tmp_path):
    launcher = _launcher(tmp_path)
    launcher.start([_python("bad_params", "exit(2)", respawn=True, respawn_delay=0.0)])
    try:
        assert launcher.wait_any(period=0.01) == ("bad_params", 2)
    finally:
        launcher.stop(grace=1.0)
    assert "refused its parameters" in launcher.reasons["bad_params"]
    assert launcher.restarts() == {"bad_params": 0}
    plain = _launcher(tmp_path)
    plain.start([_python("once", "exit(4)")])
    try:
        assert plain.wait_any(period=0.01) == ("once", 4)
    finally:
        plain.stop(grace=1.0)
    assert plain.take_respawns() == []


def test_stopping_cancels_a_pending_restart(tmp_path):
    launcher = _launcher(tmp_path)
    launcher.start([_python("x", "exit(5)", respawn=True, respawn_delay=0.3)])
    deadline = time.monotonic() + 10.0
    while not launcher.respawns and time.monotonic() < deadline:
        launcher.poll()
        time.sleep(0.01)
    launcher.stop(grace=1.0)
    time.sleep(0.4)
    assert launcher.poll() == [] and launcher.restarts() == {"x": 0}


def test_the_stack_file_sets_respawn_defaults_policy_and_per_process_overrides(tmp_path):
    cfg = tmp_path / "stack.yaml"
    cfg.write_text("respawn: {enabled: true, delay: 2.0, max_restarts: 3, window: 30,\n"
                   "          args: [-p, 'a:=1']}\n"
                   "processes:\n"
                   "  - {name: robot, package: p, executable: robot}\n"
                   "  - {name: learner, package: p, executable: learner, respawn_delay: 0.5,\n"
                   "     respawn_args: [-p, 'resume:=true']}\n"
                   "  - {name: tool, package: p, executable: tool, respawn: false}\n")
    specs, policy = load_stack(cfg)
    assert [(s.name, s.respawn, s.respawn_delay, s.respawn_args) for s in specs] == [
        ("robot", True, 2.0, ("-p", "a:=1")), ("learner", True, 0.5, ("-p", "resume:=true")),
        ("tool", False, 2.0, ("-p", "a:=1"))]
    assert (policy.max_restarts, policy.window) == (3, 30.0)
    assert policy.delay(1.0, 1) == 1.0 and policy.delay(1.0, 3) == 4.0
    assert policy.delay(1.0, 10) == policy.max_delay
    cfg.write_text("processes:\n  - {name: robot, package: p, executable: robot}\n")
    (spec,), _ = load_stack(cfg)
    assert not spec.respawn                       # no section: nothing respawns


@pytest.mark.parametrize("text, message", [
    ("respawn: {enabled: yes please}\n", "respawn.enabled must be true or false"),
    ("respawn: {max_restarts: 1.5}\n", "respawn.max_restarts must be an integer"),
    ("respawn: {window: -1}\n", "window > 0"),
    ("respawn: {restarts: 3}\n", "'respawn:' takes"),
])
def test_a_bad_respawn_section_is_refused_with_the_reason(tmp_path, text, message):
    cfg = tmp_path / "stack.yaml"
    cfg.write_text(text + "processes:\n  - {name: robot, package: p, executable: robot}\n")
    with pytest.raises(StackConfigError, match=message.replace("(", r"\(")):
        load_stack(cfg)


def test_the_shipped_stack_files_respawn_and_the_learner_resumes():
    root = Path(__file__).resolve().parents[2] / "config"
    for name in ("stack.yaml", "stack_nextage.yaml"):
        specs, policy = load_stack(root / name)
        assert all(s.respawn for s in specs), name
        (learner,) = [s for s in specs if s.executable == "learner"]
        assert learner.respawn_args == ("-p", "resume:=true"), name
        assert policy.max_restarts >= 1
