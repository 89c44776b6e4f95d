"""Child process for the kill tests: records /wrench_estimate at 1 kHz (wall clock) until killed.

Prints `produced N` (flushed) every 50 messages so the parent knows a lower bound of what was
produced before it sent the signal. The payload's force.x is the message index.
Usage: python record_child.py RUNS_DIR CHUNK_SIZE
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from qg_recording.episode_recorder import EpisodeRecorder


def main() -> None:
    recorder = EpisodeRecorder(Path(sys.argv[1]), chunk_size=int(sys.argv[2]), flush_interval_s=10.0)
    recorder.start("killed")
    start, i = time.monotonic(), 0
    try:
        while i < 60_000:
            recorder.record_wrench(1_000_000_000 + i * 1_000_000, [float(i), 0.0, 0.0], [0.0, 0.0, 0.0])
            i += 1
            if i % 50 == 0:
                print(f"produced {i}", flush=True)
            delay = start + i * 1e-3 - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    except KeyboardInterrupt:
        print(f"interrupted {i}", flush=True)
        raise


if __name__ == "__main__":
    main()
