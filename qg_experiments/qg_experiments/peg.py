"""Experiments 5 and 6: the clearance-fit peg (SPEC 4), DDPG vs QG-DDPG over learning rates.

Experiment 5 moves a free peg; experiment 6 runs the same task on the simulated Nextage through
the stack's cores (``nextage_peg.NextagePeg``: the robot plugin, the bridge's position loop and
the executor's ``PegTask``), with the same starts, budget and learners.

Thesis ch. 8.3.2 settings: actor and critic of 3 hidden layers x 200 (ch. 8.3.2.1: the actor's
weights He-uniform, the critic's from N(0, 0.001)), no target networks, a block
of minibatch updates after every episode (thesis: 50 epochs of up to 15 minibatches; here
``train_iterations`` updates of ``learner.yaml``'s batch size), the same learning rate for actor
and critic. Exploration is ``executor.yaml``'s noise on every step (no clean steps: the
thesis's). At the end each network's Q is evaluated on a regular grid of 27 states with 11 fixed
actions and with the actor's action; the spread of those predictions across seeds measures soft
divergence (thesis Fig. 8.3).

Beside the learners, random policies (``PegRandomSpec``) run the same seeds' episodes from the
same starts without learning: the bar a learner has to clear (the thesis has none for the peg).
"""
from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from qg_common.params import config_file, load_ros_params
from qg_learning_node.executor.noise import ActionNoise, NoiseConfig
from qg_learning_node.executor.parameters import load_noise
from qg_learning_node.learner.learner_config import LearnerConfig
from qg_learning_node.learner.learner_core import LearnerCore
from qg_learning_node.learner.learner_params import learner_config_from_params

from qg_experiments.environments import make_environment
from qg_experiments.nextage_peg import NextagePeg
from qg_experiments.profile import PegBudget
from qg_experiments.run_progress import RunProgress
from qg_experiments.runner import ALGORITHMS, algorithm_config, config_digest, episode_noise_seed

__all__ = ["PEG_NETWORKS", "PEG_NOISE", "PegRunSpec", "peg_specs", "peg_learner_config",
           "peg_noise_config", "run_peg", "GRID_STATES", "GRID_ACTIONS", "learning_curves",
           "q_spread", "q_seeds", "holds_final_q", "Q_POINTS", "PEG_ROBOTS", "PEG_RANDOM_KINDS",
           "PegRandomSpec", "peg_random_specs", "run_peg_random", "random_experiment",
           "random_curves"]

#: The robots that move the peg, and the experiment each one's runs are saved under.
PEG_ROBOTS = {"free": "peg", "sim_nextage": "nextage"}
#: The peg's random policies, the bar both learners have to clear, and what each one sends:
#: ``noise`` is a learner that learns nothing.
PEG_RANDOM_KINDS = {"noise": "the learners' exploration noise on the zero action",
                    "uniform": "actions uniform over the action box"}


def random_experiment(experiment: str) -> str:
    """Where the random policies of a peg experiment (``peg``, ``nextage``) are saved."""
    return f"{experiment}_random"

#: 27 states: the centres of a 3 x 3 x 3 partition of the scaled workspace [-1, 1]^3.
GRID_STATES = np.array(list(itertools.product((-2 / 3, 0.0, 2 / 3), repeat=3)))
#: 11 actions: the zero action, the six unit moves along the axes, four diagonal moves down.
GRID_ACTIONS = np.array([[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1],
                         [0, 0, -1], [.5, .5, -.5], [.5, -.5, -.5], [-.5, .5, -.5],
                         [-.5, -.5, -.5]], dtype=float)


#: The thesis's peg networks (ch. 8.3.2.1): 3 x 200 both, the actor's weights He-uniform, the
#: critic's from N(0, 0.001), no target networks.
PEG_NETWORKS: dict[str, Any] = {"actor_hidden": (200, 200, 200), "critic_hidden": (200, 200, 200),
                                "actor_init": "he_uniform", "critic_init": "normal_1e-3",
                                "target_networks": False}
#: The thesis explores on every step: none of the Panda's clean steps or episodes.
PEG_NOISE: dict[str, float] = {"clean_fraction": 0.0, "clean_episode_fraction": 0.0}


