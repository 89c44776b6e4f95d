"""The free modes of the impedance-controlled Panda at the 8 start poses, from its model.

Why: docs/learning.md (section 3) explains the RL steps that end at ``rest.max_time`` by tilt
modes at 0.5-0.8 Hz that need ~1.5 s to settle. This computes them instead of inferring them from
step durations, so the explanation holds or falls on the numbers, not on a fit.

At each start pose (the scene's inverse kinematics, the ideal arm, so no start jitter), with the
model the bridge's loop builds (``ArmModel.from_description`` of the ``sim_panda`` robot: URDF,
tool frame at the grasp point, shaft as payload):

- ``Lambda = (J M^-1 J^T)^-1``, ``J`` the tool-frame Jacobian expressed in the EEF frame (the
  kernel's ``rot6^T J``, LOCAL_WORLD_ALIGNED rotated into the tool's axes, as K and D act);
- per EEF axis (diagonal approximation: cross terms of Lambda, K and D are ignored) the
  undamped natural frequency ``sqrt(K/Lambda)`` and damping ratio ``D / (2 sqrt(K Lambda))``,
  ``D`` including what the joint damping ``d_joint`` adds at the tool
  (``Lambda J M^-1 d_joint M^-1 J^T Lambda``); and the time after which the speed of a
  single mass-spring-damper with those values, hit by a 3 Nm torque step (the largest residual),
  stays below the rest threshold (0.02 rad/s);
- the shortest such time any damping gives (a scan of D from 0.1 to 8 Nms/rad): the bound
  no ``d_rot`` can beat at this stiffness and inertia;
- the same for a tilt pivoting about the shaft tip (what a tip held in the bore does: stiffness
  ``k_rot + k_trans L^2``, inertia ``Lambda_rot + Lambda_trans L^2``, L the grasp height);
- as a check of the approximation, the modes of the linearised closed loop in joint space
  (``M ddq + D_q dq + K_q dq = 0`` with ``K_q = J^T K J + k_null N``,
  ``D_q = J^T D J + d_null N + d_joint``, ``N`` the kernel's projector): frequency and damping
  ratio of the slowest oscillating modes, free arm (no contact).

Usage: python benchmarks/tilt_modes.py [--torque 3.0] [--threshold 0.02] [--set k=v ...]
The last line is one JSON object.
"""
from __future__ import annotations

import argparse
import copy
import json

import numpy as np
import yaml
from qg_common.types import N_START_POSES
from qg_experiments.runner import StackSettings
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.impedance import ImpedanceConfig

AXES = ("x", "y", "z", "rx", "ry", "rz")


def start_configurations(robot_params: dict) -> tuple[ArmModel, list[np.ndarray], float]:
    """The loop's model, the joint angles of the 8 starts and the grasp height [m]."""
    robot = load_robot("sim_panda", robot_params)
    model = ArmModel.from_description(robot.description)
    qs = []
    for pose in range(N_START_POSES):
        robot.simulation.reset(pose)
        qs.append(np.asarray(robot.hardware.read().q, float).copy())
    grasp = float(robot_params["panda_scene"]["grasp_height"])
    robot.simulation.close()
    return model, qs, grasp


def eef_jacobian(model: ArmModel, q: np.ndarray) -> np.ndarray:
    """(6, n) tool Jacobian in the EEF frame (linear first), as the kernel applies K and D."""
    kin = model.kinematics(q)
    rot6 = np.zeros((6, 6))
    rot6[:3, :3] = rot6[3:, 3:] = kin.rotation
    return rot6.T @ kin.jacobian


def null_projector(jac: np.ndarray) -> np.ndarray:
    """The kernel's ``I - J^T (J J^T)^-1 J`` (J base-frame or EEF-frame: the same matrix)."""
    jjt = jac @ jac.T + 1e-6 * np.eye(6)
    return np.eye(jac.shape[1]) - jac.T @ np.linalg.solve(jjt, jac)


