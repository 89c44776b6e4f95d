"""QG-DDPG beside SB3's DDPG, TD3 and SAC on standard Gymnasium tasks: where do the graph's
bounds help?

Three tasks: ``Pendulum-v1`` (dense: reward every step, no terminal state, every episode
truncated at 200 steps), ``MountainCarContinuous-v0`` (+100 once, at the goal, which is
terminal; a small action cost otherwise) and ``QGSparseMountainCar-v0`` (the same car with the
thesis's sparse reward, -1 per step and 0 at the goal: ``gym_envs.sparse_mountain_car``). The
Q-Graph bounds a transition only if a terminal or a loop is reachable from it in the data, so on
Pendulum it can bound nothing (QG-DDPG then differs from our DDPG only by the a-priori bounds of
the known reward range), while on the mountain cars every episode that reached the goal bounds
its whole chain, and the left wall, where the car stops at exactly (-1.2, 0), joins the chains
of different episodes.

Same budget and settings for every algorithm: SB3 DDPG's defaults (``SB3_DDPG_SETTINGS``) with
the networks of :data:`HIDDEN` (smaller than SB3's 400-300, so that 5 seeds of 4 algorithms fit
on the 2 shared cores), the task's exploration noise of RL Zoo (Gaussian 0.1 on Pendulum,
Ornstein-Uhlenbeck 0.5 on MountainCar, as ``rl-zoo3``'s hyperparameters set them), the same
steps. One difference, ours: our agents see the observation box scaled to [-1, 1] (their own
default, the thesis's state scaling), SB3's the raw observation. On MountainCar QG-DDPG's actor
saturates the moment the graph bounds the first goal-reaching chain; with the raw observation
(velocity within +-0.07) the critic cannot tell the directions of motion apart and the actor
need never come back, scaled it can (docs/learning.md, section 13, where this is measured and
where it is also shown not to be enough: on MountainCar our agents' actor loss also keeps the
pre-tanh outputs small, ``TASKS[...]["ours"]``). Every ``eval_every`` steps the deterministic policy
plays ``eval_episodes`` episodes on a second environment seeded apart from training (SB3's
``EvalCallback`` protocol).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import gymnasium
import numpy as np
import torch
from qg_learning_node.learner import algorithms
from qg_learning_node.learner.gym_agent import QGDDPG, SB3_DDPG_SETTINGS

from qg_experiments.runner import config_digest
from qg_experiments.sb3_models import sb3_model
from qg_experiments.stats import mean_interval

__all__ = ["TASKS", "HIDDEN", "StandardSpec", "run_standard", "standard_table", "goal_found"]


def _car_goal(episode: dict[str, float]) -> bool:
    """MountainCar pays +100 at the goal and at most 0.1 per step (999 steps: 99.9) otherwise,
    so an episode's return is positive exactly when it reached the goal."""
    return episode["return"] > 0.0


def _sparse_goal(episode: dict[str, float]) -> bool:
    """The sparse car pays -1 per step and 0 on the goal step: a return above minus the steps."""
    return episode["return"] > -episode["steps"]


