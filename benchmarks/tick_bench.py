"""Microseconds per 1 kHz tick of the in-process torque loop, split by what the tick composes.

The loop is built as the in-process runner builds it (``InsertionRobot``: the robot plugin, the
bridge's and the EKF's config files) and runs uniform random-residual RL steps from the 8 start
poses, the learner's workload without the learner. Each part the tick calls is timed by a
wrapper around it (hardware read, wrench EKF, controller, safety filter, rest detector, and the
hardware write, which applies the torques and steps the physics); "loop" is the rest of
``tick``. The hardware write is split once more: the physics engine's own step (the world's
``step``) and the scene's Python around it (joint friction, sensor errors, the fit's undoing).
The wrappers cost ~0.2 us each; the total is also timed without them, in a second pass of the
same steps. On MuJoCo a third pass of the same steps splits the engine's step by MuJoCo's own
timers (``mjData.timer``, fed by ``time.perf_counter`` as ``mjcb_time`` only during that pass:
collision broad and narrow phase, constraint making, the solver, the rest); the Python clock
callback costs a little per timer, so that pass's engine step is printed beside it. Each robot given (``--robot``, default both engines' Panda) is measured in turn, in
one run. The last line is one JSON object.

Usage: python benchmarks/tick_bench.py [--steps 40] [--seed 0] [--clock wall|cpu]
       [--robot sim_panda_pybullet --robot sim_panda_mujoco]
"""
from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
from qg_common.types import N_START_POSES, WrenchSetpoint
from qg_experiments.runner import InsertionRobot, StackSettings

#: What the tick calls, by the attribute path from the loop.
PARTS = {"read": ("hardware", "read"), "ekf": ("estimator", "update"),
         "controller": ("controller", "step"), "safety_tilt": ("safety", "limit_tilt"),
         "safety_torques": ("safety", "limit_torques"), "rest": ("rest", "update"),
         "write": ("hardware", "write")}


#: The clock every part is timed by: wall time, or with ``--clock cpu`` this thread's CPU time
#: (on a shared machine the time the tick took while it had a core; ~0.3 us more per call).
CLOCK = {"wall": time.perf_counter, "cpu": time.thread_time}
clock = CLOCK["wall"]


def timed(function: Callable[..., Any], totals: dict[str, float], name: str
          ) -> Callable[..., Any]:
    """``function``, adding its time on :data:`clock` to ``totals[name]``."""

    def wrapper(*args: Any) -> Any:
        start = clock()
        result = function(*args)
        totals[name] += clock() - start
        return result
    return wrapper


#: MuJoCo's timers the engine's step is split into (``mujoco.mjtTimer``), by the name printed.
ENGINE_PARTS = {"collision_broad": "mjTIMER_COL_BROAD", "collision_narrow": "mjTIMER_COL_NARROW",
                "kinematics_inertia": ("mjTIMER_POS_KINEMATICS", "mjTIMER_POS_INERTIA"),
                "make_constraints": ("mjTIMER_POS_MAKE", "mjTIMER_POS_PROJECT"),
                "velocity_actuation": ("mjTIMER_VELOCITY", "mjTIMER_ACTUATION"),
                "solver": "mjTIMER_CONSTRAINT", "integrate": "mjTIMER_ADVANCE"}


