"""`qgl info`: counts and duration of a bag, one clear line and exit code 2 otherwise."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from qg_recording.episode_recorder import EpisodeRecorder


def qgl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "qg_bringup.main", *args],
                          capture_output=True, text=True, timeout=60)


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    recorder = EpisodeRecorder(tmp_path_factory.mktemp("runs"))
    bag = recorder.start("ep_7")
    for i in range(250):
        recorder.record_wrench(2_000_000_000 + i * 2_000_000, [1.0, 0, 0], [0, 0, 0])
    recorder.record_twist(2_000_000_000, [0, 0, 0], [0, 0, 0])
    recorder.stop()
    return bag


def test_info_prints_topics_counts_and_duration(bag: Path) -> None:
    result = qgl("info", str(bag))
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "Duration:          0.498s" in out
    assert "Messages:          251" in out
    assert "Topic: /wrench_estimate | Type: geometry_msgs/msg/WrenchStamped | Count: 250" in out
    assert "Topic: /ee_twist | Type: geometry_msgs/msg/TwistStamped | Count: 1" in out
    assert "Closed cleanly:    yes" in out


@pytest.mark.parametrize("kind", ["missing", "directory", "file"])
def test_info_on_a_non_bag_fails_with_one_line(tmp_path: Path, kind: str) -> None:
    path = tmp_path / "nothing"
    if kind == "directory":
        path.mkdir()
    elif kind == "file":
        path = tmp_path / "fake.mcap"
        path.write_bytes(b"not an mcap file")
    result = qgl("info", str(path))
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("qgl info: ") and str(path) in lines[0]


def test_replay_on_a_missing_path_fails_with_one_line(tmp_path: Path) -> None:
    result = qgl("replay", str(tmp_path / "gone"), "--into-learner")
    assert result.returncode == 2
    assert result.stderr.strip() == f"qgl replay: no such bag: {tmp_path / 'gone'}"
