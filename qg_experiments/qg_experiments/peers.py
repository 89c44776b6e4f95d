"""Stable-Baselines3's SAC, TD3 and DDPG on ``QGInsertion-v0`` under the grid's budget and test.

Why: "how does QG-DDPG compare with SAC and TD3 on this task?" needs the maintained
implementations on exactly our task, and SB3's DDPG at the settings our DDPG can also take is the
check of our implementation (:data:`SB3_DDPG_SETTINGS`, run through :class:`QGDDPG`).

The protocol is the grid's (``config/experiments.yaml``, profile ``thesis``): training for 40
episodes of at most 50 steps on the realistic arm of the run's seed (the poses rotate 0..7),
then the 8 poses once each, deterministically, at most 200 steps (a failure counts 200). A run is
a frozen :class:`PeerSpec`; ``tasks.run_specs`` saves each as ``<out>/peers/<name>.json`` in the
runner's result layout (``episodes``, ``rl_steps``, ``sim_time``, ``wall_time``), so the peers'
and our runs are counted by the same code (:func:`peer_table`, ``stats``).

Settings: ``defaults`` are each algorithm's constructor defaults, plus Gaussian action noise 0.1
for TD3 and DDPG (SB3 adds none by default; RL Zoo sets this one). ``grid`` is a grid cell: the
learning rate (SB3 has one for actor and critic; our grid's actor learns at a tenth of it) and
``iterations`` gradient steps after every 20 robot steps, the rest at the defaults.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from qg_learning_node.learner.algorithms import COMPARED, REGISTRY, keys
from qg_learning_node.learner.gym_agent import QGDDPG, SB3_DDPG_SETTINGS

from qg_experiments.gym_envs.insertion import TRAIN_MAX_STEPS, InsertionEnv
from qg_experiments.runner import config_digest
from qg_experiments.sb3_models import sb3_model
from qg_experiments.stats import Interval, mean_interval

__all__ = ["PEER_ALGORITHMS", "SETTINGS", "REPORT_SEEDS", "PeerSpec", "EpisodeLog", "run_peer",
           "peer_specs", "peer_table"]

#: The report's seeds: no tuning used them (tuning used 0-4).
REPORT_SEEDS = (100, 101, 102, 103, 104)
#: SB3's algorithms, and our DDPG and QG-DDPG through the Gymnasium API at SB3 DDPG's settings
#: (the registry's keys, ``learner/algorithms.py``).
PEER_ALGORITHMS = (*keys("sb3"), *COMPARED)
SETTINGS = ("defaults", "grid")
#: [steps] the grid's training cycle: a grid cell trains after every this many robot steps.
CYCLE_STEPS = 20
#: Gaussian exploration noise of TD3 and DDPG (RL Zoo's; SB3's own default is none).
NOISE_SIGMA = 0.1


@dataclass(frozen=True)
class PeerSpec:
    """One peer run: an algorithm at a setting with one seed (the arm's seed too).

    :param critic_lr: ``grid`` only: the learning rate of the cell.
    :param iterations: ``grid`` only: gradient steps after every 20 robot steps.
    :param tensorboard_dir: where the run's scalars go (``<dir>/<name>/``); ``None``: nowhere.
    """
    algorithm: str
    setting: str
    seed: int
    critic_lr: float | None = None
    iterations: int | None = None
    train_episodes: int = 40
    train_max_steps: int = TRAIN_MAX_STEPS
    test_episodes: int = 8
    test_max_steps: int = 200
    reward: str = "dense"
    observation: str | None = None
    arm: str = "realistic"
    config_dir: str | None = None
    tensorboard_dir: str | None = None
    experiment: str = "peers"

    def __post_init__(self) -> None:
        if self.algorithm not in PEER_ALGORITHMS:
            raise ValueError(f"algorithm must be one of {PEER_ALGORITHMS}, got {self.algorithm!r}")
        if self.setting not in SETTINGS:
            raise ValueError(f"setting must be one of {SETTINGS}, got {self.setting!r}")
        if (self.setting == "grid") != (self.critic_lr is not None and self.iterations is not None):
            raise ValueError("critic_lr and iterations are given for the grid setting only")
        if self.setting == "grid" and REGISTRY[self.algorithm].ours:
            raise ValueError("our algorithms' grid cells are the runner's (RunSpec)")

    @property
    def name(self) -> str:
        cell = (f"_lr{self.critic_lr:g}_it{self.iterations}" if self.setting == "grid"
                else "_defaults")
        extra = f"_{self.reward}" if self.reward != "dense" else ""
        extra += f"_{self.observation}" if self.observation else ""
        extra += "_ideal" if self.arm == "ideal" else ""
        return f"{self.algorithm}{cell}{extra}_s{self.seed}"

    def run(self) -> dict[str, Any]:
        return run_peer(self)


class EpisodeLog(gymnasium.Wrapper):
    """Keeps every finished episode in the runner's result layout (``mode`` is set by the
    caller: ``train`` while the agent learns, ``test`` in the test phase)."""

    def __init__(self, env: InsertionEnv) -> None:
        super().__init__(env)
        self.mode = "train"
        self.episodes: list[dict[str, Any]] = []

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        result = self.env.step(action)
        if result[2] or result[3]:
            episode = self.env.unwrapped.episode
            self.episodes.append({"episode": f"{self.mode}{len(self.episodes):03d}",
                                  "mode": self.mode, "pose": episode.initial_pose,
                                  "steps": episode.step, "success": episode.success,
                                  "end_reason": episode.end_reason,
                                  "return": episode.episode_return})
        return result


def _sb3_model(spec: PeerSpec, env: gymnasium.Env) -> Any:
    """The SB3 algorithm of ``spec`` at its setting (see the module docstring)."""
    kwargs: dict[str, Any] = {}
    if spec.setting == "grid":
        kwargs.update(learning_rate=spec.critic_lr, train_freq=(CYCLE_STEPS, "step"),
                      gradient_steps=spec.iterations)
    return sb3_model(spec.algorithm, env, spec.seed, ("gaussian", NOISE_SIGMA, 0.0), **kwargs)


def _ours(spec: PeerSpec, env: gymnasium.Env) -> QGDDPG:
    """Our DDPG or QG-DDPG through the Gymnasium API, at SB3 DDPG's defaults (+ noise 0.1)."""
    return QGDDPG(env, algorithm=spec.algorithm, seed=spec.seed,
                  **{**SB3_DDPG_SETTINGS, "noise_sigma": NOISE_SIGMA})