def speed_settle_time(inertia: float, stiffness: float, damping: float, force: float,
                      threshold: float, horizon: float = 30.0, dt: float = 1e-3) -> float:
    """[s] after which the speed of ``I x'' + d x' + k x = F`` (from rest) stays below
    ``threshold``; ``horizon`` if it never does within it."""
    t = np.arange(0.0, horizon, dt)
    roots = np.roots([inertia, damping, stiffness]).astype(complex)
    s1, s2 = roots
    if abs(s1 - s2) < 1e-9 * max(1.0, abs(s1)):
        v = force / inertia * t * np.exp(s1.real * t)
    else:
        v = (force / inertia * (np.exp(s1 * t) - np.exp(s2 * t)) / (s1 - s2)).real
    above = np.nonzero(np.abs(v) >= threshold)[0]
    return float(t[above[-1]] + dt) if above.size and above[-1] + 1 < t.size else \
        (horizon if above.size else 0.0)


def joint_space_modes(model: ArmModel, q: np.ndarray, jac: np.ndarray, config: ImpedanceConfig
                      ) -> list[tuple[float, float]]:
    """(frequency [Hz], damping ratio) of the oscillating modes of the linearised closed loop,
    slowest first."""
    k, d = config.gains()
    n = model.nv
    proj = null_projector(jac)
    stiff = jac.T @ np.diag(k) @ jac + config.k_null * proj
    damp = jac.T @ np.diag(d) @ jac + config.d_null * proj + config.d_joint * np.eye(n)
    minv = np.linalg.inv(model.mass_matrix(q))
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv @ stiff, -minv @ damp]])
    modes = []
    for s in np.linalg.eigvals(a):
        if s.imag > 1e-6:
            wn = abs(s)
            modes.append((wn / (2 * np.pi), -s.real / wn))
    return sorted(modes)


def pose_table(model: ArmModel, q: np.ndarray, config: ImpedanceConfig, grasp: float,
               torque: float, threshold: float) -> dict:
    """Lambda's diagonal and the per-axis and tip-pivot mode figures at one pose."""
    jac = eef_jacobian(model, q)
    minv = np.linalg.inv(model.mass_matrix(q))
    lam = np.linalg.inv(jac @ minv @ jac.T)
    joint_damping_at_tool = lam @ jac @ minv @ (config.d_joint * minv) @ jac.T @ lam
    k, d = config.gains()
    d_eff = d + np.diag(joint_damping_at_tool)
    axes = {}
    for i, name in enumerate(AXES):
        if k[i] <= 0.0:
            axes[name] = {"inertia": lam[i, i], "damping": d_eff[i]}
            continue
        axes[name] = _mode(lam[i, i], k[i], d_eff[i], torque if i >= 3 else None, threshold)
    pivot = {}
    for name, rot, lin in (("rx", 3, 1), ("ry", 4, 0)):  # tilt about x moves the tip along y
        pivot[name] = _mode(lam[rot, rot] + lam[lin, lin] * grasp ** 2,
                            k[rot] + k[lin] * grasp ** 2, d_eff[rot] + d_eff[lin] * grasp ** 2,
                            torque, threshold)
    return {"axes": axes, "pivot": pivot,
            "joint_modes": joint_space_modes(model, q, jac, config)[:3]}


def _mode(inertia: float, stiffness: float, damping: float, torque: float | None,
          threshold: float) -> dict:
    wn = float(np.sqrt(stiffness / inertia))
    out = {"inertia": float(inertia), "damping": float(damping), "f_hz": wn / (2 * np.pi),
           "zeta": float(damping / (2.0 * np.sqrt(stiffness * inertia)))}
    if torque is not None:
        out["settle_s"] = speed_settle_time(inertia, stiffness, damping, torque, threshold)
        out["peak_speed"] = _peak_speed(inertia, stiffness, damping, torque)
        # the fastest any damping makes it: a bound no setting of d_rot can beat
        best = min((speed_settle_time(inertia, stiffness, float(c), torque, threshold), c)
                   for c in np.linspace(0.1, 8.0, 80))
        out["best_settle_s"], out["best_damping"] = best[0], float(best[1])
    return out


