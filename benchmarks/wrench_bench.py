"""Wrench-estimator benchmark: accuracy in free motion and quasi-static contact, settling, impacts.

A pybullet Panda under computed-torque joint control (tests/robot/ekf_harness.py) gets known
wrenches at its tool via ``applyExternalForce``/``applyExternalTorque``; the EKF with the
parameters of ``config/wrench_estimator.yaml`` sees (q, dq, tau_cmd) at 1 kHz. Every scenario runs
twice: with the simulator's exact joint state, and with white measurement noise of the std the
config assumes (1e-5 rad, 1e-3 rad/s), since the exact state makes the inverse dynamics trivial.

Scenarios (tool-frame wrench W = (5, -3, -15) N, (0.5, -0.3, 0.2) Nm):
- free: a slow joint-space oscillation (period 4 s, up to 0.4 rad), no wrench: RMSE.
- contact: W switched on at 0.3 s and held, arm at rest: settling time (error within 0.3 N and
  0.03 Nm for good) and RMSE from 0.2 s after onset.
- contact_motion: W held while the arm follows the free-motion oscillation: RMSE.
- impact: a 5 ms pulse of 60 N along the tool z axis: peak error and recovery time (back within
  0.3 N and 0.03 Nm).
- surface: a real pybullet contact. The fingertips descend 2.5 cm at 6 cm/s onto a fixed table
  (friction 0.5) 2 cm below the tool and press on it (~29 N); the truth is the contact-point
  wrench. Impact peak (truth and estimate), settling after touch (error averaged over 30 ms:
  the contact chatters at ~145 and ~430 Hz, ~0.4 N, which a ~30 ms observer only partly
  follows), bias (mean error) and RMSE against the raw truth from 0.5 s after touch.
Last line: one JSON object.
"""
from __future__ import annotations

import json
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "robot"))
from ekf_harness import (  # noqa: E402
    DT,
    PandaTorqueHarness,
    Trace,
    descend_reference,
    rmse,
    settling_time,
    sine_reference,
    step_wrench,
)
from qg_common.panda_description import Q_READY, panda_arm  # noqa: E402
from qg_common.params import config_file, load_ros_params  # noqa: E402
from robot_bridge_node.core.arm_model import ArmModel  # noqa: E402
from robot_bridge_node.core.wrench_ekf import WrenchEKF, WrenchEKFConfig  # noqa: E402

W = np.array([5.0, -3.0, -15.0, 0.5, -0.3, 0.2])
TOLERANCE = (0.3, 0.03)          # [N], [Nm]: the accuracy target of the issue
ONSET = 0.3                      # [s]
NOISE = {"exact": (0.0, 0.0), "noisy": (1e-5, 1e-3)}
AMPLITUDE = np.array([0.3, -0.2, 0.3, 0.3, 0.4, 0.3, 0.4])   # [rad]
PERIOD = 4.0                     # [s]


ERROR_KEYS = ("force_rmse", "torque_rmse", "force_max", "torque_max")


def errors(trace: Trace, start: float = 0.0) -> dict[str, float]:
    """Force/torque RMSE and max error norm from ``start`` [s]."""
    err = (trace.estimate - trace.truth)[trace.time >= start]
    return {"force_rmse": rmse(err[:, :3]), "torque_rmse": rmse(err[:, 3:]),
            "force_max": float(np.linalg.norm(err[:, :3], axis=1).max()),
            "torque_max": float(np.linalg.norm(err[:, 3:], axis=1).max())}


