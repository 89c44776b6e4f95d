"""A peg run stopped part way continues from its saved progress to the result it would have had.

A thesis-budget peg run is ~15 min of a core and a sweep of 60 spans sessions; a sweep stopped
mid-run must not start that run over (``run_progress``). The runs here are a few short episodes
with a handful of updates each, enough for the networks, replay memory, graph and sampling
generator to matter to the bit.
"""
from __future__ import annotations

import json

import pytest
from qg_experiments import run_progress
from qg_experiments.peg import PegRunSpec, run_peg
from qg_experiments.run_progress import RunProgress, peek, progress_path
from qg_experiments.tasks import result_path, run_specs
from qg_learning_node.learner.learner_core import LearnerCore

SPEC = PegRunSpec(algorithm="qgddpg", lr=1e-3, seed=5, episodes=4, train_iterations=5,
                  episode_steps=30)
#: What a continued run adds to, or has other than, its result.
BESIDE = ("wall_time", "cpu_time", "code", "resumed")


def numbers(result: dict) -> dict:
    return {k: v for k, v in result.items() if k not in BESIDE}


def stop_in_episode(monkeypatch: pytest.MonkeyPatch, episode: int) -> None:
    """A sweep stopped (Ctrl-C) in the training after episode ``episode`` (counted from 1)."""
    original, cycles = LearnerCore.train_cycle, []

    def train_cycle(self: LearnerCore) -> dict:
        cycles.append(1)
        if len(cycles) == episode:
            raise KeyboardInterrupt
        return original(self)

    monkeypatch.setattr(LearnerCore, "train_cycle", train_cycle)


@pytest.fixture
def save_every_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(run_progress, "PROGRESS_EVERY", 0.0)


def test_a_sweep_stopped_mid_run_continues_the_run_to_the_same_result(
        tmp_path, monkeypatch, capsys, save_every_episode):
    straight = run_peg(SPEC)
    assert "resumed" not in straight
    with monkeypatch.context() as patch:
        stop_in_episode(patch, 3)
        with pytest.raises(KeyboardInterrupt):
            run_specs([SPEC], tmp_path, workers=1)
    progress = progress_path(tmp_path, SPEC)
    assert {k: peek(progress)[k] for k in ("done", "of")} == {"done": 2, "of": SPEC.episodes}
    saved = RunProgress(progress, SPEC).load()
    assert [e["episode"] for e in saved["episodes"]] == [0, 1]
    assert saved["episodes"] == straight["episodes"][:2]
    assert not result_path(tmp_path, SPEC).exists()

    (result,) = run_specs([SPEC], tmp_path, workers=1)
    assert f"1 run(s) continue from saved progress ({SPEC.name})" in capsys.readouterr().out
    assert numbers(result) == numbers(straight)        # episodes, final Q: to the bit
    assert [r["episode"] for r in result["resumed"]] == [2]
    assert result["resumed"][0]["code"] == result["code"]
    assert result["wall_time"] > saved["wall_time"]
    assert result["cpu_time"] > saved["cpu_time"] > 0.0      # both sessions' CPU
    assert not progress.exists()                        # the result is what stays
    assert json.loads(result_path(tmp_path, SPEC).read_text())["resumed"] == result["resumed"]


def test_progress_of_another_setting_or_a_broken_file_is_started_over(
        tmp_path, monkeypatch, save_every_episode):
    other = PegRunSpec(algorithm="qgddpg", lr=1e-2, seed=5, episodes=4, train_iterations=5,
                       episode_steps=30)
    path = tmp_path / "run.progress.pt"
    with monkeypatch.context() as patch:
        stop_in_episode(patch, 2)
        with pytest.raises(KeyboardInterrupt):
            run_peg(other, path)
    assert RunProgress(path, other).load()["episodes"][0]["episode"] == 0
    with pytest.warns(UserWarning, match="another setting"):
        assert RunProgress(path, SPEC).load() is None
    path.write_bytes(b"not a checkpoint")
    with pytest.warns(UserWarning, match="does not load"):
        result = run_peg(SPEC, path)
    assert "resumed" not in result and len(result["episodes"]) == SPEC.episodes
    assert not path.exists()


def test_progress_is_saved_only_every_so_often(tmp_path):
    keeper = RunProgress(tmp_path / "p.progress.pt", SPEC, every=3600.0)
    assert not keeper.save({"episodes": []}, 0, 4, 0.0)
    assert not keeper.path.exists() and peek(keeper.path) is None
    assert keeper.save({"episodes": []}, 0, 4, 1.5, force=True) and keeper.path.exists()
    assert RunProgress(keeper.path, SPEC).load()["episodes"] == []
    assert peek(keeper.path)["wall_time"] == 1.5


def test_the_status_of_a_sweep_counts_saved_running_and_waiting_runs_and_the_time_left(
        tmp_path, monkeypatch, save_every_episode):
    from qg_experiments.sweep_status import sweep_status
    saved, running, waiting = (PegRunSpec(algorithm="qgddpg", lr=1e-3, seed=seed, episodes=4,
                                          train_iterations=5, episode_steps=30)
                               for seed in (5, 6, 7))
    run_specs([saved], tmp_path, workers=1)
    path = result_path(tmp_path, saved)   # as if the run had taken an hour of CPU, paused for
    path.write_text(json.dumps({**json.loads(path.read_text()),     # another (its CPU counts)
                                "cpu_time": 3600.0, "wall_time": 7200.0}))
    with monkeypatch.context() as patch:
        stop_in_episode(patch, 3)
        with pytest.raises(KeyboardInterrupt):
            run_specs([running], tmp_path, workers=1)
    lines = sweep_status([saved, running, waiting], tmp_path, workers=2)
    assert lines[0] == "peg: 1 of 3 runs saved, 1 under way, 1 waiting"
    assert lines[1].startswith(f"  {running.name}: episode 2 of 4, ")
    # an hour a run: the waiting one and half of the one under way
    assert lines[2] == "  left: ~1.5 worker-hours (60.0 min a saved run)"
    assert lines[3] == "left in all: ~0.8 h on 2 worker(s), at the saved runs' pace"
    assert sweep_status([saved], tmp_path, workers=2) == [
        "peg: 1 of 1 runs saved, 0 under way, 0 waiting"]
    # Runs the page reports from their episode rows (a saved one among them is not counted).
    assert sweep_status([saved, running, waiting], tmp_path, workers=2,
                        rows={saved.name, waiting.name})[1] == (
        "  1 of the 2 not saved are reported from their episode rows; they run again for their "
        "final Q and timing")
    # The waiting run saved too, without its CPU time (as runs were saved before they recorded
    # it) and with 5 h of pauses in its wall time: the estimate leaves it out.
    run_specs([waiting], tmp_path, workers=1)
    other = result_path(tmp_path, waiting)
    other.write_text(json.dumps({**json.loads(other.read_text()), "cpu_time": None,
                                 "wall_time": 18000.0}))
    lines = sweep_status([saved, running, waiting], tmp_path, workers=2)
    assert lines[0] == "peg: 2 of 3 runs saved, 1 under way, 0 waiting"
    assert lines[2] == "  left: ~0.5 worker-hours (60.0 min a saved run)"
