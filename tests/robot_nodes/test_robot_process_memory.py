"""The robot process's memory stays flat episode after episode.

The soak (``benchmarks/soak_bench.py``) found the robot process growing 0.45 MiB an episode,
linearly (164 -> 295 MiB over 300 training episodes). The cause was the EEF pose's quaternion,
made once a tick for the bag and once for the live ``/ee_pose``: ``pin.Quaternion`` of a
C-ordered NumPy matrix, which eigenpy 3.13 leaks 80 bytes a call for (tracemalloc saw nothing
grow; the process's RSS did). Here the robot process's work on the loop's ticks, without ROS:
the ticks of a few hundred episodes as the sample ring hands them over, each episode recorded
into its own bag (``record_ticks``) and serialized for publishing (``serialized_ticks``).
"""
from __future__ import annotations

import gc
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from qg_recording.episode_recorder import EpisodeRecorder
from robot_bridge_node.core.sample_ring import HAS_TOOL, HAS_TRUTH, HAS_WRENCH, record_dtype
from robot_bridge_node.core.tick_messages import TickNames, record_ticks, serialized_ticks

EPISODES = 200
TICKS = 1000           # a 1 s episode of the 1 kHz loop
BLOCK = 50             # records the link's reader takes from the ring at once
NAMES = TickNames(tuple(f"panda_joint{i}" for i in range(1, 8)), "panda_link0")


def rss_kib() -> int:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))


def ticks(t0_ns: int, rng: np.random.Generator) -> np.ndarray:
    """A block of records as the loop writes them: a tool pose (a rotation near the tool
    pointing down), a wrench estimate, the ground truth every 10th tick."""
    records = np.zeros(BLOCK, dtype=record_dtype(len(NAMES.joint_names)))
    records["t_ns"] = t0_ns + np.arange(BLOCK) * 1_000_000
    records["flags"] = HAS_TOOL | HAS_WRENCH | np.where(np.arange(BLOCK) % 10 == 0, HAS_TRUTH, 0)
    angle = np.pi - rng.uniform(0.0, 0.1, BLOCK)
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.zeros((BLOCK, 3, 3))
    rotation[:, 0, 0] = 1.0
    rotation[:, 1, 1], rotation[:, 1, 2], rotation[:, 2, 1], rotation[:, 2, 2] = c, -s, s, c
    records["tool_rotation"] = rotation
    records["q"] = rng.normal(size=records["q"].shape)
    return records


def run_episodes(recorder: EpisodeRecorder, first: int, count: int) -> int:
    """Record and serialize ``count`` episodes; the messages published."""
    rng = np.random.default_rng(first)
    published = 0
    for episode in range(first, first + count):
        recorder.start(f"episode_{episode:04d}")
        t_ns = (episode + 1) * 10**10
        for _ in range(TICKS // BLOCK):
            records = ticks(t_ns, rng)
            record_ticks(recorder, records, NAMES)
            published += sum(len(messages) for _, messages in serialized_ticks(records, NAMES))
            t_ns += BLOCK * 1_000_000
        recorder.stop()
    return published


def measure(folder: Path) -> tuple[int, int, int]:
    """In this process: the messages published, the bags written and the RSS grown [KiB] over
    ``EPISODES`` episodes after a warm-up."""
    recorder = EpisodeRecorder(folder)
    run_episodes(recorder, 0, 20)                  # warm-up: caches, numpy's and zstd's buffers
    gc.collect()
    before = rss_kib()
    published = run_episodes(recorder, 20, EPISODES)
    gc.collect()
    return published, len(list(folder.glob("*/metadata.yaml"))), rss_kib() - before


@pytest.mark.slow
def test_recording_and_publishing_ticks_do_not_grow_the_process(tmp_path: Path) -> None:
    # A fresh interpreter: the test worker's RSS also moves with what its earlier tests left.
    out = subprocess.run([sys.executable, __file__, str(tmp_path)], capture_output=True,
                         text=True, timeout=600, check=True).stdout
    published, bags, grown = json.loads(out.splitlines()[-1])
    # 5 messages a tick (joint states and commands, wrench, pose, twist) + the truth's 2 every 10th
    assert published == EPISODES * TICKS * 5 + EPISODES * TICKS // 10 * 2
    assert bags == EPISODES + 20
    # The old quaternions: 2 x 80 bytes a tick, 31 MiB over these 200,000 ticks.
    assert grown < 4 * 1024, f"the process grew {grown / 1024:.1f} MiB over {EPISODES} episodes"


if __name__ == "__main__":
    print(json.dumps(measure(Path(sys.argv[1]))))
