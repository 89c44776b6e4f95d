"""The deterministic test actor against the same actor with stall recovery (docs/learning.md
section 15).

The stall probe's learning in process on each seed (``stall_probe.trained``: QG-DDPG, critic lr
1e-2, 50 iterations a cycle unless ``--lr``/``--iterations`` say otherwise, 40 training episodes
capped at 50 steps), then every test pose on a
fresh robot of the same seed (cap ``--cap``, the report's 200 by default): once with the deterministic actor, once with
``executor.yaml``'s stall recovery switched on (perturbation seeds ``runner.recovery_seed``).
One JSON line a pose; the last line: per seed and in all, the poses inserted deterministically,
with recovery, and the recoveries.

``--fixture PATH`` saves, for the first seed, the actor's tensors and every deterministic test
episode's states and actions (a small .npz: the stall detector's test data).

Usage: python benchmarks/stall_recovery_probe.py [SEED ...] [--cap 200] [--fixture PATH]
           [--lr 1e-2] [--iterations 50]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch
from qg_common.types import N_START_POSES
from qg_experiments.runner import InsertionRobot, recovery_seed, run_episode, stall_recovery_config
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.residual_task import ACTION_DIM
from qg_learning_node.executor.stall_recovery import StallRecovery, first_stall

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stall_probe import trained  # noqa: E402  (the same learning as the stall probe)


def probe_seed(seed: int, cap: int, fixture: Path | None, critic_lr: float = 1e-2,
               iterations: int = 50) -> dict[str, Any]:
    """Train on ``seed``, then each test pose deterministic and with recovery on a fresh robot."""
    env, learner, policy, settings = trained(seed, critic_lr, iterations)
    settings = dataclasses.replace(settings, task=dataclasses.replace(settings.task,
                                                                      test_max_steps=cap))
    test_env = InsertionRobot(settings)
    config = stall_recovery_config()
    progress = test_env.residual.progress_dims
    rows, saved = [], {}
    for pose in range(N_START_POSES):
        records: list = []
        plain = run_episode(test_env, Episode(f"test{pose}", "test", pose, "dense",
                                              test_env.residual), policy, records.append)
        states = np.array([r.state for r in records])
        actions = np.array([r.action for r in records])
        saved[f"states_{pose}"], saved[f"actions_{pose}"] = states, actions
        watch = StallRecovery(config, ACTION_DIM, recovery_seed(seed, pose), settings.noise,
                              progress)
        recovered = run_episode(test_env, Episode(f"recovery{pose}", "test", pose, "dense",
                                                  test_env.residual), policy, recovery=watch)
        rows.append({"seed": seed, "pose": pose, "steps": plain["steps"],
                     "inserted": bool(plain["success"]),
                     "detected_at": first_stall(states, actions, config, progress),
                     "recovery_steps": recovered["steps"],
                     "recovery_inserted": bool(recovered["success"]),
                     "recoveries": recovered["recoveries"],
                     "recovered_at": recovered["recovered_at"]})
        print(json.dumps(rows[-1]), flush=True)
    if fixture is not None:
        tensors = learner.agent.actor_tensors()
        np.savez_compressed(
            fixture, seed=seed, test_max_steps=settings.task.test_max_steps,
            critic_lr=critic_lr, iterations=iterations,
            observation=settings.task.observation, progress_dims=np.array(progress, int),
            actor_names=np.array([name for name, _ in tensors]),
            **{f"actor_{i}": np.asarray(t, np.float32) for i, (_, t) in enumerate(tensors)},
            **{k: v.astype(np.float32) for k, v in saved.items()})
    return {"seed": seed, "poses": len(rows), "inserted": sum(r["inserted"] for r in rows),
            "inserted_with_recovery": sum(r["recovery_inserted"] for r in rows),
            "recoveries": sum(r["recoveries"] for r in rows),
            "stalls_detected": sum(r["detected_at"] is not None for r in rows),
            "false_detections": sum(r["detected_at"] is not None and r["inserted"]
                                    for r in rows),
            "rows": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", type=int, nargs="*", default=[0])
    parser.add_argument("--cap", type=int, default=200, help="test episodes' step cap")
    parser.add_argument("--fixture", type=Path, default=None)
    parser.add_argument("--lr", type=float, default=1e-2, help="critic learning rate")
    parser.add_argument("--iterations", type=int, default=50, help="train steps a cycle")
    args = parser.parse_args()
    torch.set_num_threads(1)
    results = [probe_seed(seed, args.cap, args.fixture if i == 0 else None, args.lr,
                          args.iterations)
               for i, seed in enumerate(args.seeds)]
    total = {k: sum(r[k] for r in results) for k in ("poses", "inserted",
                                                     "inserted_with_recovery", "recoveries",
                                                     "stalls_detected", "false_detections")}
    print(json.dumps({"config": dataclasses.asdict(stall_recovery_config()),
                      "seeds": [{k: v for k, v in r.items() if k != "rows"} for r in results],
                      "total": total}))


if __name__ == "__main__":
    main()
