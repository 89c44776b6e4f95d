"""A maintained agent on the thesis's free peg: Stable-Baselines3's TD3 on ``QGPeg-v0``.

Why: the peg's thesis-budget runs (results.md section 5) test whether the Q-Graph bound helps
DDPG without target networks (thesis ch. 8.3.2). Whether the environment can be learned at all
is a separate question; TD3 with SB3's defaults (two 400-300 critics with target networks, a
delayed actor, one update per step) answers it on exactly the same environment, rewards and
starts. Exploration: ``executor.yaml``'s Gaussian sigma on every step (the peg runs' own, via
``peg_noise_config``); discount: the peg budget's.

Per seed: ``--steps`` training steps (episodes of at most 200 steps, starts drawn by the
environment), then the deterministic actor from ``--tests`` fixed starts (start indices
1,000,000 + k, which no training episode of the experiment uses). The last line is one JSON
object; ``--out FILE`` also writes it there (``docs/data/peg_td3_reference.json`` is read by
results.md's peg section).

Usage: python benchmarks/peg_td3_reference.py [--steps 20000] [--seeds 0 1] [--tests 20]
       [--out docs/data/peg_td3_reference.json]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from qg_experiments.gym_envs.peg import FreePegEnv
from qg_experiments.peg import peg_noise_config
from qg_experiments.profile import PegBudget
from qg_experiments.sb3_models import sb3_model

#: Test start indices: far from those of training (episode seeds of the runs are small ints).
TEST_START = 1_000_000


def run(seed: int, steps: int, tests: int) -> dict:
    """Train one TD3 and test its deterministic actor; its numbers."""
    torch.set_num_threads(1)
    noise = peg_noise_config()
    env = FreePegEnv()
    model = sb3_model("sb3_td3", env, seed, noise=(noise.kind, noise.sigma, noise.theta),
                      gamma=PegBudget.gamma)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    train_seconds = time.perf_counter() - start
    inserted, returns, lengths = 0, [], []
    for k in range(tests):
        obs, _ = env.reset(options={"start": TEST_START + k})
        total, done, n = 0.0, False, 0
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total, n, done = total + reward, n + 1, terminated or truncated
        inserted += int(terminated)
        returns.append(total)
        lengths.append(n)
    env.close()
    return {"seed": seed, "steps": steps, "train_seconds": round(train_seconds, 1),
            "tests": tests, "inserted": inserted, "mean_return": float(np.mean(returns)),
            "mean_steps": float(np.mean(lengths))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--tests", type=int, default=20)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    runs = []
    for seed in args.seeds:
        runs.append(run(seed, args.steps, args.tests))
        r = runs[-1]
        print(f"seed {seed}: {r['inserted']} of {r['tests']} test starts inserted "
              f"(mean return {r['mean_return']:.1f}, {r['mean_steps']:.1f} steps) after "
              f"{r['steps']} training steps ({r['train_seconds']:.0f} s)", flush=True)
    result = {"agent": "sb3_td3", "environment": "QGPeg-v0", "runs": runs}
    if args.out is not None:
        args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