#: Per task: steps, evaluation period and episodes, exploration noise, the known reward range
#: QG-DDPG takes a priori (Pendulum: -(pi^2 + 0.1 * 8^2 + 0.001 * 2^2) .. 0; MountainCar:
#: -0.1 * 1^2 per step .. +100 at the goal; the sparse car: -1 .. 0), ``reached_goal``: whether
#: a training episode (its steps and return) reached the task's goal (none on Pendulum: there is
#: no goal to find, so exploration cannot miss it), and the algorithms a sweep
#: runs by default (the registry's keys, ``learner/algorithms.py``; any registered one can run);
#: ``ours``: settings of our agents (``AgentSettings``) for that task alone, as RL Zoo sets its
#: noise per task. MountainCar: the actor's pre-tanh penalty 0.1, chosen on the tuning seeds
#: 0-4 (docs/learning.md section 13): without it the first goal the graph bounds saturates
#: QG-DDPG's actor on every state; both our agents take it, so they differ only by the bounds.
TASKS: dict[str, dict[str, Any]] = {
    "Pendulum-v1": {"steps": 10_000, "eval_every": 1_000, "eval_episodes": 5,
                    "noise": ("gaussian", 0.1, 0.0), "reward_range": (-16.2736044, 0.0),
                    "algorithms": ("qgddpg", "ddpg", "sb3_ddpg", "sb3_td3")},
    "MountainCarContinuous-v0": {"steps": 20_000, "eval_every": 2_500, "eval_episodes": 3,
                                 "noise": ("ou", 0.5, 0.15), "reward_range": (-0.1, 100.0),
                                 "algorithms": ("qgddpg", "ddpg", "sb3_ddpg", "sb3_td3"),
                                 "ours": {"actor_preact_penalty": 0.1},
                                 "reached_goal": _car_goal},
    "qg_experiments:QGSparseMountainCar-v0": {
        "steps": 20_000, "eval_every": 2_500, "eval_episodes": 3, "noise": ("ou", 0.5, 0.15),
        "reward_range": (-1.0, 0.0), "reached_goal": _sparse_goal,
        "algorithms": ("qgddpg", "ddpg", "sb3_ddpg", "sb3_td3", "sb3_sac")},
}
#: Hidden layers of every actor and critic here.
HIDDEN = (64, 64)


@dataclass(frozen=True)
class StandardSpec:
    """One run: ``algorithm`` on ``task`` with ``seed`` (``steps``: ``None`` = the task's)."""
    task: str
    algorithm: str
    seed: int
    steps: int | None = None
    config_dir: str | None = None
    experiment: str = "standard_tasks"

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {sorted(TASKS)}, got {self.task!r}")
        algorithms.algorithm(self.algorithm)

    @property
    def name(self) -> str:
        steps = f"_{self.steps}" if self.steps else ""
        task = self.task.split(":")[-1].split("-")[0]
        return f"{task}_{self.algorithm}{steps}_s{self.seed}"

    @property
    def task_settings(self) -> dict[str, Any]:
        """The task's settings of our agents (``TASKS[task]["ours"]``) that this run takes:
        a run is saved with them, and a saved run made without them is not this run."""
        return (dict(TASKS[self.task].get("ours", {}))
                if algorithms.REGISTRY[self.algorithm].ours else {})

    def run(self) -> dict[str, Any]:
        return run_standard(self)


