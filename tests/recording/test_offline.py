"""Rebuilding the learner from recorded transitions reproduces the online graph census."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
from qg_bringup.bag_commands import add_parsers  # noqa: E402
from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore  # noqa: E402
from qg_learning_node.learner.offline import rebuild_from_bags  # noqa: E402
from qg_recording.episode_recorder import EpisodeRecorder  # noqa: E402

ZERO = (0.0, 0.0)


def random_walk_episodes(n_episodes: int, steps: int, seed: int) -> list[list[tuple]]:
    """Transitions on a small integer grid with the goal at the origin (loops, dead ends, goal)."""
    rng = np.random.default_rng(seed)
    moves = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], dtype=float)
    episodes = []
    for _ in range(n_episodes):
        s, transitions = rng.integers(-3, 4, size=2).astype(float), []
        for step in range(steps):
            a = moves[rng.integers(4)]
            s_next = np.clip(s + a, -3, 3)
            terminal = bool(np.all(s_next == 0))
            transitions.append((step, s / 3, a, -1.0 + 10.0 * terminal, s_next / 3, terminal))
            if terminal:
                break
            s = s_next
        episodes.append(transitions)
    return episodes


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[list[tuple]]]:
    runs = tmp_path_factory.mktemp("runs")
    episodes = random_walk_episodes(6, 40, seed=1)
    recorder = EpisodeRecorder(runs)
    t = 1_000_000_000
    for k, transitions in enumerate(episodes):
        recorder.start(f"ep_{k:03d}")
        for step, s, a, r, s_next, terminal in transitions:
            t += 10_000_000
            recorder.record_transition(t, step, s, a, r, s_next, terminal, zero_action=False)
        recorder.stop()
    return runs, episodes


def online_core(episodes: list[list[tuple]], config: LearnerConfig) -> LearnerCore:
    core = LearnerCore(config, state_dim=2, action_dim=2)
    for transitions in episodes:
        for _, s, a, r, s_next, terminal in transitions:
            core.add_transition(s, a, r, s_next, terminal)
    return core


@pytest.mark.parametrize("capacity", [None, 50])
def test_rebuild_reproduces_the_census(recorded, capacity: int | None) -> None:
    runs, episodes = recorded
    config = LearnerConfig(zero_action=ZERO, replay_capacity=capacity)
    expected = online_core(episodes, config)
    bags = sorted(runs.iterdir())
    result = rebuild_from_bags(bags, config=config)
    assert result.transitions == sum(len(e) for e in episodes) == expected.steps
    assert result.episodes == tuple(f"ep_{k:03d}" for k in range(len(episodes)))
    assert result.census == expected.graph.census()
    assert result.census["total"] > 0 and result.census["connected"] + result.census["directly_connected"] > 0
    assert len(result.learner_core.replay) == len(expected.replay)


def test_rebuild_in_another_order_gives_another_fifo_graph(recorded) -> None:
    runs, episodes = recorded
    config = LearnerConfig(zero_action=ZERO, replay_capacity=30)
    forward = rebuild_from_bags(sorted(runs.iterdir()), config=config).census
    backward = rebuild_from_bags(sorted(runs.iterdir(), reverse=True), config=config).census
    assert forward == online_core(episodes, config).graph.census()
    assert forward != backward  # the check above can tell a wrong order


def test_training_after_the_rebuild(recorded) -> None:
    runs, _ = recorded
    config = LearnerConfig(zero_action=ZERO, iterations_per_cycle=5, batch_size=16)
    result = rebuild_from_bags(sorted(runs.iterdir()), config=config, train_iterations=7)
    assert result.train_iterations == 10  # whole cycles
    assert result.learner_core.actor_version == 2
    assert np.isfinite(result.diagnostics["critic_loss"])


def test_a_rebuild_with_progress_counts_bags_and_cycles_with_a_rate(
        recorded, capsys: pytest.CaptureFixture) -> None:
    runs, _ = recorded
    bags = sorted(runs.iterdir())
    config = LearnerConfig(zero_action=ZERO, iterations_per_cycle=5, batch_size=16)
    rebuild_from_bags(bags, config=config, train_iterations=10, progress=True)
    err = capsys.readouterr().err
    assert "rebuild: 100%" in err and f"{len(bags)}/{len(bags)}" in err and "bag/s" in err
    assert "train: 100%" in err and "2/2" in err and "cycle/s" in err


def test_qgl_replay_into_learner(recorded, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    runs, episodes = recorded
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="command"))
    (tmp_path / "learner.yaml").write_text("/**:\n  ros__parameters:\n    zero_action: [0.0, 0.0]\n")
    args = parser.parse_args(["replay", str(runs), "--into-learner", "--learner-config",
                              str(tmp_path / "learner.yaml"), "--save-checkpoint", str(tmp_path / "ckpt.pt")])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    census = online_core(episodes, LearnerConfig(zero_action=ZERO)).graph.census()
    assert f"transitions: {sum(len(e) for e in episodes)} from {len(episodes)} episode(s)" in out
    assert f"'connected': {census['connected']}" in out
    assert LearnerCore.load(tmp_path / "ckpt.pt").graph.census() == census


def test_bags_of_two_robots_are_merged_by_log_time_into_one_chain_per_robot(
        tmp_path: Path) -> None:
    """Two robots, two bags each, recorded at the same time: each robot's second episode goes
    on from where its first stopped (a cut, not the goal). The one learner got the robots'
    steps alternately, each tagged with its robot; the rebuild from the bags, listed by start
    time as `qgl replay` lists a runs folder, must store the same memory: the same order, the
    same neighbours (across each robot's two bags too) and the same chain ends."""
    walks = {robot: random_walk_episodes(1, 24, seed=seed)[0] for robot, seed in
             (("robot0", 3), ("robot1", 4))}
    arrivals = []                               # (t_ns, robot, transition): what the learner got
    for k, (robot, walk) in enumerate(walks.items()):
        assert not any(t[-1] for t in walk[:12])        # no goal before the cut
        for i, transition in enumerate(walk):
            arrivals.append((1_000_000_000 + 20_000_000 * i + 10_000_000 * k, robot, transition))
    arrivals.sort(key=lambda a: a[0])
    bags = []
    for part, (start, stop) in enumerate(((0, 12), (12, None))):
        for robot, walk in walks.items():
            recorder = EpisodeRecorder(tmp_path)
            bags.append(recorder.start(f"{robot}_20260101_120000_{part:04d}_train_p{part}"))
            for t, r, (step, s, a, reward, s_next, terminal) in arrivals:
                if r == robot and (step >= start) and (stop is None or step < stop):
                    recorder.record_transition(t, step - start, s, a, reward, s_next, terminal)
            recorder.stop()
    config = LearnerConfig(zero_action=ZERO)
    online = LearnerCore(config, state_dim=2, action_dim=2)
    for _, robot, (_, s, a, reward, s_next, terminal) in arrivals:
        online.add_transition(s, a, reward, s_next, terminal, robot=robot)

    result = rebuild_from_bags(bags, config=config)
    rebuilt, expected = result.learner_core.replay.state_dict(), online.replay.state_dict()
    assert result.robots == {robot: len(walk) for robot, walk in walks.items()}
    for name in ("states", "actions", "prev", "next", "serial"):
        assert np.array_equal(rebuilt[name], expected[name]), name
    assert rebuilt["chain_ends"].keys() == {"robot0", "robot1"}
    for robot, (serial, next_state) in expected["chain_ends"].items():
        assert rebuilt["chain_ends"][robot][0] == serial
        assert np.array_equal(rebuilt["chain_ends"][robot][1], next_state)
    # each robot's first step of its second bag continues its first bag's last step
    linked = int(np.sum(expected["prev"] >= 0))
    assert linked == sum(len(walk) - 1 for walk in walks.values())
    assert result.census == online.graph.census()