def _peak_speed(inertia: float, stiffness: float, damping: float, torque: float) -> float:
    t = np.arange(0.0, 5.0, 1e-3)
    x = np.zeros(2)
    peak = 0.0
    for _ in t:  # semi-implicit Euler, 1 ms: only the peak is wanted
        x[1] += 1e-3 * (torque - damping * x[1] - stiffness * x[0]) / inertia
        x[0] += 1e-3 * x[1]
        peak = max(peak, abs(x[1]))
    return peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--torque", type=float, default=3.0, help="[Nm] torque step")
    parser.add_argument("--threshold", type=float, default=0.02, help="[rad/s] rest threshold")
    parser.add_argument("--set", action="append", default=[], metavar="impedance.KEY=VALUE")
    args = parser.parse_args()
    settings = StackSettings.load(arm="ideal")
    bridge = copy.deepcopy(settings.bridge)
    for assignment in args.set:
        path, _, value = assignment.partition("=")
        section, key = path.split(".")
        bridge.setdefault(section, {})[key] = yaml.safe_load(value)
    config = ImpedanceConfig.from_dict(bridge.get("impedance", {}))
    model, qs, grasp = start_configurations(settings.robot)
    rows = [pose_table(model, q, config, grasp, args.torque, args.threshold) for q in qs]
    print(f"K {config.gains()[0].tolist()}, D {config.gains()[1].tolist()}, d_joint "
          f"{config.d_joint}, d_null {config.d_null}; {args.torque} Nm step, speed below "
          f"{args.threshold} rad/s (single mass-spring-damper, diagonal of Lambda)")
    print("pose | Lambda x  y [kg]  rx   ry   rz [kg m^2] | f [Hz] x  y  rx  ry  rz | zeta rx  ry"
          " | settle rx ry [s] (best d) | tip pivot f rx ry, zeta rx ry, settle rx ry | joint-space "
          "modes [Hz (zeta)]")
    for pose, r in enumerate(rows):
        a, p = r["axes"], r["pivot"]
        print(f"{pose:4d} | {a['x']['inertia']:5.1f} {a['y']['inertia']:5.1f} "
              f"{a['rx']['inertia']:6.3f} {a['ry']['inertia']:6.3f} {a['rz']['inertia']:6.4f} | "
              + " ".join(f"{a[n]['f_hz']:4.2f}" for n in ("x", "y", "rx", "ry", "rz"))
              + f" | {a['rx']['zeta']:4.2f} {a['ry']['zeta']:4.2f}"
              f" | {a['rx']['settle_s']:4.2f} {a['ry']['settle_s']:4.2f} (best "
              f"{a['rx']['best_settle_s']:4.2f} {a['ry']['best_settle_s']:4.2f})"
              f" | {p['rx']['f_hz']:4.2f} {p['ry']['f_hz']:4.2f}, {p['rx']['zeta']:4.2f} "
              f"{p['ry']['zeta']:4.2f}, {p['rx']['settle_s']:4.2f} {p['ry']['settle_s']:4.2f} | "
              + " ".join(f"{f:4.2f} ({z:4.2f})" for f, z in r["joint_modes"]))

    def span(values: list[float]) -> list[float]:
        return [round(min(values), 4), round(max(values), 4)]

    summary = {"impedance": {k: list(v) if isinstance(v, tuple) else v
                             for k, v in vars(config).items()},
               "torque": args.torque, "threshold": args.threshold}
    for name in ("rx", "ry"):
        for key in ("inertia", "f_hz", "zeta", "settle_s", "peak_speed", "best_settle_s",
                    "best_damping"):
            summary[f"{name}_{key}"] = span([r["axes"][name][key] for r in rows])
            summary[f"pivot_{name}_{key}"] = span([r["pivot"][name][key] for r in rows])
    for name in ("x", "y"):
        summary[f"{name}_inertia"] = span([r["axes"][name]["inertia"] for r in rows])
        summary[f"{name}_f_hz"] = span([r["axes"][name]["f_hz"] for r in rows])
        summary[f"{name}_zeta"] = span([r["axes"][name]["zeta"] for r in rows])
    summary["slowest_joint_mode_hz"] = span([r["joint_modes"][0][0] for r in rows])
    summary["slowest_joint_mode_zeta"] = span([r["joint_modes"][0][1] for r in rows])
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