@dataclass(frozen=True)
class PegRunSpec:
    """One peg learning run.

    :param lr: learning rate of actor and critic.
    :param train_iterations: minibatch updates after each episode.
    :param robot: ``free`` (the free peg) or ``sim_nextage`` (the arm through the stack's cores).
    :param gamma: discount, not ``learner.yaml``'s, which is the Panda's; its one home is
        ``PegBudget.gamma`` (a profile may set it), this default is that one.
    """
    algorithm: str
    lr: float
    seed: int
    episodes: int = 100
    train_iterations: int = 750
    episode_steps: int = 200
    config_dir: str | None = None
    robot: str = "free"
    gamma: float = PegBudget.gamma

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {self.algorithm!r}")
        if self.robot not in PEG_ROBOTS:
            raise ValueError(f"robot must be one of {sorted(PEG_ROBOTS)}, got {self.robot!r}")
        if not self.lr > 0 or self.episodes < 1 or self.train_iterations < 1 \
                or self.episode_steps < 1:
            raise ValueError("lr must be > 0; episodes, train_iterations, episode_steps >= 1")

    @property
    def experiment(self) -> str:
        return PEG_ROBOTS[self.robot]

    @property
    def task_settings(self) -> dict[str, Any]:
        """What the run takes beside its fields and ``config_digest``'s files: the networks and
        the exploration above. Saved with the run; a saved run made with others (before they
        were the thesis's) is not this run (``tasks``)."""
        return {"networks": PEG_NETWORKS, "noise": PEG_NOISE}

    @property
    def name(self) -> str:
        return f"{self.algorithm}_lr{self.lr:g}_s{self.seed}"

    def run(self) -> dict[str, Any]:
        return run_peg(self)

    def run_resuming(self, progress: Path) -> dict[str, Any]:
        """The run, saving its progress in ``progress`` and continuing from what is there."""
        return run_peg(self, progress)


def peg_specs(budget: PegBudget, config_dir: str | None = None,
              robot: str = "free") -> list[PegRunSpec]:
    """The budget's runs, learning rate by learning rate and seed by seed, both algorithms of
    a seed side by side: a budget that runs for hours and is stopped part way has complete
    pairs of the first learning rates, not one algorithm's runs of all of them."""
    return [PegRunSpec(algorithm=a, lr=float(lr), seed=s, episodes=budget.episodes,
                       train_iterations=budget.train_iterations,
                       episode_steps=budget.episode_steps, config_dir=config_dir, robot=robot,
                       gamma=budget.gamma)
            for lr in budget.lrs for s in budget.seeds for a in budget.algorithms]


def peg_learner_config(spec: PegRunSpec, action_dim: int) -> LearnerConfig:
    """``learner.yaml``'s learner with the algorithm of ``spec`` and the thesis's peg networks
    (ch. 8.3.2.1): 3 x 200 both, the actor's weights He-uniform, the critic's from N(0, 0.001),
    no target networks, one learning rate for both, ``spec.train_iterations`` updates after
    every episode."""
    params = load_ros_params(config_file("learner.yaml", spec.config_dir))
    base = learner_config_from_params(params["learner"], "learner.yaml")
    config = algorithm_config(base, spec.algorithm, action_dim)
    return dataclasses.replace(
        config, seed=spec.seed, iterations_per_cycle=spec.train_iterations,
        cycle_steps=spec.episode_steps,
        ddpg=dataclasses.replace(config.ddpg, **PEG_NETWORKS, critic_lr=spec.lr,
                                 actor_lr=spec.lr, seed=spec.seed, gamma=spec.gamma))


def peg_noise_config(config_dir: str | None = None) -> NoiseConfig:
    """``executor.yaml``'s exploration noise with noise on every training step, as the thesis
    explores: its clean steps and episodes are the Panda's remedy for stalls of the test actor
    (docs/learning.md section 17), which the peg's experiments do not test."""
    noise = load_noise(load_ros_params(config_file("executor.yaml", config_dir)),
                       "executor.yaml")
    return dataclasses.replace(noise, **PEG_NOISE)


