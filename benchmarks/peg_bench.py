"""Clearance-fit peg environment speed: RL steps and physics steps per wall second, both drives.

The free peg (default, for the experiment-5 sweeps) and the Nextage arm behind the IK position
controller, each under uniform random actions from random free starts (seeded), plus the scripted
"rise, centre, descend" policy for the success rate and episode length. One core; pybullet DIRECT.
Last line: one JSON object.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
for package in ("sim_robot_node", "robot_bridge_node"):
    sys.path.insert(0, str(ROOT / package))

from qg_common.params import config_file, load_ros_params  # noqa: E402
from robot_bridge_node.core.position_control import (  # noqa: E402
    PositionControlConfig,
    TaskSpacePositionController,
)
from sim_robot_node.core.nextage_scene import nextage_urdf_path  # noqa: E402
from sim_robot_node.core.peg_env import PegEnv, PegEnvConfig, toward_goal  # noqa: E402


def measure(env: PegEnv, episodes: int, steps: int, policy: str) -> dict:
    """Run ``episodes`` episodes of at most ``steps`` steps; speeds exclude nothing (resets too)."""
    rng = np.random.default_rng(0)
    physics_before, rl_steps, successes, lengths = env.physics_steps, 0, 0, []
    start = time.perf_counter()
    for episode in range(episodes):
        env.reset(seed=episode)
        for n in range(steps):
            action = rng.uniform(-1, 1, 3) if policy == "random" else toward_goal(env)
            _, _, terminal = env.step(action)
            rl_steps += 1
            if terminal:
                successes += 1
                lengths.append(n + 1)
                break
    seconds = time.perf_counter() - start
    return {"episodes": episodes, "rl_steps": rl_steps, "seconds": round(seconds, 2),
            "rl_steps_per_second": round(rl_steps / seconds, 1),
            "physics_steps_per_second": round((env.physics_steps - physics_before) / seconds),
            "physics_steps_per_rl_step": round((env.physics_steps - physics_before) / rl_steps, 1),
            "success_rate": successes / episodes,
            "mean_steps_to_goal": round(float(np.mean(lengths)), 1) if lengths else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10, help="free-peg random episodes")
    parser.add_argument("--arm-steps", type=int, default=100, help="random steps with the arm")
    args = parser.parse_args()
    env_params = load_ros_params(config_file("peg_env.yaml"))
    nextage = load_ros_params(config_file("nextage.yaml"))
    results = {}

    free = PegEnv(PegEnvConfig.from_dict(env_params))
    results["free_random"] = measure(free, args.episodes, 200, "random")
    results["free_scripted"] = measure(free, args.episodes, 200, "scripted")
    free.close()

    controller = TaskSpacePositionController(
        nextage_urdf_path(), "RARM_TOOL",
        PositionControlConfig.from_dict(nextage["position_control"]))
    arm = PegEnv(PegEnvConfig.from_dict({**env_params, "use_arm": True, "arm": nextage["scene"]}),
                 controller)
    results["arm_random"] = measure(arm, 1, args.arm_steps, "random")
    results["arm_scripted"] = measure(arm, 3, 200, "scripted")
    arm.close()

    for name, figures in results.items():
        print(f"{name:14s} {figures['rl_steps_per_second']:8.1f} RL steps/s  "
              f"{figures['physics_steps_per_second']:7d} physics steps/s  "
              f"success {figures['success_rate']:.2f}  "
              f"steps to goal {figures['mean_steps_to_goal']}")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