def _evaluate(agent: Any, env: gymnasium.Env, episodes: int, seed: int) -> float:
    """Mean return of ``episodes`` deterministic episodes (seeded: the same starts each time)."""
    returns = []
    for index in range(episodes):
        obs, _ = env.reset(seed=seed + index)
        done, total = False, 0.0
        while not done:
            action, _ = agent.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def _episode_recorder(episodes: list[dict[str, float]]) -> Any:
    """An SB3 callback appending each finished training episode's steps and return (from the
    ``Monitor`` SB3 wraps every environment in)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Recorder(BaseCallback):
        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                if "episode" in info:
                    episodes.append({"steps": int(info["episode"]["l"]),
                                     "return": float(info["episode"]["r"])})
            return True
    return Recorder()


def _sb3(spec: StandardSpec, env: gymnasium.Env) -> Any:
    from stable_baselines3.common.logger import Logger
    model = sb3_model(spec.algorithm, env, spec.seed, TASKS[spec.task]["noise"],
                      policy_kwargs={"net_arch": list(HIDDEN)})
    model.set_logger(Logger(None, []))   # SB3's own would be an empty /tmp/SB3-<time> folder
    return model


def _ours(spec: StandardSpec, env: gymnasium.Env) -> QGDDPG:
    kind, sigma, theta = TASKS[spec.task]["noise"]
    return QGDDPG(env, algorithm=spec.algorithm, seed=spec.seed,
                  **{**SB3_DDPG_SETTINGS, "actor_hidden": HIDDEN, "critic_hidden": HIDDEN,
                     "noise": kind, "noise_sigma": sigma, "noise_theta": theta,
                     "reward_range": TASKS[spec.task]["reward_range"],
                     "normalize_observations": True, **spec.task_settings})


def run_standard(spec: StandardSpec) -> dict[str, Any]:
    """Train with evaluations every ``eval_every`` steps; the curve and the final return."""
    torch.set_num_threads(1)
    start = time.perf_counter()
    task = TASKS[spec.task]
    steps, every = spec.steps or task["steps"], task["eval_every"]
    env, eval_env = gymnasium.make(spec.task), gymnasium.make(spec.task)
    ours = algorithms.REGISTRY[spec.algorithm].ours
    agent = _ours(spec, env) if ours else _sb3(spec, env)
    evaluations: list[dict[str, float]] = []
    episodes: list[dict[str, float]] = []     # training episodes: did exploration find the goal?
    for done in sorted({*range(every, steps, every), steps}):
        chunk = done - (evaluations[-1]["steps"] if evaluations else 0)
        if ours:
            agent.learn(chunk, callback=lambda e: episodes.append(
                {"steps": e["steps"], "return": e["return"]}) or True)
        else:
            agent.learn(chunk, reset_num_timesteps=False, callback=_episode_recorder(episodes))
        evaluations.append({"steps": done, "return": _evaluate(
            agent, eval_env, task["eval_episodes"], 10_000 + 1000 * spec.seed)})
    env.close()
    eval_env.close()
    return {"experiment": spec.experiment, "name": spec.name, "spec": dataclasses.asdict(spec),
            "config_digest": config_digest(spec.config_dir),
            "task_settings": spec.task_settings, "evaluations": evaluations,
            "train_episodes": episodes,
            "final_return": evaluations[-1]["return"], "wall_time": time.perf_counter() - start}


def _steps_to_reach(result: dict[str, Any], target: float) -> float:
    """The first evaluation's step count at which the return reached ``target`` (inf: never)."""
    return next((e["steps"] for e in result["evaluations"] if e["return"] >= target), np.inf)


def goal_found(result: dict[str, Any]) -> tuple[int, int] | None:
    """How many of a run's training episodes reached the task's goal, of how many (``None``: the
    task has no goal). Under a sparse reward a seed whose exploration never finds the goal has
    nothing but -1 to learn from, and the graph has no chain to bound: this tells that failure
    apart from one of learning."""
    reached = TASKS[result["spec"]["task"]].get("reached_goal")
    if reached is None:
        return None
    episodes = result.get("train_episodes", [])
    return sum(map(reached, episodes)), len(episodes)


def standard_table(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per task and algorithm: final return over seeds with its interval, the steps each seed
    needed to reach SB3 TD3's mean final return on that task (inf: never), and per seed the
    training episodes that reached the goal (:func:`goal_found`)."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault((r["spec"]["task"], r["spec"]["algorithm"]), []).append(r)
    rows = []
    for (task, algorithm), group in sorted(groups.items()):
        td3 = groups.get((task, "sb3_td3"), [])
        target = float(np.mean([r["final_return"] for r in td3])) if td3 else None
        rows.append({"task": task, "algorithm": algorithm,
                     "seeds": sorted(r["spec"]["seed"] for r in group),
                     "final_return": mean_interval([r["final_return"] for r in group]).as_dict(),
                     "td3_final_return": target,
                     "steps_to_td3": None if target is None else
                     {r["spec"]["seed"]: _steps_to_reach(r, target) for r in group},
                     "goal_found": {r["spec"]["seed"]: goal_found(r) for r in group},
                     "wall_time": float(sum(r["wall_time"] for r in group))})
    return rows
