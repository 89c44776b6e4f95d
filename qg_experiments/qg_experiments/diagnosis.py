"""What the learner can see: the thesis's 4-D wrench state against the tilt state, in numbers.

``python -m qg_experiments.diagnosis`` runs the in-process Panda task, on the realistic arm and on
the ideal one, and writes ``docs/data/diagnosis.json`` and two figures (the realistic arm's) for
``docs/learning.md``:

1. the scaled state after the settled reset and after one zero-residual step, per start pose: the
   wrench part is the same for all 8 tilt directions (statics: at rest the contact wrench balances
   the commanded one), the tilt part points the way back;
2. along uniform-random episodes, how much of the true tilt (the simulator's orientation error)
   a linear map from each state explains (R^2), and how closely the estimated torque echoes the
   action just taken;
3. two hand-written policies as floors: one that reads only the measured torque, one that tilts
   back by the measured tilt.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
from qg_learning_node.executor.episode import Episode
from qg_learning_node.executor.residual_task import ACTION_DIM

from qg_experiments.figures import pyplot
from qg_experiments.runner import ARMS, InsertionRobot, StackSettings, run_episode

__all__ = ["pose_states", "random_walk", "scripted_policy_steps", "diagnose", "main"]


def _task(settings: StackSettings, cap: int) -> InsertionRobot:
    task = dataclasses.replace(settings.task, observation="tilt", train_max_steps=cap,
                               test_max_steps=cap)
    return InsertionRobot(dataclasses.replace(settings, task=task))


def pose_states(env: InsertionRobot) -> list[dict[str, Any]]:
    """Per start pose: the 6-D state (thesis part first) after reset and after a zero step."""
    rows = []
    for pose in range(8):
        reset = env.residual.state(env.reset(pose))
        zero = env.residual.state(env.step(np.zeros(ACTION_DIM)))
        rows.append({"pose": pose, "reset": reset.tolist(), "after_zero_step": zero.tolist()})
    return rows


def _r_squared(x: np.ndarray, y: np.ndarray) -> float:
    """Share of the variance of ``y`` (n, k) that a least-squares affine map of ``x`` explains."""
    design = np.hstack([x, np.ones((len(x), 1))])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = y - design @ coef
    return float(1.0 - residual.var(axis=0).sum() / y.var(axis=0).sum())


def random_walk(env: InsertionRobot, episodes: int, steps: int, seed: int) -> dict[str, Any]:
    """Uniform-random residual steps: states, actions and the true tilt at every rest."""
    rng = np.random.default_rng(seed)
    states, actions, truth, trace = [], [], [], []
    for index in range(episodes):
        env.reset(index % 8)
        for step in range(steps):
            action = rng.uniform(-1.0, 1.0, ACTION_DIM)
            obs = env.step(action)
            state = env.residual.state(obs)
            error = env.loop.ground_truth().orientation_error
            states.append(state)
            actions.append(action)
            truth.append(error)
            if index == 0:
                trace.append({"step": step, "state": state.tolist(), "action": action.tolist(),
                              "orientation_error": error.tolist()})
            if obs.success or env.residual.left_bore(obs):
                break
    s, a, t = np.array(states), np.array(actions), np.array(truth)
    torque_echo = float(np.corrcoef(s[:, 2:4].ravel(), a.ravel())[0, 1])
    return {"transitions": len(s), "r2_tilt_from_thesis_state": _r_squared(s[:, :4], t),
            "r2_tilt_from_tilt_state": _r_squared(s, t),
            "corr_torque_state_vs_last_action": torque_echo, "trace": trace}


def scripted_policy_steps(env: InsertionRobot, policy: str, cap: int) -> list[int]:
    """Steps to insert from each start pose (``cap`` if not inserted) of a hand-written policy.

    ``torque``: push against the measured contact torque, ``a = -10 T / 3 Nm`` (thesis state only).
    ``tilt``: rotate back by the measured tilt, ``a = -3 * tilt state`` (= -6 rad^-1 * tilt).
    """
    def actor(state: np.ndarray) -> np.ndarray:
        part = state[2:4] * -10.0 if policy == "torque" else state[4:6] * -3.0
        return np.clip(part, -1.0, 1.0)

    steps = []
    for pose in range(8):
        episode = Episode(f"{policy}{pose}", "test", pose, "dense", env.residual)
        steps.append(run_episode(env, episode, actor)["steps"])
    return steps


def _figures(poses: list[dict[str, Any]], walk: dict[str, Any], out: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    colours = plt.cm.hsv(np.linspace(0, 1, 9)[:8])
    for row, colour in zip(poses, colours):
        zero = np.array(row["after_zero_step"])
        axes[0].plot(zero[2], zero[3], "o", color=colour, label=f"pose {row['pose']}")
        axes[1].plot(zero[4], zero[5], "o", color=colour)
    axes[0].set_title("thesis state: (Tx, Ty) after a zero step")
    axes[1].set_title("tilt state: (ex, ey) after a zero step")
    for ax in axes:
        ax.set_xlim(-1.05, 1.05)
        ax.set_ylim(-1.05, 1.05)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(out / "learning_state_per_pose.png", dpi=110)
    plt.close(fig)

    trace = walk["trace"]
    steps = [t["step"] for t in trace]
    state, action = np.array([t["state"] for t in trace]), np.array([t["action"] for t in trace])
    truth = np.array([t["orientation_error"] for t in trace])
    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    axes[0].plot(steps, state[:, 2], label="Tx state (thesis)")
    axes[0].plot(steps, action[:, 0], "--", label="action tx just taken")
    axes[0].set_title("the wrench state echoes the last action ...")
    axes[1].plot(steps, state[:, 4] * 0.5, label="ex state x 0.5 rad (tilt)")
    axes[1].plot(steps, truth[:, 0], "--", label="true orientation error x [rad]")
    axes[1].set_title("... the tilt state follows the true tilt")
    axes[1].set_xlabel("RL step (uniform random residual, pose 0)")
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "learning_state_per_step.png", dpi=110)
    plt.close(fig)


def diagnose(arm: str, episodes: int, steps: int, cap: int) -> dict[str, Any]:
    """Sections 1-3 of the module docstring on one simulated arm (``runner.ARMS``)."""
    env = _task(StackSettings.load(arm=arm), cap)
    poses = pose_states(env)
    walk = random_walk(env, episodes, steps, seed=0)
    return {"arm": arm, "poses": poses, "random_walk": walk,
            "scripted": {name: scripted_policy_steps(env, name, cap)
                         for name in ("torque", "tilt")},
            "step_timeouts": env.step_timeouts, "rl_steps": env.steps}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m qg_experiments.diagnosis",
                                     description=__doc__)
    parser.add_argument("--docs", type=Path, default=Path("docs"))
    parser.add_argument("--episodes", type=int, default=8, help="random episodes for the R^2")
    parser.add_argument("--steps", type=int, default=30, help="steps per random episode")
    parser.add_argument("--cap", type=int, default=40, help="step cap of the scripted policies")
    args = parser.parse_args(argv)
    # The realistic arm (the default, drawn in the figures) and the ideal one beside it.
    result = {arm: diagnose(arm, args.episodes, args.steps, args.cap) for arm in ARMS}
    (args.docs / "data").mkdir(parents=True, exist_ok=True)
    (args.docs / "figures").mkdir(parents=True, exist_ok=True)
    (args.docs / "data" / "diagnosis.json").write_text(json.dumps(result, indent=1))
    realistic = result["realistic"]
    _figures(realistic["poses"], realistic["random_walk"], args.docs / "figures")
    summary = {arm: {**{k: v for k, v in r["random_walk"].items() if k != "trace"},
                     "scripted": r["scripted"]} for arm, r in result.items()}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
