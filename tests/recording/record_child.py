"""Child process for the kill tests: records /wrench_estimate at 1 kHz (wall clock) until killed.

Prints `produced N` (flushed) every 50 messages so the parent knows a lower bound of what was
produced before it sent the signal. The payload's force.x is the message index. With `truth`,
every tenth tick also records /sim/ground_truth (100 Hz, insertion_depth = the tick index), the
rate at which a row buffer takes 2 s to fill.
Usage: python record_child.py RUNS_DIR CHUNK_SIZE [FLUSH_INTERVAL_S [truth]]
"""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

from qg_recording.episode_recorder import EpisodeRecorder

ZERO = [0.0, 0.0, 0.0]


def main() -> None:
    # Ctrl-C semantics even when the test runs as a background job, which inherits SIGINT ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    flush_interval_s = float(sys.argv[3]) if len(sys.argv) > 3 else 10.0
    truth = sys.argv[4:5] == ["truth"]
    recorder = EpisodeRecorder(Path(sys.argv[1]), chunk_size=int(sys.argv[2]), flush_interval_s=flush_interval_s)
    recorder.start("killed")
    start, i = time.monotonic(), 0
    try:
        while i < 60_000:
            t_ns = 1_000_000_000 + i * 1_000_000
            recorder.record_wrench(t_ns, [float(i), 0.0, 0.0], ZERO)
            if truth and i % 10 == 0:
                recorder.record_ground_truth(t_ns, ZERO + ZERO, float(i), 0.0, False, 0.0, [0.0, 0.0], 0.0, 0.0)
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