def engine_split(task: InsertionRobot, steps: int, seed: int) -> dict[str, float]:
    """The MuJoCo step of ``task`` split by MuJoCo's timers over ``steps`` RL steps [us per tick].

    Why: collision and solver cannot be told apart from outside ``mj_step``.
    """
    data = task.loop.simulation.scene.world.data
    ids = {name: [int(getattr(mujoco.mjtTimer, t)) for t in ((ts,) if isinstance(ts, str) else ts)]
           for name, ts in ENGINE_PARTS.items()}
    step_id = int(mujoco.mjtTimer.mjTIMER_STEP)
    mujoco.set_mjcb_time(time.perf_counter)      # the wall clock whatever --clock: the cheapest
    try:
        before = np.array(data.timer.duration, dtype=float)
        calls_before = int(data.timer.number[step_id])
        run_steps(task, steps, seed)
        spent = np.array(data.timer.duration, dtype=float) - before
        steps_taken = int(data.timer.number[step_id]) - calls_before
    finally:
        mujoco.set_mjcb_time(None)
    spent *= 1e6                                  # [us]
    us = {name: float(spent[i].sum()) / steps_taken for name, i in ids.items()}
    step = float(spent[step_id]) / steps_taken
    us["other"] = step - sum(us.values())
    us["engine_step (timed)"] = step
    return us


def run_steps(task: InsertionRobot, steps: int, seed: int) -> tuple[int, float]:
    """Random-residual steps from rotating start poses; (ticks, wall seconds inside ``tick``)."""
    loop, rng = task.loop, np.random.default_rng(seed)
    ticks, busy = 0, 0.0
    for step in range(steps):
        if step % 5 == 0:
            loop.reset(task.residual.start_pose((step // 5) % N_START_POSES))
        loop.command(WrenchSetpoint(task.residual.wrench(rng.uniform(-1.0, 1.0, 2))))
        start = clock()
        while True:
            ticks += 1
            if loop.tick():
                break
        busy += clock() - start
    return ticks, busy


def measure(robot: str, steps: int, seed: int) -> dict[str, Any]:
    """The tick's cost on ``robot``, split by part [us per tick]."""
    task = InsertionRobot(StackSettings.load(robot=robot))
    run_steps(task, 5, seed + 1)                            # warm-up (imports, caches)
    ticks, busy = run_steps(task, steps, seed)              # plain: the total
    totals = dict.fromkeys([*PARTS, "engine_step"], 0.0)
    loop = task.loop
    for name, (owner, method) in PARTS.items():
        target = getattr(loop, owner)
        setattr(target, method, timed(getattr(target, method), totals, name))
    world = loop.simulation.scene.world
    world.step = timed(world.step, totals, "engine_step")
    split_ticks, split_busy = run_steps(task, steps, seed)
    us = {name: 1e6 * seconds / split_ticks for name, seconds in totals.items()}
    us["write"] -= us["engine_step"]          # what remains: the scene's Python around it
    us["loop"] = 1e6 * split_busy / split_ticks - sum(us.values())
    total = 1e6 * busy / ticks
    engine = engine_split(task, steps, seed) if task.settings.engine == "mujoco" else {}
    task.close()
    print(f"{robot} ({task.settings.engine}):")
    for name, value in us.items():
        print(f"  {name:18s} {value:6.1f} us")
    for name, value in engine.items():
        print(f"    engine: {name:20s} {value:6.1f} us")
    print(f"  {'tick (unwrapped)':18s} {total:6.1f} us over {ticks} ticks; outside the engine's "
          f"step: ~{total - us['engine_step']:.0f} us", flush=True)
    return {"engine": task.settings.engine, "us_per_tick": round(total, 1),
            "us_per_part": {k: round(v, 1) for k, v in us.items()},
            "engine_us_per_part": {k: round(v, 2) for k, v in engine.items()}, "ticks": ticks}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=40, help="RL steps per pass")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--robot", action="append", default=None,
                        help="robot plugin (repeat for several; default: the Panda on each "
                             "engine)")
    parser.add_argument("--clock", choices=sorted(CLOCK), default="wall",
                        help="time by the wall clock or by this thread's CPU time")
    args = parser.parse_args()
    global clock
    clock = CLOCK[args.clock]
    robots = args.robot or ["sim_panda_pybullet", "sim_panda_mujoco"]
    print(json.dumps({"steps": args.steps, "clock": args.clock, **{robot: measure(robot, args.steps, args.seed)
                                               for robot in robots}}))


if __name__ == "__main__":
    main()
