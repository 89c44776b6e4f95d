"""The peg's sections of results.md written alone, from saved runs and from the episode rows of
runs whose JSON is gone (``episode_rows``, ``report.peg_block``, ``peg_report``)."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from qg_experiments.core.stack_settings import config_digest
from qg_experiments.episode_rows import ROWS, identities_path, runs_from_rows, with_rows
from qg_experiments.peg import PegRandomSpec, PegRunSpec, peg_random_specs, peg_specs
from qg_experiments.peg_report import main, write_section
from qg_experiments.profile import load_profile
from qg_experiments.report.markdown import PEG_BLOCK
from qg_experiments.report.peg_block import peg_rows, peg_runs
from qg_experiments.report.tables import episodes_csv


def _episodes(spec, seed: int) -> list[dict]:
    """Episodes as a run saves them: the learners' with their mean Q, a random policy's
    without; a success in the last, returns that differ by seed and in their last digits."""
    rng = np.random.default_rng(seed)
    return [{"episode": k, "steps": 4 - (k == spec.episodes - 1), "success":
             k == spec.episodes - 1, "return": float(-4 + rng.normal()),
             **({} if isinstance(spec, PegRandomSpec) else {"mean_q": float(rng.normal())})}
            for k in range(spec.episodes)]


def _run(spec, whole: bool) -> dict:
    """A run of ``spec`` as the sweep saves it, on this machine's config; ``whole``: with its
    final Q and timing (what rows do not keep)."""
    run = {"experiment": spec.experiment, "name": spec.name, "spec": spec.__dict__.copy(),
           "config_digest": config_digest(), "task_settings": spec.task_settings,
           "episodes": _episodes(spec, spec.seed * 7 + len(spec.name))}
    if isinstance(spec, PegRandomSpec):
        run["label"] = spec.label
    if whole:
        q = 1.0 + spec.seed
        run.update({"q_given": np.full((27, 11), q).tolist(), "q_pi": np.full(27, q).tolist(),
                    "wall_time": 2.0, "cpu_time": 1.5, "rl_steps": 7,
                    "code": {"commit": "f" * 40, "modified": False}})
    return run


def test_a_run_reads_back_from_its_rows_as_it_was_saved(tmp_path) -> None:
    learner = PegRunSpec("qgddpg", 1e-3, seed=3, episodes=3)
    random = PegRandomSpec(kind="uniform", seed=3, episodes=3)
    short = PegRunSpec("ddpg", 1e-3, seed=3, episodes=3)
    runs = [_run(learner, whole=True), _run(random, whole=False)]
    cut = _run(short, whole=False)
    cut["episodes"] = cut["episodes"][:2]                  # a run stopped part way
    episodes_csv(tmp_path / "peg_episodes.csv", [*runs, cut])
    read = {r["name"]: r for r in runs_from_rows(tmp_path / "peg_episodes.csv",
                                                 [learner, random, short])}
    assert sorted(read) == sorted([learner.name, random.name])   # not the run cut short
    for run in runs:   # every episode field to the last bit, and the spec the profile gives
        assert read[run["name"]]["episodes"] == run["episodes"]
        assert read[run["name"]]["spec"] == run["spec"] and read[run["name"]]["source"] == ROWS
    assert read[random.name]["label"] == "random (uniform)"
    assert "q_given" not in read[learner.name] and "wall_time" not in read[learner.name]
    # Rows made by another run of the same name are not this run's: another number of updates
    # after each episode, other config files.
    edited = dataclasses.replace(learner, train_iterations=learner.train_iterations + 1)
    assert runs_from_rows(tmp_path / "peg_episodes.csv", [edited]) == []
    other = json.loads(identities_path(tmp_path / "peg_episodes.csv").read_text())
    other[learner.name]["config_digest"] = "another arm"
    identities_path(tmp_path / "peg_episodes.csv").write_text(json.dumps(other))
    assert [r["name"] for r in runs_from_rows(tmp_path / "peg_episodes.csv",
                                              [learner, random])] == [random.name]
    # Rows of a run the specs do not name are not read; a saved run wins over its rows.
    assert runs_from_rows(tmp_path / "peg_episodes.csv", [random]) == [read[random.name]]
    saved = {**runs[0], "episodes": runs[0]["episodes"][::-1]}
    merged = with_rows([saved], tmp_path / "peg_episodes.csv", [learner, random])
    assert "another arm" not in json.dumps(merged)
    assert [r["name"] for r in merged] == sorted([learner.name, random.name])
    assert merged[[r["name"] for r in merged].index(learner.name)] is saved
    assert runs_from_rows(tmp_path / "absent.csv", [learner]) == []


def test_the_peg_sections_are_written_alone_from_saved_runs_and_rows(tmp_path) -> None:
    """Seed 0's learners saved whole, seed 1's and every random policy only as episode rows:
    the block says so, pairs both seeds, takes the Q spread over the whole runs only (too few
    here: one seed), and leaves the page around it as it was."""
    profile = load_profile("tiny")
    out, docs = tmp_path / "runs", tmp_path / "docs"
    learners, randoms = peg_specs(profile.peg), peg_random_specs(profile.peg)
    for spec in learners:
        if spec.seed == 0:
            path = out / profile.name / "peg" / f"{spec.name}.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(_run(spec, whole=True)))
    data = docs / "data" / profile.name
    data.mkdir(parents=True)
    rows = [_run(spec, whole=False) for spec in learners if spec.seed == 1]
    episodes_csv(data / "peg_episodes.csv", rows)
    episodes_csv(data / "peg_random_episodes.csv", [_run(s, whole=False) for s in randoms])
    before, after = "# Results\n\n## 4. Variants\n\ntext\n\n", "\n\n## 7. Against\n\nmore\n"
    page = docs / "results.md"
    page.write_text(before + PEG_BLOCK[0] + "\nold peg text\n" + PEG_BLOCK[1] + after)

    assert peg_rows(profile, docs) == {spec.name for spec in [*learners, *randoms]
                                       if spec.seed == 1 or spec in randoms}
    assert write_section(profile, out, docs) == page
    text = page.read_text()
    assert text.startswith(before) and text.endswith(after) and "old peg text" not in text
    block = text[len(before):-len(after)]
    assert block.startswith(PEG_BLOCK[0]) and block.endswith(PEG_BLOCK[1])
    assert "## 5. Clearance-fit peg" in block and "## 6. The peg on the simulated Nextage" in block
    assert (f"Runs finished: {len(learners)} of {len(learners)} learners, {len(randoms)} of "
            f"{len(randoms)} random policies. {2 + len(randoms)} of them are read back from "
            f"their episode rows") in block
    assert "over the 2 runs that kept their timing, 14 RL steps in 0.1 worker-minutes" in block
    assert f"config digest(s) `{config_digest()}`; made at `ffffffffff` (2 runs)" in block
    (pair,) = [line for line in block.splitlines() if line.startswith("| 0.001 | 2 (0, 1) |")]
    assert pair.count("n/a") == 3          # the spread needs two whole seeds, its ratio five
    assert "| random (uniform) | - | 2 |" in block
    # The CSV keeps seed 1's rows and gains seed 0's, read from its saved runs.
    assert {r["name"] for r in runs_from_rows(data / "peg_episodes.csv", learners)} == \
        {spec.name for spec in learners}
    assert Path(docs / "figures" / "exp5_peg_learning.png").stat().st_size > 1000
    # A saved run made under other config files is not the profile's run, nor are its rows.
    stale = next(spec for spec in learners if spec.seed == 0)
    path = out / profile.name / "peg" / f"{stale.name}.json"
    path.write_text(json.dumps({**_run(stale, whole=True), "config_digest": "another arm"}))
    identities = json.loads(identities_path(data / "peg_episodes.csv").read_text())
    identities[stale.name]["config_digest"] = "another arm"
    identities_path(data / "peg_episodes.csv").write_text(json.dumps(identities))
    results, _ = peg_runs(profile, out / profile.name, docs, "peg")
    assert sorted(r["name"] for r in results) == sorted(s.name for s in learners if s != stale)


def test_the_command_refuses_a_page_without_the_block_or_a_profile_and_writes_nothing(
        tmp_path, capsys) -> None:
    page = f"# Results\n\n{PEG_BLOCK[0]}\n{PEG_BLOCK[1]}\n"
    for argv, text, message in (
            (["--docs", str(tmp_path / "docs")], page, "no peg sections between markers in"),
            (["--docs", str(tmp_path)], "# An older page\n\n## 5. Clearance-fit peg\n",
             "write the whole page once"),
            (["--docs", str(tmp_path), "--profile", "nosuch"], page, "unknown profile 'nosuch'")):
        (tmp_path / "results.md").write_text(text)
        with pytest.raises(SystemExit) as stop:
            main([*argv, "--out", str(tmp_path / "runs")])
        assert stop.value.code == 2 and message in capsys.readouterr().err
        assert sorted(p.name for p in tmp_path.iterdir()) == ["results.md"]
        assert (tmp_path / "results.md").read_text() == text
