"""Why the deterministic test actor stalls, measured at the stall (docs/learning.md section 17).

The probe's protocol (``stall_probe.py``: the demo's learning in process, 40 training episodes
capped at 50 steps, then the 8 test poses with the deterministic actor, cap 60) on the tuning
seeds, and at every stalled test pose, at its last (s, a):

- the critic's ``Q(s, a)`` beside the value of repeating ``a`` forever, ``r / (1 - gamma)``
  (the world is deterministic at rest: a stall is a self-loop), and Monte-Carlo returns of the
  same state with the training noise switched on (the first from the stall itself, the others
  after replaying the deterministic prefix, which also checks that the prefix repeats);
- how close the replay memory came to the actor's noise-free action there: replay transitions
  whose state lies within ``RADIUS`` of ``s``, the distance of their actions to ``a``, how many
  were self-loops (the state moved by at most ``LOOP_TOL``) and the true depth they began at;
- whether ``a`` is a local maximum of ``Q(s, .)``: the gradient there, a 41 x 41 grid over the
  whole action box and random actions around ``a``;
- what the Q-Graph makes of the stalled step: its lower bound for ``(s, a)`` once the step is
  added as measured (``s'`` a hair from ``s``) and as an exact self-loop (``s' == s``);
- at every failed pose, the tail's size per state component: how much each changed and spread,
  the true depth's change and the action's size (what stall recovery's criterion is set from).

One JSON line a stalled pose, one a seed, the last line the summary over the seeds.

Usage: python benchmarks/stall_cause.py [--seeds 0 1 2 3 4] [--algorithm qgddpg] [--lr 1e-2]
           [--iterations 50] [--mc 2] [--clean-fraction P] [--self-loop-tol T] [--no-probe]
           [--ddpg KEY=VALUE ...]   (any DDPGConfig field, e.g. twin_critics=true target_noise=0.2)
           [--noise KEY=VALUE ...]  (any NoiseConfig field, e.g. clean_episode_fraction=0.25)
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import time
from typing import Any

import numpy as np
import torch
import yaml
from qg_common.types import N_START_POSES
from qg_experiments.runner import (
    InsertionRobot,
    LivePolicy,
    RunSpec,
    StackSettings,
    episode_noise_seed,
)
from qg_learning_node.executor.episode import Episode, TransitionRecord
from qg_learning_node.executor.noise import ActionNoise
from qg_learning_node.executor.residual_task import ACTION_DIM, Observation
from qg_learning_node.learner.learner_core import LearnerCore

TEST_CAP = 60          # [steps] the probe's test cap: a stall shows long before the report's 200
TAIL = 10              # [steps] the end of a stalled episode that is looked at
STALL_MOTION = 1e-3    # a failed test episode whose state moved less than this over its tail
LOOP_TOL = 1e-3        # a transition whose state moved at most this (max norm) is a self-loop
RADIUS = 0.01          # [scaled state] replay states this close to the stalled one (max norm)
CLOSE_ACTION = 0.05    # [actor units] a replay action this close to the actor's counts as its own
ESCAPE_CAP = 50        # [steps] the noisy continuation from a stall


@dataclasses.dataclass
class Trained:
    """A trained run: the robot, learner, actor, settings and the truth of every training step."""
    env: InsertionRobot
    learner: LearnerCore
    policy: LivePolicy
    settings: Any
    spec: RunSpec
    steps: dict[str, np.ndarray]
    train_successes: list[bool]


def drive(env: InsertionRobot, episode: Episode, actor: Any, on_step: Any = None,
          cap_actions: list[np.ndarray] | None = None) -> list[tuple[TransitionRecord, Observation]]:
    """Run ``episode`` on ``env``; (record, observation) of every step, and
    ``on_step(record, observation before, observation after)``. ``cap_actions``: replay these
    actions instead of choosing (the deterministic prefix of a stall)."""
    before = env.reset(episode.initial_pose)
    episode.begin(before)
    out = []
    while not episode.done:
        if cap_actions is not None and len(out) >= len(cap_actions):
            break
        action = (cap_actions[len(out)] if cap_actions is not None
                  else episode.choose_action(actor))
        obs = env.step(action)
        record = episode.observe(action, obs)
        out.append((record, obs))
        if on_step is not None:
            on_step(record, before, obs)
        before = obs
    return out


def train(seed: int, algorithm: str, clean_fraction: float, self_loop_tol: float,
          episodes: int = 40, critic_lr: float = 1e-2, iterations: int = 50,
          ddpg: dict[str, Any] | None = None, noise: dict[str, Any] | None = None,
          task: dict[str, Any] | None = None) -> Trained:
    """The probe's learning (``stall_probe.trained``) for ``algorithm``, with the remedies'
    settings (``ddpg``, ``noise``: DDPGConfig and NoiseConfig fields to override), keeping the true depth before and after
    every training step."""
    spec = RunSpec(algorithm, critic_lr, iterations, seed, train_episodes=episodes,
                   train_max_steps=50)
    settings = StackSettings.load(spec.config_dir, spec.arm, spec.robot).with_arm_seed(seed)
    noise_config = settings.noise
    if clean_fraction >= 0:
        noise_config = dataclasses.replace(noise_config, clean_fraction=clean_fraction)
    noise_config = dataclasses.replace(noise_config, **(noise or {}))
    settings = dataclasses.replace(settings, noise=noise_config, task=dataclasses.replace(
        settings.task, train_max_steps=spec.train_max_steps, test_max_steps=TEST_CAP,
        **(task or {})))
    env = InsertionRobot(settings, spec.estimator)
    config = spec.learner_config(settings.learner)
    if self_loop_tol >= 0:
        config = dataclasses.replace(config, ddpg=dataclasses.replace(
            config.ddpg, self_loop_tol=self_loop_tol))
    if ddpg:
        config = dataclasses.replace(config, ddpg=dataclasses.replace(config.ddpg, **ddpg))
    learner = LearnerCore(config, env.residual.state_dim, ACTION_DIM)
    policy = LivePolicy(learner.agent)
    log: dict[str, list] = {k: [] for k in ("s", "a", "r", "s2", "term", "depth0", "depth1")}

    def learn(record: TransitionRecord, before: Observation, obs: Observation) -> None:
        for key, value in (("s", record.state), ("a", record.action), ("r", record.reward),
                           ("s2", record.next_state), ("term", record.terminal),
                           ("depth0", before.truth.insertion_depth),
                           ("depth1", obs.truth.insertion_depth)):
            log[key].append(value)
        learner.add_transition(record.state, record.action, record.reward, record.next_state,
                               record.terminal)
        while learner.training_due():
            learner.train_cycle()
            policy.update(learner.agent)

    successes = []
    for index in range(spec.train_episodes):
        noise = ActionNoise(settings.noise, ACTION_DIM, episode_noise_seed(seed, index))
        episode = Episode(f"train{index:03d}", "train", index % N_START_POSES, spec.reward,
                          env.residual, noise)
        drive(env, episode, policy, learn)
        successes.append(bool(episode.success))
    steps = {k: np.array(v, dtype=np.float64) for k, v in log.items()}
    return Trained(env, learner, policy, settings, spec, steps, successes)


def discounted(rewards: list[float], gamma: float) -> float:
    """sum_t gamma^t r_t of a reward sequence."""
    return float(sum(r * gamma ** t for t, r in enumerate(rewards)))


def critic_over_actions(run: Trained, s: np.ndarray, a: np.ndarray) -> dict[str, Any]:
    """Is ``a`` a local maximum of Q(s, .)? Gradient, a grid over the box, random neighbours."""
    agent = run.learner.agent
    rng = np.random.default_rng(0)
    st = torch.tensor(s[None], dtype=torch.float32)
    at = torch.tensor(a[None], dtype=torch.float32, requires_grad=True)
    q = agent.q(st, at)     # the value the actor maximises
    (grad,) = torch.autograd.grad(q.sum(), at)
    q_sa = float(q.item())
    axis = np.linspace(-1.0, 1.0, 41)
    grid = np.stack(np.meshgrid(axis, axis, indexing="ij"), -1).reshape(-1, 2)
    near = np.clip(a + rng.normal(0.0, 0.1, (512, 2)), -1.0, 1.0)
    noisy = np.clip(a + rng.normal(0.0, run.settings.noise.sigma, (512, 2)), -1.0, 1.0)
    q_grid = agent.q_values(np.repeat(s[None], len(grid), 0), grid)
    q_near = agent.q_values(np.repeat(s[None], len(near), 0), near)
    q_noisy = agent.q_values(np.repeat(s[None], len(noisy), 0), noisy)
    best = int(np.argmax(q_grid))
    return {"q": q_sa, "grad_norm": float(grad.norm()), "grad": grad[0].numpy().round(4).tolist(),
            "grid_max": float(q_grid[best]), "grid_argmax": grid[best].round(2).tolist(),
            "grid_frac_above": float(np.mean(q_grid > q_sa)),
            "near_frac_above": float(np.mean(q_near > q_sa)),
            "near_max_gain": float(q_near.max() - q_sa),
            "q_noisy_mean": float(q_noisy.mean())}


def replay_near(run: Trained, s: np.ndarray, a: np.ndarray) -> dict[str, Any]:
    """What the training steps near ``s`` were: their actions against ``a``, their outcomes."""
    st = run.steps
    d_state = np.abs(st["s"] - s).max(1)
    d_action = np.linalg.norm(st["a"] - a, axis=1)
    moved = np.abs(st["s2"] - st["s"]).max(1)
    loop = (moved <= LOOP_TOL) & (st["term"] == 0)
    near = d_state <= RADIUS
    both = near & (d_action <= 3 * CLOSE_ACTION)
    joint = np.sqrt(d_state ** 2 + d_action ** 2)

    def share(mask: np.ndarray) -> dict[str, Any]:
        n = int(mask.sum())
        return {"n": n, "self_loops": int((mask & loop).sum()),
                "terminal": int((mask & (st["term"] > 0)).sum()),
                "depth0_mm": ([round(float(np.min(st["depth0"][mask])) * 1e3, 2),
                               round(float(np.max(st["depth0"][mask])) * 1e3, 2)] if n else None)}

    return {"nearest_state": float(d_state.min()),
            "nearest_joint": float(joint.min()),
            "near": share(near), "near_close_action": share(both),
            "near_action_dist_min": float(d_action[near].min()) if near.any() else None,
            "near_action_dist_median": float(np.median(d_action[near])) if near.any() else None,
            "near_own_action": int((near & (d_action <= CLOSE_ACTION)).sum())}


def graph_view(run: Trained, s: np.ndarray, a: np.ndarray, r: float, s2: np.ndarray
               ) -> dict[str, Any] | None:
    """The Q-Graph's bound for the stalled step added as measured and as an exact self-loop."""
    graph = run.learner.graph
    if graph is None:
        return None
    out = {"before": graph.lower_bound(s, a)}
    for name, nxt in (("as_measured", s2), ("exact_loop", s)):
        trial = copy.deepcopy(graph)
        trial.add(s, a, r, nxt, False)
        out[name] = trial.lower_bound(s, a)
        out[f"{name}_is_self_loop"] = bool(trial._state_key(s) == trial._state_key(nxt))
    return out


