"""Microseconds per 1 kHz tick of the in-process torque loop, split by what the tick composes.

The loop is built as the in-process runner builds it (``PandaTask``: the Panda plugin, the
bridge's and the EKF's config files) and runs uniform random-residual RL steps from the 8 start
poses, the learner's workload without the learner. Each part the tick calls is timed by a
wrapper around it (hardware read, wrench EKF, controller, safety filter, rest detector, and the
hardware write, which applies the torques and steps pybullet); "loop" is the rest of ``tick``.
The wrappers cost ~0.2 us each; the total is also timed without them, in a second pass of the
same steps. Only public APIs are used, so the same script measures an older checkout.
The last line is one JSON object.

Usage: python benchmarks/tick_bench.py [--steps 40] [--seed 0]
"""
from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from qg_common.types import N_START_POSES, WrenchSetpoint
from qg_experiments.runner import PandaTask, StackSettings

#: What the tick calls, by the attribute path from the loop.
PARTS = {"read": ("hardware", "read"), "ekf": ("estimator", "update"),
         "controller": ("controller", "step"), "safety_tilt": ("safety", "limit_tilt"),
         "safety_torques": ("safety", "limit_torques"), "rest": ("rest", "update"),
         "write_and_physics": ("hardware", "write")}


def timed(function: Callable[..., Any], totals: dict[str, float], name: str
          ) -> Callable[..., Any]:
    """``function``, adding its wall time to ``totals[name]``."""
    clock = time.perf_counter

    def wrapper(*args: Any) -> Any:
        start = clock()
        result = function(*args)
        totals[name] += clock() - start
        return result
    return wrapper


def run_steps(task: PandaTask, steps: int, seed: int) -> tuple[int, float]:
    """Random-residual steps from rotating start poses; (ticks, wall seconds inside ``tick``)."""
    loop, rng = task.loop, np.random.default_rng(seed)
    ticks, busy = 0, 0.0
    for step in range(steps):
        if step % 5 == 0:
            loop.reset((step // 5) % N_START_POSES)
        loop.command(WrenchSetpoint(task.residual.wrench(rng.uniform(-1.0, 1.0, 2))))
        start = time.perf_counter()
        while True:
            ticks += 1
            if loop.tick():
                break
        busy += time.perf_counter() - start
    return ticks, busy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40, help="RL steps per pass")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    task = PandaTask(StackSettings.load())
    run_steps(task, 5, args.seed + 1)                       # warm-up (imports, caches)
    ticks, busy = run_steps(task, args.steps, args.seed)    # plain: the total
    totals = dict.fromkeys(PARTS, 0.0)
    loop = task.loop
    for name, (owner, method) in PARTS.items():
        target = getattr(loop, owner)
        setattr(target, method, timed(getattr(target, method), totals, name))
    split_ticks, split_busy = run_steps(task, args.steps, args.seed)
    us = {name: 1e6 * seconds / split_ticks for name, seconds in totals.items()}
    us["loop"] = 1e6 * split_busy / split_ticks - sum(us.values())
    total = 1e6 * busy / ticks
    for name, value in us.items():
        print(f"{name:18s} {value:6.1f} us")
    print(f"{'tick (unwrapped)':18s} {total:6.1f} us over {ticks} ticks; outside pybullet's "
          f"write: ~{total - us['write_and_physics']:.0f} us")
    print(json.dumps({"us_per_tick": round(total, 1),
                      "us_per_part": {k: round(v, 1) for k, v in us.items()},
                      "ticks": ticks, "steps": args.steps}))


if __name__ == "__main__":
    main()
