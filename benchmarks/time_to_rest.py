"""How long an RL step takes to come to rest at the stack's gains, without a short time limit.

Runs residual episodes (8 start poses, at most ``--max-steps`` steps each; uniform random
residuals, or with ``--policy zero`` the base push alone) through the in-process Panda task (sim
+ bridge loop + EKF, ``config/``) with ``rest.max_time`` raised to ``--max-time``, and prints the
distribution of step durations, the share of steps that still reached the limit and the RL steps
per wall second and per CPU second of this process (the machine is shared: CPU time is what a
core gives when the process has it alone). Each ``--robot`` (default: the Panda on pybullet,
then on MuJoCo) is measured in turn, in one run.

- ``--arm realistic|ideal``: the arm as ``StackSettings.load`` builds it (``ideal``:
  ``panda_ideal.yaml`` on top of ``panda_scene.yaml``; arm seed 0 of the file).
- ``--set section.key=value`` overrides a ``bridge.yaml`` parameter (e.g.
  ``impedance.d_rot=[2.5,2.5,0.6]`` or ``rest.angular_threshold=0.1``), ``--scene-set`` a
  ``panda_scene.yaml`` one (e.g. ``panda_scene.friction=0.8``).
- For the steps that reached the limit it prints the tool's linear and angular speed at the end
  (median) and which threshold held the step open; for all steps the per-tick speeds of the last
  ``--window`` ticks (their median and 99th percentile over the steps: on a jammed, still arm
  that is the speed noise floor the rest thresholds must clear).

This is what docs/learning.md (section 3) measures to show that at 4 Nm/rad and the Panda's
inertia a free step needs about 1.5 s to settle. The last line is one JSON object.

Usage: python benchmarks/time_to_rest.py [--max-time 3.0] [--seed 0] [--arm realistic|ideal]
       [--policy random|zero] [--set rest.max_time=...] [--scene-set panda_scene.friction=...]
       [--robot sim_panda_pybullet --robot sim_panda_mujoco]
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import time

import numpy as np
import yaml
from qg_experiments.runner import ARMS, InsertionRobot, StackSettings
from qg_learning_node.executor.residual_task import ACTION_DIM


def _override(params: dict, assignment: str) -> None:
    """Apply ``section.key=value`` (value parsed as YAML) to a parameter tree."""
    path, _, value = assignment.partition("=")
    *sections, key = path.split(".")
    node = params
    for section in sections:
        node = node.setdefault(section, {})
    node[key] = yaml.safe_load(value)


class _SpeedTrace:
    """Records the tool speeds the rest detector is fed, tick by tick (wraps its ``update``)."""

    def __init__(self, detector) -> None:
        self.linear: list[float] = []
        self.angular: list[float] = []
        update = detector.update

        def traced(linear_speed: float, angular_speed: float, dt: float) -> bool:
            self.linear.append(linear_speed)
            self.angular.append(angular_speed)
            return update(linear_speed, angular_speed, dt)

        detector.update = traced

    def clear(self) -> None:
        self.linear.clear()
        self.angular.clear()


def _pct(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def measure(robot_name: str, args: argparse.Namespace) -> dict:
    """Time to rest and RL steps per second of ``robot_name`` under ``args``."""
    settings = StackSettings.load(arm=args.arm, robot=robot_name)
    bridge = copy.deepcopy(settings.bridge)
    bridge.setdefault("rest", {})["max_time"] = args.max_time
    for assignment in args.set:
        _override(bridge, assignment)
    robot = copy.deepcopy(settings.robot)
    for assignment in args.scene_set:
        _override(robot, assignment)
    env = InsertionRobot(dataclasses.replace(settings, bridge=bridge, robot=robot))
    trace = _SpeedTrace(env.loop.rest)
    rest = env.loop.rest.config
    rng = np.random.default_rng(args.seed)
    durations, timed_out, episode_steps, successes = [], [], [], 0
    end_linear, end_angular, blocked = [], [], {"linear": 0, "angular": 0, "both": 0}
    window_linear, window_angular = [], []   # per step: the last ticks' median / p99 speed
    start, cpu = time.perf_counter(), time.process_time()
    for pose in range(8):
        obs = env.reset(pose)
        for step in range(1, args.max_steps + 1):
            action = (rng.uniform(-1.0, 1.0, ACTION_DIM) if args.policy == "random"
                      else np.zeros(ACTION_DIM))
            trace.clear()
            obs = env.step(action)
            durations.append(env.loop.rest.elapsed)
            timed_out.append(env.loop.rest.timed_out)
            window_linear.append(trace.linear[-args.window:])
            window_angular.append(trace.angular[-args.window:])
            if env.loop.rest.timed_out:
                tool = env.loop.controller.tool
                end_linear.append(tool.linear_speed)
                end_angular.append(tool.angular_speed)
                moving_linear = tool.linear_speed >= rest.linear_threshold
                moving_angular = tool.angular_speed >= rest.angular_threshold
                key = ("both" if moving_linear and moving_angular
                       else "linear" if moving_linear else "angular" if moving_angular else None)
                if key is not None:
                    blocked[key] += 1
            if env.residual.succeeded(obs) or env.residual.left_bore(obs):
                break
        successes += int(env.residual.succeeded(obs))
        episode_steps.append(step)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    env.close()
    d = np.array(durations)
    win_lin = [float(np.median(w)) for w in window_linear]
    win_ang = [float(np.median(w)) for w in window_angular]
    win_lin99 = [float(np.percentile(w, 99)) for w in window_linear]
    win_ang99 = [float(np.percentile(w, 99)) for w in window_angular]
    result = {"robot": robot_name, "engine": settings.engine, "arm": args.arm,
              "policy": args.policy, "max_time": args.max_time, "overrides": args.set,
              "scene_overrides": args.scene_set, "steps": len(d),
              "success": f"{successes}/8", "mean_episode_steps": float(np.mean(episode_steps)),
              "timeout_fraction": float(np.mean(timed_out)),
              "duration_p25": float(np.percentile(d, 25)),
              "duration_median": float(np.median(d)),
              "duration_p90": float(np.percentile(d, 90)),
              "timeout_end_linear_speed_median": _pct(end_linear, 50),
              "timeout_end_angular_speed_median": _pct(end_angular, 50),
              "timeout_held_open_by": blocked,
              "window_ticks": args.window,
              "window_linear_speed_median": _pct(win_lin, 50),
              "window_linear_speed_p99_median": _pct(win_lin99, 50),
              "window_angular_speed_median": _pct(win_ang, 50),
              "window_angular_speed_p99_median": _pct(win_ang99, 50),
              "rl_steps_per_second": len(d) / wall, "rl_steps_per_cpu_second": len(d) / cpu,
              "sim_seconds_per_wall_second": d.sum() / wall}
    print(f"{robot_name} ({settings.engine}): {len(d)} {args.policy} steps, {args.arm} arm, "
          f"max_time {args.max_time} s {args.set} {args.scene_set}: "
          f"{result['timeout_fraction']:.0%} at the limit; time to rest median "
          f"{result['duration_median']:.3f} s (p25 {result['duration_p25']:.3f}, p90 "
          f"{result['duration_p90']:.3f}); {result['rl_steps_per_second']:.1f} RL steps/s "
          f"({result['rl_steps_per_cpu_second']:.1f} per CPU second); "
          f"success {result['success']}, {result['mean_episode_steps']:.1f} steps/episode")
    if end_linear:
        print(f"steps at the limit end at (median) {np.median(end_linear) * 1e3:.2f} mm/s, "
              f"{np.median(end_angular):.4f} rad/s (thresholds {rest.linear_threshold * 1e3:g} "
              f"mm/s, {rest.angular_threshold:g} rad/s); held open by {blocked}")
    print(f"last {args.window} ticks of every step, median over steps of the median / p99 speed: "
          f"{result['window_linear_speed_median'] * 1e3:.2f} / "
          f"{result['window_linear_speed_p99_median'] * 1e3:.2f} mm/s, "
          f"{result['window_angular_speed_median']:.4f} / "
          f"{result['window_angular_speed_p99_median']:.4f} rad/s")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-time", type=float, default=3.0, help="rest.max_time [s]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-steps", type=int, default=60, help="per episode")
    parser.add_argument("--arm", choices=ARMS, default="realistic")
    parser.add_argument("--policy", choices=("random", "zero"), default="random",
                        help="uniform random residuals or the zero residual (base push only)")
    parser.add_argument("--window", type=int, default=20,
                        help="ticks at the end of each step whose speeds are reported")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="bridge.yaml parameter")
    parser.add_argument("--scene-set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="panda_scene.yaml parameter, e.g. panda_scene.solver_iterations=100")
    parser.add_argument("--robot", action="append", default=None,
                        help="robot plugin (repeat for several; default: the Panda on each "
                             "engine)")
    args = parser.parse_args()
    robots = args.robot or ["sim_panda_pybullet", "sim_panda_mujoco"]
    results = {robot: measure(robot, args) for robot in robots}
    print(json.dumps(results))


if __name__ == "__main__":
    main()
