"""The three properties SPEC section 1 asks of the simulated press fit, measured.

1. The base push alone (Fz = -15 N, zero residual) jams from most of the 8 starts.
2. Uniform random residual torques ([-1, 1]^2 scaled to 3 Nm) finish, and how many steps they
   need (the real robot: 32 on average).
3. The last millimetres need a sustained push above 10 N: the force-vs-depth curve of an upright
   shaft pressed with a slowly rising force, and the constant pushes that stall or finish.
A hand-written "tilt back towards vertical" policy (using ground truth) gives the floor a learner
could approach. Each ``--robot`` (default: the Panda on pybullet, then on MuJoCo) is measured in
turn with the stack's config files (``StackSettings.load``: its scene, ``config/bridge.yaml``'s
gains and step limit), so one run prints both engines' figures. Prints tables; the last line is
one JSON object, by robot.

Usage: python benchmarks/force_depth.py [--seeds 1] [--max-steps 1000] [--zero-steps 200]
       [--arm realistic|ideal] [--robot sim_panda_pybullet --robot sim_panda_mujoco]
       [--set rest.max_time=3.0]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import yaml
from qg_common.params import merge_params
from qg_common.shaft_task import TOOL_DOWN
from qg_common.types import N_START_POSES, PoseReference, WrenchSetpoint
from qg_experiments.runner import ARMS, StackSettings
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop

PUSH = -15.0


def episode(loop: RobotLoop, pose: int, max_steps: int, policy) -> tuple[bool, int, float]:
    """(success, steps, fraction of steps ended at rest) of one residual-policy episode."""
    geometry = loop.simulation.scene.geometry
    loop.reset(geometry.start_pose(pose))
    rested = 0
    for step in range(1, max_steps + 1):
        result = loop.execute(WrenchSetpoint.residual(PUSH, *policy(loop)))
        rested += not result.timed_out
        gt = result.ground_truth
        if gt.success or gt.lateral_offset > geometry.max_lateral_offset:
            return gt.success, step, rested / step
    return False, max_steps, rested / max_steps


def press(loop: RobotLoop, force: float | None, seconds: float, ramp: tuple[float, float] | None
          = None) -> list[tuple[float, float, float]]:
    """Press the shaft, held on the true bore axis; constant ``force`` or a linear ``ramp``
    (from, to) [N].

    :returns: (commanded force, tip depth, plunger travel) every 10 ms.
    """
    scene = loop.simulation.scene
    target = scene.geometry.target_tool_position(scene.fixture)
    upright = scene.fixture.rotation @ TOOL_DOWN
    ticks = round(seconds / loop.config.dt)
    trace = []
    for i in range(ticks):
        f = force if ramp is None else ramp[0] + (ramp[1] - ramp[0]) * i / ticks
        if ramp is not None or i == 0:
            loop.command(WrenchSetpoint(np.array([0.0, 0.0, -f, 0.0, 0.0, 0.0]),
                                        PoseReference(target, upright)))
        loop.tick()
        if i % 10 == 0:
            gt = loop.simulation.scene.ground_truth()
            trace.append((f, gt.insertion_depth, gt.plunger_travel))
    return trace


def tilt_back(loop: RobotLoop) -> tuple[float, float]:
    """Floor policy from ground truth: torque turning the shaft upright (contact convention)."""
    error = loop.simulation.scene.ground_truth().orientation_error
    return tuple(np.clip(-20.0 * error, -3.0, 3.0))


def land(loop: RobotLoop) -> None:
    """Start 0, turn the shaft upright under a gentle push (3 N, the tilt-back torques: a 3 N
    push and the upright pose reference alone can leave it wedged at 1-2 deg in the 0.1 mm
    clearance, or its flat end on the bore's rim when the arm's kinematics are off) and slide
    it onto the inner ring."""
    geometry = loop.simulation.scene.geometry
    loop.reset(geometry.start_pose(0))
    for _ in range(30):
        gt = loop.execute(WrenchSetpoint.residual(-3.0, *tilt_back(loop))).ground_truth
        if gt.insertion_depth > geometry.bore_depth - 0.001:
            break
    press(loop, 3.0, 0.5)


def force_depth(loop: RobotLoop) -> dict:
    land(loop)
    trace = press(loop, None, 4.0, ramp=(3.0, 15.0))  # 3 N/s: quasi-static
    print("\nforce-vs-depth, upright shaft, force rising 3 N/s")
    print(" force[N]  tip depth[mm]  ring travel[mm]  ring speed[mm/s]")
    forces = np.array([f for f, _, _ in trace])
    travel = np.array([t for _, _, t in trace])
    speed = np.gradient(travel, 0.01)  # samples every 10 ms
    for i in range(0, len(trace), 10):
        print(f"  {forces[i]:6.2f}   {trace[i][1] * 1e3:9.3f}   {travel[i] * 1e3:9.3f}"
              f"   {speed[i] * 1e3:9.2f}")
    g = loop.simulation.scene.geometry
    moving = np.flatnonzero(speed > 0.001)                  # > 1 mm/s: sliding, not creeping
    done = np.flatnonzero(travel >= g.plunger_travel - g.success_tolerance)
    before = speed[: moving[0]] if len(moving) else speed
    print("\nconstant push from the landed shaft, 2 s:")
    finishes = {}
    for force in (9.0, 10.0, 10.5, 11.0, 11.5, 12.0, 13.0):
        land(loop)
        landed = loop.simulation.scene.plunger_travel()
        press(loop, force, 2.0)
        gt = loop.simulation.scene.ground_truth()
        finishes[force] = gt.success
        print(f"  {force:5.1f} N: ring moved {(gt.plunger_travel - landed) * 1e3:.2f} mm,"
              f" {'finished' if gt.success else 'stalled'}")
    return {"ring_breaks_away_at_N": float(forces[moving[0]]) if len(moving) else None,
            "ring_creep_below_breakaway_mm_per_s": round(float(np.mean(before)) * 1e3, 3),
            "ring_finishes_at_N": float(forces[done[0]]) if len(done) else None,
            "min_constant_push_that_finishes_N": min((f for f, ok in finishes.items() if ok),
                                                     default=None),
            "max_constant_push_that_stalls_N": max((f for f, ok in finishes.items() if not ok),
                                                   default=None)}


def measure(robot: str, args: argparse.Namespace) -> dict:
    """The three properties on ``robot`` (a shaft-task plugin), with the stack's config."""
    wall = time.perf_counter()
    settings = StackSettings.load(arm=args.arm, robot=robot)
    bridge = settings.bridge
    for assignment in args.set:                 # section.key=value, value as YAML
        path, _, value = assignment.partition("=")
        section, key = path.split(".")
        bridge = merge_params(bridge, {section: {key: yaml.safe_load(value)}})
    loop = build_loop(load_robot(robot, settings.robot), bridge)
    print(f"\n=== {robot} ({settings.engine}), {args.arm} arm ===")
    out: dict = {"engine": settings.engine, "arm": args.arm,
                 "rest_max_time": loop.rest.config.max_time}
    if args.force_only:
        out.update(force_depth(loop))
        out["wall_s"] = round(time.perf_counter() - wall, 1)
        loop.simulation.close()
        return out

    print("zero residual (Fz = -15 N only), per start:")
    zero = []
    for k in range(N_START_POSES):
        ok, steps, rest = episode(loop, k, args.zero_steps, lambda _: (0.0, 0.0))
        gt = loop.simulation.scene.ground_truth()
        zero.append(ok)
        print(f"  start {k}: {'inserted in ' + str(steps) if ok else 'jammed'} "
              f"(depth {gt.insertion_depth * 1e3:.2f} mm, tilt {np.degrees(gt.tilt):.1f} deg, "
              f"steps at rest {rest:.0%})", flush=True)
    out["zero_residual_jams"] = f"{sum(not z for z in zero)}/{N_START_POSES}"

    print(f"\nuniform random residual, {args.seeds} seed(s) per start, cap {args.max_steps}:")
    steps_ok, total, rest_fractions = [], 0, []
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        for k in range(N_START_POSES):
            ok, steps, rest = episode(loop, k, args.max_steps,
                                      lambda _: tuple(3.0 * rng.uniform(-1.0, 1.0, 2)))
            total += 1
            rest_fractions.append(rest)
            if ok:
                steps_ok.append(steps)
            print(f"  seed {seed} start {k}: {'inserted in ' + str(steps) if ok else 'failed'}"
                  f" (steps at rest {rest:.0%})", flush=True)
    out["random_success"] = f"{len(steps_ok)}/{total}"
    out["random_mean_steps"] = float(np.mean(steps_ok)) if steps_ok else None
    out["random_median_steps"] = float(np.median(steps_ok)) if steps_ok else None
    out["random_steps_at_rest"] = float(np.mean(rest_fractions))
    print(f"  -> {out['random_success']} inserted, mean {out['random_mean_steps']} steps "
          f"(real robot: 32)")

    print("\ntilt-back heuristic (ground truth), per start:")
    heuristic = [episode(loop, k, 50, tilt_back) for k in range(N_START_POSES)]
    for k, (ok, steps, _) in enumerate(heuristic):
        print(f"  start {k}: {'inserted in ' + str(steps) if ok else 'failed'}")
    out["heuristic_success"] = f"{sum(h[0] for h in heuristic)}/{N_START_POSES}"
    out["heuristic_mean_steps"] = float(np.mean([h[1] for h in heuristic if h[0]] or [np.nan]))

    out.update(force_depth(loop))
    out["wall_s"] = round(time.perf_counter() - wall, 1)
    loop.simulation.close()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1, help="random-residual seeds per start")
    parser.add_argument("--max-steps", type=int, default=1000, help="random episode cap")
    parser.add_argument("--zero-steps", type=int, default=200, help="zero-residual episode cap")
    parser.add_argument("--force-only", action="store_true", help="only the force-vs-depth part")
    parser.add_argument("--arm", choices=ARMS, default="realistic",
                        help="the simulated arm: its scene file's imperfections, or "
                             "config/panda_ideal.yaml on top (none)")
    parser.add_argument("--robot", action="append", default=None,
                        help="robot plugin (repeat for several; default: the Panda on each "
                             "engine)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="a config/bridge.yaml parameter, e.g. rest.max_time=3.0")
    args = parser.parse_args()
    robots = args.robot or ["sim_panda_pybullet", "sim_panda_mujoco"]
    results = {robot: measure(robot, args) for robot in robots}
    print(json.dumps(results))


if __name__ == "__main__":
    main()