def run_peg(spec: PegRunSpec, progress: Path | None = None) -> dict[str, Any]:
    """Train for ``spec.episodes`` episodes; per-episode records and the final Q on the grid.

    :param progress: a file to save the run's progress in between episodes and to continue
        from (``run_progress``); the result is the same to the bit, plus ``resumed``: where
        and on which code the run continued. Its ``wall_time`` and ``cpu_time`` add up its
        sessions (``cpu_time`` None: continued from progress saved without it).
    """
    torch.set_num_threads(1)
    start, cpu_start = time.perf_counter(), time.process_time()
    env = _peg_env(spec.robot, spec.config_dir, spec.episode_steps)
    keeper = None if progress is None else RunProgress(progress, spec)
    saved = None if keeper is None else keeper.load()
    if saved is None:
        learner = LearnerCore(peg_learner_config(spec, env.action_dim), env.state_dim,
                              env.action_dim)
        records: list[dict[str, Any]] = []
        resumed: list[dict[str, Any]] = []
        earlier, earlier_cpu = 0.0, 0.0
    else:
        learner = LearnerCore.from_state_dict(saved["learner"])
        records, earlier = saved["episodes"], saved["wall_time"]
        earlier_cpu = saved.get("cpu_time")
        resumed = [*saved["resumed"], {"episode": len(records), "code": saved["code"]}]

    def cpu_time() -> float | None:
        return None if earlier_cpu is None else earlier_cpu + time.process_time() - cpu_start

    def keep(record: dict[str, Any]) -> None:
        records.append(record)
        if keeper is not None and len(records) < spec.episodes:
            keeper.save({"learner": learner.state_dict(), "episodes": records,
                         "resumed": resumed, "cpu_time": cpu_time()}, len(records),
                        spec.episodes, earlier + time.perf_counter() - start)

    try:
        _episodes(env, spec.seed, range(len(records), spec.episodes),
                  peg_noise_config(spec.config_dir), learner.agent.act, learner, keep)
    finally:
        env.close()
    agent = learner.agent
    states = np.repeat(GRID_STATES, len(GRID_ACTIONS), axis=0)
    actions = np.tile(GRID_ACTIONS, (len(GRID_STATES), 1))
    result = {"experiment": spec.experiment, "name": spec.name, "spec": dataclasses.asdict(spec),
              "config_digest": config_digest(spec.config_dir),
              "task_settings": spec.task_settings, "episodes": records,
              "q_given": agent.q_values(states, actions).reshape(len(GRID_STATES), -1).tolist(),
              "q_pi": agent.q_values(GRID_STATES, agent.act(GRID_STATES)).tolist(),
              "rl_steps": int(sum(e["steps"] for e in records)),
              **({"sim_time": env.sim_time, "step_timeouts": env.step_timeouts,
                  "engine": "pybullet", "step_limit": env.loop.rest.config.max_time}
                 if isinstance(env, NextagePeg) else {}),
              **({"resumed": resumed} if resumed else {}),
              "wall_time": earlier + time.perf_counter() - start, "cpu_time": cpu_time()}
    if keeper is not None:
        keeper.remove()
    return result


def _peg_env(robot: str, config_dir: str | None, episode_steps: int) -> Any:
    """The environment that moves the peg: the free peg, or the Nextage through the cores."""
    if robot == "free":
        return make_environment("peg", load_ros_params(config_file("peg_env.yaml", config_dir)),
                                episode_steps=episode_steps)
    return NextagePeg(config_dir, episode_steps)


def _episodes(env: Any, seed: int, indices: range, noise_config: NoiseConfig,
              act: Callable[[np.ndarray], np.ndarray], learner: LearnerCore | None = None,
              keep: Callable[[dict[str, Any]], None] | None = None) -> list[dict[str, Any]]:
    """Run the episodes ``indices`` of ``act`` perturbed by ``noise_config``; episode ``k``
    starts where and explores as every run of ``seed`` does (``episode_noise_seed``), so runs of
    one seed, learning or random, meet the same starts, and a run continued at episode ``k``
    runs the episodes it would have. With a ``learner`` it stores each step and trains after
    each episode (``mean_q`` in the record); ``keep`` takes each record as its episode ends."""
    records = []
    for index in indices:
        noise = ActionNoise(noise_config, env.action_dim, episode_noise_seed(seed, index))
        state = env.reset(seed=episode_noise_seed(seed, index))
        total, success = 0.0, False
        while not env.truncated:
            action = noise.perturb(act(state))
            next_state, reward, terminal = env.step(action)
            if learner is not None:
                learner.add_transition(state, action, reward, next_state, terminal)
            total += reward
            state = next_state
            if terminal:
                success = True
                break
        record = {"episode": index, "steps": env.steps, "success": success, "return": total}
        if learner is not None:
            record["mean_q"] = float(learner.train_cycle()["mean_q"])
        records.append(record)
        if keep is not None:
            keep(record)
    return records


@dataclass(frozen=True)
class PegRandomSpec:
    """One seed of a random policy on the peg (``PEG_RANDOM_KINDS``): the episodes of a learning
    run of that seed, from the same starts, without learning.

    :param kind: ``noise`` (the learners' exploration on the zero action) or ``uniform``.
    """
    kind: str
    seed: int
    episodes: int = 100
    episode_steps: int = 200
    config_dir: str | None = None
    robot: str = "free"

    def __post_init__(self) -> None:
        if self.kind not in PEG_RANDOM_KINDS:
            raise ValueError(f"kind must be one of {tuple(PEG_RANDOM_KINDS)}, got {self.kind!r}")
        if self.robot not in PEG_ROBOTS:
            raise ValueError(f"robot must be one of {sorted(PEG_ROBOTS)}, got {self.robot!r}")
        if self.episodes < 1 or self.episode_steps < 1:
            raise ValueError("episodes and episode_steps must be >= 1")

    @property
    def experiment(self) -> str:
        return random_experiment(PEG_ROBOTS[self.robot])

    @property
    def task_settings(self) -> dict[str, Any]:
        """The exploration the ``noise`` kind takes (``PEG_NOISE``), saved with the run."""
        return {"noise": PEG_NOISE}

    @property
    def label(self) -> str:
        return {"noise": "random (exploration noise)", "uniform": "random (uniform)"}[self.kind]

    @property
    def name(self) -> str:
        return f"random_{self.kind}_s{self.seed}"

    def run(self) -> dict[str, Any]:
        return run_peg_random(self)