def run_peer(spec: PeerSpec) -> dict[str, Any]:
    """Train ``spec``'s agent for its episodes, then test it on the poses; the run's record."""
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes
    from stable_baselines3.common.logger import Logger, configure
    torch.set_num_threads(1)
    start = time.perf_counter()
    env = EpisodeLog(InsertionEnv(spec.observation, spec.reward, spec.train_max_steps, spec.arm,
                                  config_dir=spec.config_dir))
    budget = spec.train_episodes * spec.train_max_steps
    folder = None if spec.tensorboard_dir is None else Path(spec.tensorboard_dir) / spec.name
    ours = REGISTRY[spec.algorithm].ours
    if ours:
        agent: Any = _ours(spec, env)
        agent.learn(budget, max_episodes=spec.train_episodes, tensorboard_log=folder)
    else:
        agent = _sb3_model(spec, env)
        # Without a logger of its own, SB3 makes an empty /tmp/SB3-<time> folder every run.
        agent.set_logger(Logger(None, []) if folder is None
                         else configure(str(folder), ["tensorboard", "csv"]))
        agent.learn(budget, callback=StopTrainingOnMaxEpisodes(spec.train_episodes))
    train_steps = sum(e["steps"] for e in env.episodes)
    env.mode = "test"
    for index in range(spec.test_episodes):
        state, _ = env.reset(options={"pose": index % 8, "max_steps": spec.test_max_steps})
        done = False
        while not done:
            action, _ = agent.predict(state, deterministic=True)
            state, _, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
    tests = [e for e in env.episodes if e["mode"] == "test"]
    lengths, successes = [e["steps"] for e in tests], [e["success"] for e in tests]
    if ours and agent.log is not None:
        agent.log.evaluation(lengths, successes, train_steps)
        agent.close()
    elif folder is not None:        # SB3's EvalCallback tags, as our TrainingLog writes them
        agent.logger.record("eval/mean_ep_length", float(np.mean(lengths)))
        agent.logger.record("eval/success_rate", float(np.mean(successes)))
        agent.logger.dump(train_steps)
    robot = env.unwrapped.robot
    result = {"experiment": spec.experiment, "name": spec.name,
              "spec": dataclasses.asdict(spec), "config_digest": config_digest(spec.config_dir),
              "episodes": env.episodes, "train_steps": train_steps,
              "rl_steps": robot.steps, "step_timeouts": robot.step_timeouts,
              "sim_time": robot.sim_time, "wall_time": time.perf_counter() - start}
    env.close()
    return result


def peer_specs(setting: str, seeds: tuple[int, ...], algorithms: tuple[str, ...],
               cells: tuple[tuple[float, int], ...] = (), tensorboard_dir: str | None = None,
               **overrides: Any) -> list[PeerSpec]:
    """The runs of ``setting``, seed by seed (so an interrupted sweep has every algorithm on the
    first seeds rather than one algorithm on all)."""
    grid = cells if setting == "grid" else ((None, None),)
    return [PeerSpec(algorithm, setting, seed, lr, iterations,
                     tensorboard_dir=tensorboard_dir, **overrides)
            for lr, iterations in grid for seed in seeds for algorithm in algorithms]


def _per_seed_mean_steps(result: dict[str, Any]) -> float:
    return float(np.mean([e["steps"] for e in result["episodes"] if e["mode"] == "test"]))


def peer_table(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per algorithm and setting (cell): mean test steps over seeds with its interval,
    test poses solved, and training robot steps (mean per seed, with its interval)."""
    groups: dict[tuple[str, str, Any, Any], list[dict[str, Any]]] = {}
    for r in results:
        s = r["spec"]
        groups.setdefault((s["algorithm"], s["setting"], s.get("critic_lr"),
                           s.get("iterations")), []).append(r)
    rows = []
    for (algorithm, setting, lr, iterations), group in sorted(
            groups.items(), key=lambda kv: tuple(str(k) for k in kv[0])):
        tests = [[e for e in r["episodes"] if e["mode"] == "test"] for r in group]
        steps: Interval = mean_interval([_per_seed_mean_steps(r) for r in group])
        train: Interval = mean_interval([float(r["train_steps"]) for r in group])
        rows.append({"algorithm": algorithm, "setting": setting, "critic_lr": lr,
                     "iterations": iterations, "seeds": sorted(r["spec"]["seed"] for r in group),
                     "mean_test_steps": steps.as_dict(),
                     "solved": sum(e["success"] for t in tests for e in t),
                     "tests": sum(len(t) for t in tests),
                     "all_solved_seeds": sum(all(e["success"] for e in t) for t in tests),
                     "train_steps": train.as_dict(),
                     "per_seed": {r["spec"]["seed"]: {"mean_test_steps": _per_seed_mean_steps(r),
                                                      "train_steps": r["train_steps"]}
                                  for r in group},
                     "wall_time": float(sum(r["wall_time"] for r in group))})
    return rows
