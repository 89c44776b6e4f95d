"""The Franka plugin through franky-sim on this machine: holding still, the bridge's loop on it,
a known push on the hand, and how fast an unreachable arm is refused.

Starts ``franka_sim`` (franky-sim's MuJoCo FR3 with the demo scene: a block 10 cm below the held
cylinder's tip where the arm starts, and no unknown payload, so gravity alone holds the arm) on a
private loopback address, connects ``robot:=franka`` and measures:

1. *hold*: ``--hold`` seconds of gravity-only torques (zero after the gravity the robot adds is
   subtracted): libfranka's ``control_command_success_rate``, the joints' and the tool's drift,
   robot states the loop missed, the loop's period (wall clock between reads).
2. *loop*: the bridge's loop (``build_loop`` with ``config/bridge.yaml`` and the EKF, on the
   robot's state clock) executing residual setpoints on the free arm, alternately a 15 N push
   along the tool (down) and a 15 N pull (up): how far the tool moves each way per step, and
   the loop's tick period.
3. *push*: the loop holding the pose stiffly (its watchdog hold) while franky-sim pushes the
   hand with a known force (MuJoCo's ``xfrc_applied``): the EKF's estimate against it.
4. *refusal*: the seconds until an address nobody serves and one that does not answer are
   refused, with libfranka's and our reasons.

The benchmark process runs at ``SCHED_FIFO`` ``--priority`` (the loop process's default, 50) and
franky-sim at ``--sim-priority`` (40), as a robot's own computer would; 0 runs either at normal
priority. A loop that stalls past libfranka's signal timeout ends the run's phases with the
fault libfranka reported (``fault``). The last line is one JSON object.

Usage: python benchmarks/franka_bench.py [--hold 10] [--steps 20] [--priority 50]
"""
from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from franka_robot_node.core.franka_arm import FrankaConnectError, FrankaFault
from franka_robot_node.plugin import FRANKA
from franka_sim_node.franka_sim import spawn
from qg_common.params import load_ros_params, merge_params, package_config
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.hardware_interface import robot_defaults
from robot_bridge_node.core.loop_clock import MAX_STATE_GAP, StateClock
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from robot_bridge_node.core.torque_kind import build_ekf

PUSH = 15.0        # [N] along the tool axis, each way
FREE_AIR_STEP = 0.25   # [s] the free-air steps' limit (nothing stops the arm: no rest)
FORCE = (0.0, 0.0, -5.0, 0.0, 0.0, 0.0)   # [N, Nm] the known push on the hand, base frame


def percentiles(periods: list[float]) -> dict[str, float]:
    d = np.asarray(periods) * 1e3
    return {"p50_ms": round(float(np.percentile(d, 50)), 3),
            "p99_ms": round(float(np.percentile(d, 99)), 3), "max_ms": round(float(d.max()), 3)}


class ReadTimes:
    """Wraps ``read``: the wall clock of every new state read and the robot's stamps."""

    def __init__(self, arm) -> None:
        self.arm, self.inner = arm, arm.read
        self.wall: list[float] = []
        self.stamps: list[float] = []
        arm.read = self

    def __call__(self):
        state = self.inner()
        stamp = self.arm.state_time()
        if not self.stamps or stamp != self.stamps[-1]:     # a tick's read, not a re-read
            self.wall.append(time.perf_counter())
            self.stamps.append(stamp)
        return state

    def summary(self) -> dict[str, float]:
        span = round((self.stamps[-1] - self.stamps[0]) * 1000)
        return {"ticks": len(self.wall), "robot_ms": span,
                "missed_states": span + 1 - len(self.wall),
                **percentiles(list(np.diff(self.wall)))}


def hold(robot, seconds: float) -> dict:
    arm = robot.hardware
    model_q0 = arm.read().q.copy()
    times = ReadTimes(arm)
    tool0 = arm.robot.state.O_T_EE.translation.copy()
    end = arm.state_time() + seconds
    while arm.state_time() < end:
        arm.read()
        arm.write(arm.robot_gravity())       # zero after the gravity subtraction
    drift = float(np.abs(arm.read().q - model_q0).max())
    tool_drift = float(np.linalg.norm(arm.robot.state.O_T_EE.translation - tool0))
    arm.read = times.inner
    return {"success_rate": arm.command_success_rate(), "joint_drift_mrad": round(drift * 1e3, 3),
            "tool_drift_mm": round(tool_drift * 1e3, 3), **times.summary()}


