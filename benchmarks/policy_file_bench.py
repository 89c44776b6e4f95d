"""What running a policy file costs a robot's computer: numpy only, load time, time per action.

Loads a policy file (default: the MuJoCo-trained actor of docs/deployment.md) in a fresh
interpreter, checks that neither torch nor rclpy was imported, and times the load and one
action per state over many states. Prints the figures; the last line is JSON.

Usage: python benchmarks/policy_file_bench.py [FILE] [--states N]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

DEFAULT = Path(__file__).resolve().parents[1] / "docs" / "data" / "policies" / \
    "mujoco_qgddpg_seed0.npz"

_CHILD = r"""
import json, sys, time
start = time.perf_counter()
import numpy as np
from qg_learning_node.policy_file import load_policy
imported = time.perf_counter()
policy = load_policy(sys.argv[1])
loaded = time.perf_counter()
states = np.random.default_rng(0).uniform(-1, 1, (int(sys.argv[2]), policy.spec.state_dim))
t0 = time.perf_counter()
for s in states:
    policy(s)
t1 = time.perf_counter()
print(json.dumps({"import_s": imported - start, "load_s": loaded - imported,
                  "action_us": (t1 - t0) / len(states) * 1e6,
                  "torch_imported": "torch" in sys.modules,
                  "rclpy_imported": "rclpy" in sys.modules,
                  "layers": [list(w.shape) for w, _ in policy.layers]}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", nargs="?", default=str(DEFAULT))
    parser.add_argument("--states", type=int, default=20_000)
    args = parser.parse_args()
    out = subprocess.run([sys.executable, "-c", _CHILD, args.file, str(args.states)],
                         capture_output=True, text=True, check=True)
    row = json.loads(out.stdout.strip().splitlines()[-1])
    row.update(file=args.file, bytes=Path(args.file).stat().st_size, states=args.states)
    print(f"file {row['file']}: {row['bytes']} bytes, layers {row['layers']}")
    print(f"import {row['import_s'] * 1e3:.0f} ms, load {row['load_s'] * 1e3:.1f} ms, "
          f"{row['action_us']:.1f} us per action over {args.states} states; torch imported: "
          f"{row['torch_imported']}, rclpy imported: {row['rclpy_imported']}")
    print(json.dumps(row))


if __name__ == "__main__":
    main()
