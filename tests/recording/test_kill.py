"""A recorder process killed mid-episode leaves a readable bag (process level)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

from qg_recording.bag_reader import bag_info, read_bag
from qg_recording.episode_recorder import ROWS, EpisodeRecorder

CHILD = Path(__file__).with_name("record_child.py")
CHUNK = 8 * 1024  # about 80 WrenchStamped messages per chunk
PER_CHUNK = CHUNK // 100 + 1  # a message record is more than 100 bytes


def run_child_until(runs: Path, produced: int) -> tuple[subprocess.Popen, int]:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    child = subprocess.Popen([sys.executable, str(CHILD), str(runs), str(CHUNK)], stdout=subprocess.PIPE,
                             text=True, env=env)
    last, deadline = 0, time.monotonic() + 60.0
    while last < produced and time.monotonic() < deadline:
        line = child.stdout.readline()
        if not line:
            break
        last = int(line.split()[1])
    assert last >= produced, "the child did not record"
    return child, last


def indices(bag: Path) -> list[int]:
    return [int(m.wrench.force.x) for _, _, _, m in read_bag(bag)]


def test_sigkill_loses_at_most_the_last_chunk(tmp_path: Path) -> None:
    child, produced = run_child_until(tmp_path, 1500)
    child.send_signal(signal.SIGKILL)
    child.wait(10)
    bag = tmp_path / "killed"
    got = indices(bag)
    assert got == list(range(len(got)))  # a gap-free prefix: nothing dropped before the cut
    # Lost: the rows not yet handed to the writer, the chunk being filled, what the writer had not
    # yet taken (a 20 ms poll).
    assert produced - ROWS - 2 * PER_CHUNK - 60 <= len(got) <= produced + 60
    info = bag_info(bag)
    assert not info.complete and info.count("/wrench_estimate") == len(got)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert len(got) - PER_CHUNK <= meta["message_count"] <= len(got)  # rewritten after every chunk


def test_sigint_closes_the_bag_cleanly(tmp_path: Path) -> None:
    child, _ = run_child_until(tmp_path, 300)
    child.send_signal(signal.SIGINT)
    out, _ = child.communicate(timeout=20)
    produced = int(out.strip().splitlines()[-1].split()[1])  # "interrupted N"
    bag = tmp_path / "killed"
    info = bag_info(bag)
    assert info.complete  # MCAP summary written at exit
    assert indices(bag) == list(range(produced))
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == produced


def test_a_file_cut_anywhere_reads_up_to_its_last_complete_chunk(tmp_path: Path) -> None:
    recorder = EpisodeRecorder(tmp_path / "runs", chunk_size=CHUNK)
    recorder.start("full")
    for i in range(1000):
        recorder.record_wrench(1_000_000_000 + i, [float(i), 0.0, 0.0], [0.0, 0.0, 0.0])
    full = recorder.stop() / "full_0.mcap"
    data = full.read_bytes()
    previous = -1
    for cut in range(200, len(data), len(data) // 37):
        cut_dir = tmp_path / f"cut{cut}"
        cut_dir.mkdir()
        (cut_dir / "cut_0.mcap").write_bytes(data[:cut])
        got = indices(cut_dir)
        assert got == list(range(len(got)))
        assert len(got) >= previous  # a longer prefix of the file never reads less
        previous = len(got)
        assert not bag_info(cut_dir).complete
    assert 1000 - 2 * PER_CHUNK <= previous <= 1000
