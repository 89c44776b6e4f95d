"""How long an RL step takes to come to rest at the stack's gains, without a short time limit.

Runs uniform-random residual episodes (8 start poses, at most 60 steps each) through the
in-process Panda task (sim + bridge loop + EKF, ``config/``) with ``rest.max_time`` raised to
``--max-time``, and prints the distribution of step durations, the share of steps that still
reached the limit and the RL steps per wall second. ``--set section.key=value`` overrides a
``bridge.yaml`` parameter (e.g. ``impedance.d_rot=[2.5,2.5,0.6]`` or
``rest.angular_threshold=0.1``). This is what docs/learning.md (section 3) measures to show
that at 4 Nm/rad and the Panda's inertia a free step needs about 1.5 s to settle.
The last line is one JSON object.

Usage: python benchmarks/time_to_rest.py [--max-time 3.0] [--seed 0] [--set rest.max_time=...]
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import time

import numpy as np
import yaml
from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_experiments.runner import PandaTask, StackSettings


def _override(params: dict, assignment: str) -> None:
    """Apply ``section.key=value`` (value parsed as YAML) to the bridge parameters."""
    path, _, value = assignment.partition("=")
    *sections, key = path.split(".")
    node = params
    for section in sections:
        node = node.setdefault(section, {})
    node[key] = yaml.safe_load(value)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-time", type=float, default=3.0, help="rest.max_time [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-steps", type=int, default=60, help="per episode")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = parser.parse_args()
    settings = StackSettings.load()
    bridge = copy.deepcopy(settings.bridge)
    bridge.setdefault("rest", {})["max_time"] = args.max_time
    for assignment in args.set:
        _override(bridge, assignment)
    env = PandaTask(dataclasses.replace(settings, bridge=bridge))
    rng = np.random.default_rng(args.seed)
    durations, timed_out, episode_steps, successes = [], [], [], 0
    start = time.perf_counter()
    for pose in range(8):
        obs = env.reset(pose)
        for step in range(1, args.max_steps + 1):
            obs = env.step(rng.uniform(-1.0, 1.0, ACTION_DIM))
            durations.append(env.loop.rest.elapsed)
            timed_out.append(env.loop.rest.timed_out)
            if obs.success or env.residual.left_bore(obs):
                break
        successes += int(obs.success)
        episode_steps.append(step)
    wall = time.perf_counter() - start
    d = np.array(durations)
    result = {"max_time": args.max_time, "overrides": args.set, "steps": len(d),
              "success": f"{successes}/8", "mean_episode_steps": float(np.mean(episode_steps)),
              "timeout_fraction": float(np.mean(timed_out)),
              "duration_p25": float(np.percentile(d, 25)),
              "duration_median": float(np.median(d)),
              "duration_p90": float(np.percentile(d, 90)),
              "rl_steps_per_second": len(d) / wall, "sim_seconds_per_wall_second": d.sum() / wall}
    print(f"{len(d)} uniform-random steps, max_time {args.max_time} s {args.set}: "
          f"{result['timeout_fraction']:.0%} at the limit; time to rest median "
          f"{result['duration_median']:.3f} s (p25 {result['duration_p25']:.3f}, p90 "
          f"{result['duration_p90']:.3f}); {result['rl_steps_per_second']:.1f} RL steps/s")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