def loop_steps(loop: RobotLoop, steps: int) -> dict:
    times = ReadTimes(loop.hardware)
    moves = {"down": [], "up": []}
    for k in range(steps):
        push = -PUSH if k % 2 == 0 else PUSH      # residual force along the tool axis
        z0 = loop.controller.model.kinematics(loop.hardware.read().q).position[2]
        loop.execute(WrenchSetpoint.residual(push, 0.0, 0.0))
        z1 = loop.controller.tool.position[2]
        moves["down" if push < 0 else "up"].append(float(z1 - z0) * 1e3)
    loop.hardware.read = times.inner
    return {"tool_dz_mm_push_down": [round(v, 2) for v in moves["down"]],
            "tool_dz_mm_pull_up": [round(v, 2) for v in moves["up"]],
            "tick": times.summary()}


def known_push(loop: RobotLoop, sim, seconds: float = 1.5) -> dict:
    """The EKF's estimate while the loop holds stiffly and franky-sim pushes the hand."""
    loop.command(WrenchSetpoint(np.zeros(6)))
    loop.controller.hold(loop.hardware.read().q)
    loop.holding = True

    def settle() -> np.ndarray:
        estimates = []
        for _ in range(round(seconds / 0.001)):
            loop.tick()
            estimates.append(loop.wrench_estimate.copy())
        return np.mean(estimates[-200:], axis=0)

    before = settle()
    sim.stdin.write("wrench " + " ".join(map(str, FORCE)) + "\n")
    sim.stdin.flush()
    during = settle()
    rotation = loop.controller.tool.rotation
    expected = np.concatenate([rotation.T @ np.array(FORCE[:3]), rotation.T @ np.array(FORCE[3:])])
    sim.stdin.write("wrench 0 0 0 0 0 0\n")
    sim.stdin.flush()
    change = during - before
    return {"applied_tool_frame": np.round(expected, 3).tolist(),
            "ekf_before": np.round(before, 3).tolist(), "ekf_during": np.round(during, 3).tolist(),
            "force_error_N": round(float(np.linalg.norm(change[:3] - expected[:3])), 3),
            "torque_error_Nm": round(float(np.linalg.norm(change[3:] - expected[3:])), 3)}


def refusal(address: str) -> dict:
    out = {}
    for name, where in (("refused", address), ("no_answer", "10.255.255.1")):
        start = time.monotonic()
        try:
            FRANKA.create({"franka": {"address": where}})
            out[name] = {"seconds": None, "reason": "connected?!"}
        except FrankaConnectError as exc:
            out[name] = {"seconds": round(time.monotonic() - start, 2), "reason": str(exc)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hold", type=float, default=10.0, help="[s] gravity-only hold")
    parser.add_argument("--steps", type=int, default=20, help="loop steps on the free arm")
    parser.add_argument("--priority", type=int, default=50, help="SCHED_FIFO of this process")
    parser.add_argument("--sim-priority", type=int, default=40, help="SCHED_FIFO of franky-sim")
    args = parser.parse_args()
    address = f"127.0.{34 + os.getpid() % 200}.{1 + os.getpid() % 250}"
    sim = spawn(address, "--realtime-priority", str(args.sim_priority), "--scene",
                "franka_sim_node.core.franky_sim_scene:demo_scene")
    if args.priority > 0:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.priority))
    results: dict = {"address": address, "load_average": os.getloadavg()[0]}
    try:
        params = {"franka": {"address": address}}
        robot = FRANKA.create(params)
        arm = robot.hardware
        try:
            results["hold"] = hold(robot, args.hold)
            print(f"hold {args.hold} s: {results['hold']}", flush=True)
            arm.close()                              # the loop's first write starts anew
            bridge = robot_defaults(FRANKA, (("robot_bridge_node", "bridge.yaml"),), "bridge")
            # Free-air steps at the 0.25 s limit: a step that ends at rest (the default, up to
            # 3 s) carried the free arm 0.47 m per step, out of the demo scene and its start.
            bridge = merge_params(bridge, {"rest": {"max_time": FREE_AIR_STEP}})
            ekf = load_ros_params(package_config("robot_bridge_node", "wrench_estimator.yaml"))
            loop = build_loop(robot, bridge, lambda robot, model: build_ekf(ekf, model),
                              StateClock(arm, MAX_STATE_GAP))
            loop.begin()
            loop.settle_here()                       # the episode starts where the arm is
            results["loop"] = loop_steps(loop, args.steps)
            print(f"loop, {args.steps} steps: {results['loop']}", flush=True)
            results["push"] = known_push(loop, sim)
            print(f"known push on the hand: {results['push']}", flush=True)
        except FrankaFault as exc:                   # what a stalled loop gets from libfranka
            results["fault"] = {"after_phases": [k for k in ("hold", "loop", "push")
                                                 if k in results], "reason": str(exc)}
            print(f"fault: {results['fault']}", flush=True)
        arm.close()
        results["success_rate_end"] = arm.command_success_rate()
    finally:
        sim.terminate()
        sim.wait(10)
        results["sim"] = sim.output[-1] if sim.output else ""
    results["refusal"] = refusal(f"127.0.{34 + os.getpid() % 200}.251")
    print(f"refusal: {results['refusal']}", flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
