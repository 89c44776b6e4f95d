"""The recording policy: RL-rate bags, every k-th episode's 1 kHz data, a disk budget the bag
folder never exceeds, and an episode refused before anything is written."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pytest
from qg_recording.bag_reader import bag_info, read_raw
from qg_recording.disk_keeper import (
    MB,
    RL_RATE_TOPICS,
    RecordingPolicy,
    RecordingRefused,
    disk_bytes,
    free_bytes,
    holds_high_rate,
)
from qg_recording.episode_recorder import EpisodeRecorder

NAMES = tuple(f"panda_joint{i}" for i in range(1, 8))
BLOCK = 200          # ticks the robot process hands over at once
STEPS = 10           # transitions per episode


class Episodes:
    """Episodes shaped like the robot's: the 1 kHz topics in blocks of ticks (random numbers,
    which compress as little as the real ones), a transition every few blocks; after every
    block ``check`` is called (the budget test measures the folder there)."""

    def __init__(self, recorder: EpisodeRecorder, check=lambda: None) -> None:
        self.recorder, self.check = recorder, check
        self.rng = np.random.default_rng(0)
        self.t_ns = 1_000_000_000
        self.transitions: dict[str, int] = {}

    def keep_pace(self) -> None:
        """Wait until the writer thread has the file up to date but for its open chunk, as it
        has at the robot's 1 kHz (a block every 0.2 s); without, these blocks come faster
        than zstd compresses them and the queued bytes end episodes early."""
        deadline = time.monotonic() + 10.0
        while self.recorder.unwritten_bytes > 512 * 1024 and time.monotonic() < deadline:
            time.sleep(0.002)

    def record(self, episode_id: str, ticks: int = 3000) -> Path:
        rec, rng = self.recorder, self.rng
        rec.start(episode_id, {"mode": "train"})
        blocks = ticks // BLOCK
        sent = 0
        for block in range(blocks):
            t = self.t_ns + np.arange(BLOCK, dtype=np.int64) * 1_000_000
            rec.record_rows("/joint_states", t, rng.standard_normal((BLOCK, 21)), names=NAMES)
            rec.record_rows("/wrench_estimate", t, rng.standard_normal((BLOCK, 6)), frame_id="tool")
            rec.record_rows("/ee_pose", t, rng.standard_normal((BLOCK, 7)), frame_id="base")
            self.t_ns = int(t[-1]) + 1_000_000
            self.keep_pace()
            while sent < (block + 1) * STEPS // blocks:
                rec.record_transition(self.t_ns + sent, sent, rng.standard_normal(6),
                                      rng.standard_normal(6), -1.0, rng.standard_normal(6), False)
                sent += 1
            self.check()
        self.transitions[episode_id] = sent
        path = rec.stop()
        self.check()
        return path


def topics_of(bag: Path) -> dict[str, int]:
    return {t.name: t.message_count for t in bag_info(bag).topics if t.message_count}


def test_rl_rate_bags_hold_no_1khz_topic_and_a_few_percent_of_the_bytes(tmp_path: Path) -> None:
    full = Episodes(EpisodeRecorder(tmp_path / "all"))
    full.record("ep0", ticks=6000)
    rl = Episodes(EpisodeRecorder(tmp_path / "rl", policy=RecordingPolicy(mode="rl_rate")))
    rl.record("ep0", ticks=6000)
    full_bytes, rl_bytes = full.recorder.last_bytes, rl.recorder.last_bytes
    assert topics_of(tmp_path / "all" / "ep0") == {
        "/joint_states": 6000, "/wrench_estimate": 6000, "/ee_pose": 6000, "/transitions": STEPS}
    assert topics_of(tmp_path / "rl" / "ep0") == {"/transitions": STEPS}
    assert {t.name for t in bag_info(tmp_path / "rl" / "ep0").topics} <= RL_RATE_TOPICS
    assert full_bytes == disk_bytes(tmp_path / "all" / "ep0")
    assert not rl.recorder.last_high_rate and full.recorder.last_high_rate
    # 6 s of three topics here; a training episode's real share is in recording_bench.py
    assert rl_bytes < 0.05 * full_bytes, (rl_bytes, full_bytes)


def test_every_k_keeps_1khz_in_every_kth_and_the_last_episodes(tmp_path: Path) -> None:
    policy = RecordingPolicy(mode="every_k", every_k=3, keep_last=2)
    episodes = Episodes(EpisodeRecorder(tmp_path, policy=policy))
    for n in range(8):
        episodes.record(f"ep{n}", ticks=1000)
        with_1khz = {n for n in range(n + 1) if "/joint_states" in topics_of(tmp_path / f"ep{n}")}
        assert with_1khz == {m for m in range(n + 1) if m % 3 == 0 or m > n - 2}, n
    # ep0, ep3, ep6 (every 3rd) and ep6, ep7 (the last 2); all transitions kept
    assert {n for n in range(8) if "/joint_states" in topics_of(tmp_path / f"ep{n}")} == {0, 3, 6, 7}
    for n in range(8):
        assert topics_of(tmp_path / f"ep{n}")["/transitions"] == STEPS
    meta = (tmp_path / "ep1" / "metadata.yaml").read_text()
    assert "high_rate_dropped" in meta and "every_k = 3" in meta and "mode: train" in meta.replace('"', "")
    assert not (tmp_path / ".compacting").exists()


@pytest.mark.parametrize("budget_mb", [4.0, 9.0])
@pytest.mark.slow
def test_the_folder_never_exceeds_its_budget_and_keeps_every_transition(
        tmp_path: Path, budget_mb: float) -> None:
    folder = tmp_path / "episodes"
    seen: list[int] = []
    recorder = EpisodeRecorder(folder, policy=RecordingPolicy(mode="all", budget_mb=budget_mb))
    episodes = Episodes(recorder, check=lambda: seen.append(disk_bytes(folder)))
    for n in range(12):
        episodes.record(f"ep{n:02d}")
    budget = budget_mb * MB
    assert max(seen) <= budget, (max(seen), budget)
    assert max(seen) > 0.6 * budget            # the budget is used, not avoided
    assert len(seen) > 12 * 15
    bags = sorted(folder.iterdir())
    assert [b.name for b in bags] == [f"ep{n:02d}" for n in range(12)]
    for bag in bags:     # every transition of every episode, in order
        steps = [m.data for m in read_raw(bag, ["/transitions"])]
        assert len(steps) == episodes.transitions[bag.name] == STEPS
    # the oldest 1 kHz data went first: the bags still holding it are the most recent ones
    kept = [n for n in range(12) if "/joint_states" in topics_of(folder / f"ep{n:02d}")]
    assert kept and kept == list(range(12 - len(kept), 12)), kept
    assert 12 - len(kept) >= 4


def test_an_episode_larger_than_the_budget_loses_its_1khz_topics_not_its_transitions(
        tmp_path: Path) -> None:
    folder = tmp_path / "episodes"
    seen: list[int] = []
    recorder = EpisodeRecorder(folder, policy=RecordingPolicy(budget_mb=3.0))
    episodes = Episodes(recorder, check=lambda: seen.append(disk_bytes(folder)))
    episodes.record("long", ticks=30000)          # about 11 MB with all its ticks
    assert max(seen) <= 3.0 * MB
    # written with its ticks until the cut (the whole episode is about 11 MB) ...
    assert 1.5 * MB < recorder.last_bytes <= 3.0 * MB, recorder.last_bytes
    # ... whose 1 kHz data, the only there is, then made room for the next episode
    assert topics_of(folder / "long") == {"/transitions": STEPS}
    meta = (folder / "long" / "metadata.yaml").read_text()
    assert "high_rate_cut" in meta and "high_rate_dropped" in meta


def test_a_full_budget_of_rl_rate_data_refuses_the_next_episode(tmp_path: Path) -> None:
    recorder = EpisodeRecorder(tmp_path, policy=RecordingPolicy(mode="rl_rate", budget_mb=0.5))
    episodes = Episodes(recorder)
    recorded = 0
    with pytest.raises(RecordingRefused, match="recording.budget_mb = 0.5"):
        for n in range(100):
            episodes.record(f"ep{n:02d}", ticks=1000)
            recorded += 1
    assert 2 <= recorded < 100
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"ep{n:02d}" for n in range(recorded)]
    assert disk_bytes(tmp_path) <= 0.5 * MB


def test_a_nearly_full_disk_refuses_the_episode_before_anything_is_written(tmp_path: Path) -> None:
    free = {"bytes": 5000 * MB}
    recorder = EpisodeRecorder(tmp_path, policy=RecordingPolicy(min_free_mb=1000.0),
                               free_space=lambda _: free["bytes"])
    episodes = Episodes(recorder)
    episodes.record("ep0", ticks=1000)
    free["bytes"] = 1000 * MB + 100 * 1024        # 100 KiB above the floor: an episode won't fit
    with pytest.raises(RecordingRefused, match=r"1000.1 MiB free.*min_free_mb = 1000") as refused:
        recorder.start("ep1")
    assert "ep1" in str(refused.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ep0"]   # no ep1, not even a folder
    assert not recorder.active
    recorder.record_rows("/joint_states", np.array([1], dtype=np.int64), np.zeros((1, 21)),
                         names=NAMES)      # an idle recorder: the loop's calls do nothing
    free["bytes"] = 5000 * MB
    episodes.record("ep1", ticks=1000)
    assert topics_of(tmp_path / "ep1")["/transitions"] == STEPS


def test_the_real_free_space_is_the_filesystems(tmp_path: Path) -> None:
    import shutil
    usage = shutil.disk_usage(tmp_path)
    assert 0 < free_bytes(tmp_path / "not" / "yet") <= usage.total
    assert abs(free_bytes(tmp_path) - usage.free) < 0.05 * usage.total


@pytest.mark.parametrize("bad, message", [
    ({"mode": "some"}, "recording.mode must be one of"),
    ({"every_k": 0}, "recording.every_k must be >= 1"),
    ({"keep_last": -1}, "recording.keep_last"),
    ({"budget_mb": -1.0}, "recording.budget_mb"),
    ({"min_free_mb": float("nan")}, "recording.min_free_mb"),
])
def test_a_bad_setting_is_a_clear_error(bad: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        RecordingPolicy(**bad)


def test_a_resumed_run_goes_on_with_the_bags_already_there(tmp_path: Path) -> None:
    policy = RecordingPolicy(mode="every_k", every_k=2, keep_last=1)
    Episodes(EpisodeRecorder(tmp_path, policy=policy)).record("a0", ticks=1000)
    Episodes(EpisodeRecorder(tmp_path, policy=policy)).record("a1", ticks=1000)
    again = Episodes(EpisodeRecorder(tmp_path, policy=policy))
    assert again.recorder.keeper.next_ordinal == 2
    again.record("a2", ticks=1000)
    assert ["/joint_states" in topics_of(tmp_path / b) for b in ("a0", "a1", "a2")] == \
        [True, False, True]
    # the same from metadata.yaml alone
    assert [holds_high_rate(tmp_path / b) for b in ("a0", "a1", "a2")] == [True, False, True]
    assert [b.high_rate for b in EpisodeRecorder(tmp_path, policy=policy).keeper.bags] == \
        [True, False, True]


def test_qgl_replay_rebuilds_the_replay_from_rl_rate_and_compacted_bags(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    pytest.importorskip("torch")
    from qg_bringup.bag_commands import add_parsers

    runs = tmp_path / "episodes"
    policy = RecordingPolicy(mode="every_k", every_k=4, keep_last=1)
    episodes = Episodes(EpisodeRecorder(runs, policy=policy))
    for n in range(3):
        episodes.record(f"ep{n}", ticks=1000)
    rl = Episodes(EpisodeRecorder(runs, policy=RecordingPolicy(mode="rl_rate")))
    rl.rng, rl.t_ns = episodes.rng, episodes.t_ns
    rl.record("ep3", ticks=1000)
    assert "high_rate_dropped" in (runs / "ep1" / "metadata.yaml").read_text()
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="command"))
    (tmp_path / "learner.yaml").write_text(
        "/**:\n  ros__parameters:\n    zero_action: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n")
    args = parser.parse_args(["replay", str(runs), "--into-learner", "--learner-config",
                              str(tmp_path / "learner.yaml")])
    assert args.func(args) == 0
    assert f"transitions: {4 * STEPS} from 4 episode(s)" in capsys.readouterr().out


def test_a_compacted_bag_keeps_its_rl_rate_messages_byte_for_byte(tmp_path: Path) -> None:
    from qg_recording.disk_keeper import compact_bag
    from rosbags.highlevel import AnyReader

    episodes = Episodes(EpisodeRecorder(tmp_path))
    bag = episodes.record("ep0", ticks=2000)
    before = list(read_raw(bag, RL_RATE_TOPICS))
    full = disk_bytes(bag)
    after_bytes = compact_bag(bag, "test")
    assert after_bytes == disk_bytes(bag) < 0.1 * full
    assert list(read_raw(bag)) == before and len(before) == STEPS
    assert bag_info(bag).complete
    with AnyReader([bag]) as reader:      # a reader we did not write
        counts = {c.topic: c.msgcount for c in reader.connections if c.msgcount}
        assert {c.topic for c in reader.connections} <= RL_RATE_TOPICS
        decoded = [reader.deserialize(data, c.msgtype) for c, _, data in reader.messages()]
    assert counts == {"/transitions": STEPS}
    assert [m.step for m in decoded] == list(range(STEPS))