def probe(run: Trained, pose: int, mc: int) -> dict[str, Any]:
    """A deterministic test episode of ``pose``; at a stall, everything the module names."""
    env, gamma = run.env, run.learner.config.ddpg.gamma
    episode = Episode(f"test{pose}", "test", pose, "dense", env.residual)
    steps = drive(env, episode, run.policy)
    row: dict[str, Any] = {"pose": pose, "steps": episode.step, "success": bool(episode.success),
                           "end": episode.end_reason}
    if episode.success:
        return row
    records = [rec for rec, _ in steps]
    states = np.array([rec.state for rec in records[-TAIL:]])
    actions = np.array([rec.action for rec in records[-TAIL:]])
    last, obs = steps[-1]
    s, a, r, s2 = last.state, last.action, last.reward, last.next_state
    a_next = run.policy(s2)
    truth = obs.truth
    row.update(stalled=bool(np.abs(np.diff(states, axis=0)).max() <= STALL_MOTION),
               state_change=float(np.abs(np.diff(states, axis=0)).max()),
               action_change=float(np.abs(np.diff(actions, axis=0)).max()),
               last_step_motion=float(np.abs(s2 - s).max()),
               bitwise_loop=bool(np.array_equal(s, s2)),
               s=s.round(4).tolist(), a=a.round(4).tolist(),
               pi_next_minus_a=float(np.abs(a_next - a).max()),
               tilt_deg=round(float(np.degrees(truth.tilt)), 2),
               depth_mm=round(truth.insertion_depth * 1e3, 2), r=r,
               loop_value=r / (1.0 - gamma))
    # Per state component over the tail (learning.md section 21): its largest change from step
    # to step, its spread and its largest size (a progress component, the step's motion, reads
    # about 0 at a jam); the true depth's change over the tail and the action's largest size.
    depths = [o.truth.insertion_depth for _, o in steps[-TAIL:]]
    row.update(tail_change_per_dim=np.abs(np.diff(states, axis=0)).max(0).round(4).tolist(),
               tail_spread_per_dim=np.ptp(states, axis=0).round(4).tolist(),
               tail_size_per_dim=np.abs(states).max(0).round(4).tolist(),
               tail_depth_moved_mm=round((depths[-1] - depths[0]) * 1e3, 3),
               tail_action_size=round(float(np.abs(actions).max()), 3))
    row["critic"] = critic_over_actions(run, s, a)
    row["replay"] = replay_near(run, s, a)
    row["graph"] = graph_view(run, s, a, r, s2)
    # Monte-Carlo: from the stall with the training noise on; the first continues this
    # episode, the others run the deterministic actor from the pose again until it stalls
    # (the realistic arm's noise makes a replay of the same actions end elsewhere)
    returns, escape_steps, restall = [], [], []
    for k in range(mc):
        previous = obs          # the observation the continuation's first step begins from
        if k > 0:
            again = Episode(f"again{pose}", "test", pose, "dense", env.residual)
            again.begin(env.reset(pose))
            history = [again.state]
            while not again.done and not (
                    len(history) > TAIL and np.abs(np.diff(history[-5:], axis=0)).max()
                    <= STALL_MOTION):
                action = again.choose_action(run.policy)
                previous = env.step(action)
                again.observe(action, previous)
                history.append(again.state)
            if again.success:
                restall.append(None)
                continue
            s2 = again.state
            restall.append(float(np.abs(s2 - last.next_state).max()))
        noise = ActionNoise(run.settings.noise, ACTION_DIM, 5000 + 100 * pose + k)
        rewards, escaped = [], None
        state = s2
        for t in range(ESCAPE_CAP):
            action = noise.perturb(run.policy(state))
            obs_t = env.step(action)
            rewards.append(float(env.residual.reward(obs_t, "dense")))
            state = env.residual.state(obs_t, previous)   # the step's motion, as the executor
            previous = obs_t
            if env.residual.succeeded(obs_t):
                escaped = t + 1
                break
            if env.residual.left_bore(obs_t):
                break
        returns.append(discounted(rewards, gamma))
        escape_steps.append(escaped)
    row.update(mc_noisy_returns=[round(g, 4) for g in returns],
               mc_escape_steps=escape_steps, restall_state_diff=restall,
               q_stay_then_noisy=[round(r + gamma * g, 4) for g in returns])
    return row