def run_all(harness: PandaTorqueHarness, config: WrenchEKFConfig, exact: bool
            ) -> tuple[dict, np.ndarray]:
    """All scenarios on one harness; returns the figures and every update's wall time.

    Settling and recovery times are taken only with exact measurements: the filter gain, hence
    the response, does not depend on the noise realisation, while instantaneous noise would keep
    crossing the tolerance band.
    """
    ekf = WrenchEKF(config, harness.model)
    out: dict[str, dict[str, float]] = {}
    motion = sine_reference(Q_READY, AMPLITUDE, PERIOD)
    costs = []

    harness.reset(Q_READY)
    tr = harness.run(ekf, PERIOD, lambda t: np.zeros(6), motion)
    out["free"] = errors(tr)
    costs.append(tr.update_seconds)

    harness.reset(Q_READY)
    tr = harness.run(ekf, ONSET + 1.5, step_wrench(W, ONSET))
    out["contact"] = errors(tr, ONSET + 0.2)
    if exact:
        out["contact"]["settling_s"] = settling_time(tr, ONSET, TOLERANCE)
    costs.append(tr.update_seconds)

    harness.reset(Q_READY)
    tr = harness.run(ekf, PERIOD, step_wrench(W, 0.0), motion)
    out["contact_motion"] = errors(tr, 0.2)
    costs.append(tr.update_seconds)

    harness.reset(Q_READY)
    pulse = np.array([0.0, 0.0, 60.0, 0.0, 0.0, 0.0])
    tr = harness.run(ekf, ONSET + 0.7, step_wrench(pulse, ONSET, ONSET + 0.005))
    out["impact"] = errors(tr, ONSET)
    if exact:
        out["impact"]["recovery_s"] = settling_time(tr, ONSET + 0.005, TOLERANCE)
    out["impact"]["peak_estimate_fz"] = float(tr.estimate[:, 2].max())
    costs.append(tr.update_seconds)

    harness.reset(Q_READY)
    harness.add_surface(gap=0.02)
    tr = harness.run(ekf, 1.5, lambda t: np.zeros(6),
                     descend_reference(harness.model, Q_READY, 0.025, 0.4))
    touch = float(tr.time[np.flatnonzero(np.linalg.norm(tr.truth, axis=1) > 0.0)[0]])
    out["surface"] = errors(tr, touch + 0.5)
    err = (tr.estimate - tr.truth)[tr.time >= touch + 0.5]
    out["surface"].update(
        touch_s=touch, peak_truth_force=float(np.linalg.norm(tr.truth[:, :3], axis=1).max()),
        peak_estimate_force=float(np.linalg.norm(tr.estimate[:, :3], axis=1).max()),
        force_bias=float(np.linalg.norm(err[:, :3].mean(axis=0))),
        torque_bias=float(np.linalg.norm(err[:, 3:].mean(axis=0))),
        final_force=float(np.linalg.norm(tr.truth[-1, :3])))
    out["surface"]["settling_30ms_avg_s"] = settling_time(tr, touch, TOLERANCE, window=30)
    costs.append(tr.update_seconds)
    harness.remove_surface()
    return out, np.concatenate(costs)


def main() -> None:
    params = load_ros_params(config_file("wrench_estimator.yaml"))
    config = WrenchEKFConfig.from_dict(params["ekf"])
    model = ArmModel.of_arm(panda_arm())
    result: dict[str, object] = {"config": params["ekf"], "dt": DT}
    costs = []
    for name, noise in NOISE.items():
        harness = PandaTorqueHarness(model, measurement_noise=noise, seed=1)
        figures, cost = run_all(harness, config, exact=not any(noise))
        harness.close()
        costs.append(cost)
        result[name] = figures
        print(f"--- {name} measurements (noise std q, dq = {noise})")
        for scenario, f in figures.items():
            extra = "".join(f"  {k} {v * 1e3:.0f} ms" if k.endswith("_s") else f"  {k} {v:.3f}"
                            for k, v in f.items() if k not in ERROR_KEYS)
            print(f"{scenario:15s} force RMSE {f['force_rmse']:.4f} N (max {f['force_max']:.3f})"
                  f"  torque RMSE {f['torque_rmse']:.5f} Nm (max {f['torque_max']:.4f}){extra}")
    cost = np.concatenate(costs) * 1e6
    result["update_us"] = {"median": float(np.median(cost)), "p99": float(np.percentile(cost, 99))}
    print(f"update: median {np.median(cost):.0f} us, p99 {np.percentile(cost, 99):.0f} us "
          f"over {cost.size} updates")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