def peg_random_specs(budget: PegBudget, config_dir: str | None = None,
                     robot: str = "free") -> list[PegRandomSpec]:
    """The random policies of the budget (``PegBudget.random``), on its seeds and episodes."""
    return [PegRandomSpec(kind=k, seed=s, episodes=budget.episodes,
                          episode_steps=budget.episode_steps, config_dir=config_dir, robot=robot)
            for k in budget.random for s in budget.seeds]


def run_peg_random(spec: PegRandomSpec) -> dict[str, Any]:
    """The random policy's episodes (the records of ``run_peg``, without Q)."""
    start = time.perf_counter()
    env = _peg_env(spec.robot, spec.config_dir, spec.episode_steps)
    noise = peg_noise_config(spec.config_dir)
    if spec.kind == "uniform":
        noise = dataclasses.replace(noise, kind="uniform")
    try:
        episodes = _episodes(env, spec.seed, range(spec.episodes), noise,
                             lambda state: np.zeros(env.action_dim))
    finally:
        env.close()
    return {"experiment": spec.experiment, "name": spec.name, "label": spec.label,
            "spec": dataclasses.asdict(spec), "config_digest": config_digest(spec.config_dir),
            "task_settings": spec.task_settings, "episodes": episodes,
            "rl_steps": int(sum(e["steps"] for e in episodes)),
            "wall_time": time.perf_counter() - start}


def _groups(results: list[dict[str, Any]]) -> dict[tuple[str, float], list[dict[str, Any]]]:
    groups: dict[tuple[str, float], list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault((r["spec"]["algorithm"], r["spec"]["lr"]), []).append(r)
    return dict(sorted(groups.items()))


def _curve(group: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean and standard error over the runs ``group`` of return and steps per episode."""
    n = min(len(r["episodes"]) for r in group)
    returns = np.array([[e["return"] for e in r["episodes"][:n]] for r in group])
    steps = np.array([[e["steps"] for e in r["episodes"][:n]] for r in group], dtype=float)
    success = np.array([[e["success"] for e in r["episodes"][:n]] for r in group], dtype=float)
    return {"seeds": len(group), "return_mean": returns.mean(0),
            "return_sem": returns.std(0) / np.sqrt(len(group)),
            "steps_mean": steps.mean(0), "success_mean": success.mean(0)}


def learning_curves(results: list[dict[str, Any]]) -> dict[tuple[str, float], dict[str, Any]]:
    """Per (algorithm, lr): mean and standard error over seeds of return and steps per episode."""
    return {key: _curve(group) for key, group in _groups(results).items()}


def random_curves(results: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per random policy (its label), the same statistics over its seeds (``run_peg_random``)."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in sorted(results, key=lambda r: r["spec"]["kind"]):
        groups.setdefault(r["label"], []).append(r)
    return {name: _curve(group) for name, group in groups.items()}


#: The two sets of final Q predictions whose spread across seeds thesis Fig. 8.3 shows: each
#: grid state with the 11 given actions, and with the run's own actor's action.
Q_POINTS = {"given": "q_given", "pi": "q_pi"}


def q_spread(results: list[dict[str, Any]], points: str = "given"
             ) -> dict[tuple[str, float], np.ndarray]:
    """Per (algorithm, lr): std across seeds of the final Q at each of ``points``
    (``Q_POINTS``: ``given``, the 27 x 11 state-action pairs; ``pi``, the 27 states with the
    actor's action), over the runs that hold their final Q (``holds_final_q``)."""
    return {key: np.array([r[Q_POINTS[points]] for r in group]).std(axis=0).ravel()
            for key, group in _groups(list(filter(holds_final_q, results))).items()
            if len(group) >= 2}


def q_seeds(results: list[dict[str, Any]]) -> dict[tuple[str, float], int]:
    """Per (algorithm, lr): how many runs hold their final Q, the seeds ``q_spread`` is over."""
    return {key: len(group)
            for key, group in _groups(list(filter(holds_final_q, results))).items()}


def holds_final_q(run: dict[str, Any]) -> bool:
    """Whether a run holds its final Q at every set of ``Q_POINTS`` (a saved run does; one read
    back from its episode rows does not)."""
    return all(field in run for field in Q_POINTS.values())