def _median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians and counts over the stalled poses of all seeds."""
    stalled = [r for r in rows if r.get("stalled")]

    def med(get: Any) -> float | None:
        values = [v for v in (get(r) for r in stalled) if v is not None]
        return float(np.median(values)) if values else None

    return {
        "test_episodes": len(rows), "failed": sum(not r["success"] for r in rows),
        "stalled": len(stalled),
        "q_median": med(lambda r: r["critic"]["q"]),
        "loop_value_median": med(lambda r: r["loop_value"]),
        "q_minus_loop_median": med(lambda r: r["critic"]["q"] - r["loop_value"]),
        "mc_noisy_median": med(lambda r: _median(r["mc_noisy_returns"])),
        "q_stay_then_noisy_median": med(lambda r: _median(r["q_stay_then_noisy"])),
        "escapes": f"{sum(e is not None for r in stalled for e in r['mc_escape_steps'])} of "
                   f"{sum(len(r['mc_escape_steps']) for r in stalled)}",
        "grad_norm_median": med(lambda r: r["critic"]["grad_norm"]),
        "grid_frac_above_median": med(lambda r: r["critic"]["grid_frac_above"]),
        "near_frac_above_median": med(lambda r: r["critic"]["near_frac_above"]),
        "replay_near_n_median": med(lambda r: r["replay"]["near"]["n"]),
        "replay_own_action_total": sum(r["replay"]["near_own_action"] for r in stalled),
        "replay_near_action_dist_min_median": med(lambda r: r["replay"]["near_action_dist_min"]),
        "replay_near_self_loops_total": sum(r["replay"]["near"]["self_loops"] for r in stalled),
        "bitwise_loops": sum(r["bitwise_loop"] for r in stalled),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--algorithm", default="qgddpg")
    parser.add_argument("--mc", type=int, default=2, help="Monte-Carlo continuations a stall")
    parser.add_argument("--clean-fraction", type=float, default=-1.0,
                        help="noise.clean_fraction in training (-1: config/executor.yaml's)")
    parser.add_argument("--self-loop-tol", type=float, default=-1.0,
                        help="ddpg.self_loop_tol (-1: config/learner.yaml's)")
    parser.add_argument("--lr", type=float, default=1e-2, help="critic learning rate")
    parser.add_argument("--iterations", type=int, default=50, help="train steps a cycle")
    parser.add_argument("--episodes", type=int, default=40, help="training episodes")
    parser.add_argument("--no-probe", action="store_true",
                        help="count stalls only (the remedies' protocol)")
    parser.add_argument("--ddpg", nargs="*", default=[], metavar="KEY=VALUE",
                        help="DDPGConfig fields to override (values read as YAML)")
    parser.add_argument("--noise", nargs="*", default=[], metavar="KEY=VALUE",
                        help="NoiseConfig fields to override (values read as YAML)")
    parser.add_argument("--task", nargs="*", default=[], metavar="KEY=VALUE",
                        help="TaskConfig fields to override, e.g. observation=tilt_depth")
    args = parser.parse_args()
    ddpg, noise, task = ({key: yaml.safe_load(value) for key, _, value in
                          (item.partition("=") for item in items)}
                         for items in (args.ddpg, args.noise, args.task))
    torch.set_num_threads(1)
    rows, per_seed = [], []
    for seed in args.seeds:
        start = time.perf_counter()
        run = train(seed, args.algorithm, args.clean_fraction, args.self_loop_tol,
                    args.episodes, args.lr, args.iterations, ddpg, noise, task)
        moved = np.abs(run.steps["s2"] - run.steps["s"]).max(1)
        loops = (moved <= LOOP_TOL) & (run.steps["term"] == 0)
        seed_rows = []
        for pose in range(N_START_POSES):
            row = probe(run, pose, 0 if args.no_probe else args.mc)
            row["seed"] = seed
            seed_rows.append(row)
            if not row["success"]:
                print(json.dumps(row), flush=True)
        rows += seed_rows
        per_seed.append({
            "seed": seed, "algorithm": args.algorithm, "train_inserted": sum(run.train_successes),
            "trained": bool(sum(run.train_successes[-8:]) >= 6),
            "test_inserted": sum(r["success"] for r in seed_rows),
            "stalled": sum(bool(r.get("stalled")) for r in seed_rows),
            "train_steps": int(len(moved)), "train_self_loops": int(loops.sum()),
            "train_self_loops_deeper_0.5mm": int(np.sum(
                loops & (run.steps["depth1"] - run.steps["depth0"] > 5e-4))),
            "train_bitwise_loops": int(np.sum(np.all(run.steps["s2"] == run.steps["s"], 1))),
            "wall_s": round(time.perf_counter() - start, 1)})
        print(json.dumps(per_seed[-1]), flush=True)
    print(json.dumps({"algorithm": args.algorithm, "lr": args.lr, "iterations": args.iterations,
                      "clean_fraction": args.clean_fraction,
                      "self_loop_tol": args.self_loop_tol, "ddpg": ddpg, "noise": noise, "task": task,
                      "seeds": per_seed,
                      **summary(rows)}))


if __name__ == "__main__":
    main()
