"""QG-DDPG (or our vanilla DDPG) on any Gymnasium environment with a ``Box`` action space.

Why: a researcher should be able to point QG-DDPG at their own task in one line, and compare it
with Stable-Baselines3 in one TensorBoard. So the API is SB3's shape,
``QGDDPG(env, **settings).learn(total_steps)`` and ``predict(obs, deterministic=True)``, and the
scalars carry SB3's tags (``training_log.TrainingLog``). The learning itself is the stack's
learner core (``LearnerCore``: replay, Q-Graph, the bounded train step), the same code the ROS
learner node and the experiments run; this module only collects transitions from ``env``.

Units: the networks see observations of a bounded ``Box`` scaled to [-1, 1] when
``normalize_observations`` (the thesis's state scaling; off for SB3's settings, which feed the raw
observation), and act in [-1, 1], mapped linearly onto the action box. Rewards are the
environment's. The graph identifies states exactly, so its bounds come from terminal states
reached (``terminated``, never ``truncated``) and from loops, such as a known ``zero_action``
that leaves the state unchanged; a dense task without terminals or loops gets no graph bound.

A-priori bounds: ``reward_range=(r_min, r_max)`` (or a finite ``reward_range`` attribute of the
unwrapped environment, as ours have) clips targets into the realisable range too.

Example (the README's)::

    QGDDPG(gymnasium.make("Pendulum-v1"), seed=0).learn(20_000)
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from qg_learning_node.executor.noise import ActionNoise, NoiseConfig
from qg_learning_node.learner import algorithms
from qg_learning_node.learner.ddpg import DDPGConfig
from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore
from qg_learning_node.learner.training_log import TrainingLog

__all__ = ["QGDDPG", "AgentSettings", "ALGORITHMS", "SB3_DDPG_SETTINGS"]

#: Our algorithms (``algorithms.REGISTRY``): ``qgddpg``: graph bounds (+ a-priori bounds when the
#: reward range is known) and the zero action's loops; ``ddpg``: the same learner without any
#: bound (thesis Algorithm 4 unclipped); and QG-DDPG's parts apart.
ALGORITHMS = algorithms.keys("ours")

#: Stable-Baselines3 DDPG's defaults (2.x, ``DDPG.__init__`` and ``TD3Policy``) in our terms:
#: 400-300 ReLU networks with PyTorch's init, one learning rate, target networks, 100 uniformly
#: random steps first, one gradient step per environment step, raw observations. SB3 adds no
#: exploration noise by default; RL Zoo and our peers' runs add Gaussian 0.1 (``noise_sigma``).
SB3_DDPG_SETTINGS: dict[str, Any] = {
    "actor_hidden": (400, 300), "critic_hidden": (400, 300), "actor_activation": "relu",
    "init": "torch_default", "critic_lr": 1e-3, "actor_lr": 1e-3, "gamma": 0.99,
    "batch_size": 256, "buffer_size": 1_000_000, "learning_starts": 100, "train_freq": 1,
    "gradient_steps": 1, "target_networks": True, "tau": 0.005,
    "normalize_observations": False}


@dataclass(frozen=True)
class AgentSettings:
    """The agent's settings; the defaults are the stack's (``config/learner.yaml``, SPEC 2),
    apart from ``gamma`` (0.99, SB3's; the shaft task runs 0.9).

    :param algorithm: one of :data:`ALGORITHMS`.
    :param gamma: discount; :param critic_lr: Adam rate of the critic; :param actor_lr: of the
        actor, ``None`` = ``critic_lr / 10`` (the thesis grid).
    :param actor_hidden: hidden layers of the actor; :param critic_hidden: of the critic.
    :param actor_activation: ``tanh`` (thesis) | ``relu`` (SB3).
    :param init: ``thesis`` (Glorot actor, He critic) | ``torch_default`` (SB3).
    :param batch_size: minibatch size; :param buffer_size: replay slots, ``None`` = unbounded.
    :param learning_starts: [steps] uniformly random actions, and no training, before this.
    :param train_freq: [steps] train after every this many steps; :param gradient_steps: that
        many minibatch updates each time (the thesis: 10 or 50 per 20 steps).
    :param noise: exploration noise kind (``executor.noise.KINDS``) in [-1, 1] action units;
        :param noise_sigma: its sigma; :param noise_theta: OU only.
    :param target_networks: soft-updated target networks (the thesis has none); :param tau: rate.
    :param zero_action: an action (environment units) that leaves the state unchanged, if the
        task has one: QG-DDPG then adds its never-executed self-loops (SPEC 4).
    :param reward_range: ``(r_min, r_max)`` for a-priori bounds; ``None``: the unwrapped
        environment's ``reward_range`` if it is finite, else none.
    :param normalize_observations: scale a bounded observation box to [-1, 1].
    :param actor_preact_penalty: ``DDPGConfig.actor_preact_penalty`` (0: none): keeps the
        actor's tanh out of saturation when a bound lifts the critic at once.
    :param seed: networks, sampling, noise and the first ``env.reset``.
    """
    algorithm: str = "qgddpg"
    gamma: float = 0.99
    critic_lr: float = 1e-3
    actor_lr: float | None = None
    actor_hidden: tuple[int, ...] = (100, 100)
    critic_hidden: tuple[int, ...] = (100, 100)
    actor_activation: str = "tanh"
    init: str = "thesis"
    batch_size: int = 64
    buffer_size: int | None = None
    learning_starts: int = 0
    train_freq: int = 20
    gradient_steps: int = 10
    noise: str = "gaussian"
    noise_sigma: float = 0.3
    noise_theta: float = 1.0
    target_networks: bool = False
    tau: float = 0.005
    zero_action: tuple[float, ...] | None = None
    reward_range: tuple[float, float] | None = None
    normalize_observations: bool = True
    actor_preact_penalty: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        algorithms.algorithm(self.algorithm, "ours")
        if self.init not in ("thesis", "torch_default"):
            raise ValueError(f"init must be thesis or torch_default, got {self.init!r}")
        if self.learning_starts < 0 or self.train_freq < 1 or self.gradient_steps < 1:
            raise ValueError("learning_starts must be >= 0, train_freq and gradient_steps >= 1")


class QGDDPG:
    """QG-DDPG on a Gymnasium environment (see the module docstring).

    :param env: a ``gymnasium.Env`` with a ``Box`` action space and a flat ``Box`` observation.
    :param settings: :class:`AgentSettings` fields by name.
    :raises ValueError: for another kind of space, or an unknown setting.
    """

    def __init__(self, env: Any, **settings: Any) -> None:
        from gymnasium import spaces
        unknown = set(settings) - {f.name for f in dataclasses.fields(AgentSettings)}
        if unknown:
            raise ValueError(f"unknown settings {sorted(unknown)}")
        self.settings = s = AgentSettings(**settings)
        if not isinstance(env.action_space, spaces.Box):
            raise ValueError(f"QG-DDPG needs a Box action space, got {env.action_space}")
        if not isinstance(env.observation_space, spaces.Box) or \
                len(env.observation_space.shape) != 1:
            raise ValueError(f"QG-DDPG needs a flat Box observation, got {env.observation_space}")
        self.env = env
        self._low = env.action_space.low.astype(np.float64)
        self._high = env.action_space.high.astype(np.float64)
        if not (np.all(np.isfinite(self._low)) and np.all(np.isfinite(self._high))):
            raise ValueError("QG-DDPG needs a bounded action box")
        obs = env.observation_space
        bounded = bool(np.all(np.isfinite(obs.low)) and np.all(np.isfinite(obs.high)))
        self._obs_low = obs.low.astype(np.float64) if bounded else None
        self._obs_span = (obs.high - obs.low).astype(np.float64) if bounded else None
        self._scale_observations = s.normalize_observations and bounded
        action_dim, state_dim = env.action_space.shape[0], obs.shape[0]
        self.reward_range = self._reward_range(env, s.reward_range)
        self.core = LearnerCore(self._learner_config(action_dim), state_dim, action_dim)
        self.noise = ActionNoise(NoiseConfig(s.noise, s.noise_sigma, s.noise_theta), action_dim,
                                 s.seed)
        self.rng = np.random.default_rng([s.seed, 1])
        self.num_timesteps = 0
        self.episodes = 0
        self.log: TrainingLog | None = None
        self._obs: np.ndarray | None = None
        #: The running episode's steps and return: an episode may span calls of ``learn`` (a
        #: sweep that evaluates every N steps calls it in chunks), and is reported whole.
        self._episode_steps, self._episode_return = 0, 0.0

    # --- settings -> the learner core ------------------------------------------------------------
    @staticmethod
    def _reward_range(env: Any, given: tuple[float, float] | None) -> tuple[float, float] | None:
        found = given if given is not None else getattr(env.unwrapped, "reward_range", None)
        if found is None or not all(math.isfinite(float(x)) for x in found):
            return None
        return float(found[0]), float(found[1])

    def _to_actor_units(self, action: np.ndarray) -> np.ndarray:
        return 2.0 * (np.asarray(action, np.float64) - self._low) / (self._high - self._low) - 1.0

    def _learner_config(self, action_dim: int) -> LearnerConfig:
        s = self.settings
        lo, hi = self.reward_range if self.reward_range else (-math.inf, math.inf)
        init = {"thesis": ("glorot_uniform", "he_uniform"),
                "torch_default": ("torch_default", "torch_default")}[s.init]
        ddpg = DDPGConfig(gamma=s.gamma, actor_hidden=s.actor_hidden, critic_hidden=s.critic_hidden,
                          actor_activation=s.actor_activation, actor_init=init[0],
                          critic_init=init[1], critic_lr=s.critic_lr, actor_lr=s.actor_lr,
                          bounds="none", r_min=lo, r_max=hi, target_networks=s.target_networks,
                          tau=s.tau, actor_preact_penalty=s.actor_preact_penalty, seed=s.seed)
        zero = (None if s.zero_action is None
                else tuple(self._to_actor_units(np.asarray(s.zero_action)).tolist()))
        base = LearnerConfig(ddpg=ddpg, replay_capacity=s.buffer_size, use_qgraph=False,
                             zero_action=None, iterations_per_cycle=s.gradient_steps,
                             cycle_steps=s.train_freq, batch_size=s.batch_size,
                             census_every=10**9, seed=s.seed)
        return algorithms.algorithm(s.algorithm).learner_config(base, zero, self.reward_range is not None)

    # --- acting ------------------------------------------------------------------------------------
    def _state(self, observation: np.ndarray) -> np.ndarray:
        x = np.asarray(observation, dtype=np.float64).ravel()
        if self._scale_observations:
            x = 2.0 * (x - self._obs_low) / self._obs_span - 1.0
        return x

    def _to_env(self, action: np.ndarray) -> np.ndarray:
        """Actor units [-1, 1] -> the action box, in the box's dtype."""
        a = self._low + (np.clip(action, -1.0, 1.0) + 1.0) * 0.5 * (self._high - self._low)
        return a.astype(self.env.action_space.dtype)

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """The actor's action for ``observation`` (SB3's signature; no noise when
        ``deterministic``, else the exploration noise on top)."""
        del state, episode_start
        action = self.core.agent.act(self._state(observation))
        if not deterministic:
            action = self.noise.perturb(action)
        return self._to_env(action), None

    # --- learning ----------------------------------------------------------------------------------
    def learn(self, total_steps: int, max_episodes: int | None = None,
              tensorboard_log: str | Path | None = None,
              callback: Callable[[dict[str, Any]], bool] | None = None) -> QGDDPG:
        """Collect ``total_steps`` environment steps (or stop after ``max_episodes`` episodes),
        training as the settings say; returns ``self``.

        :param tensorboard_log: a folder for SB3-tagged scalars and ``progress.csv``.
        :param callback: called with each finished episode's ``{"steps", "return", "success",
            "timesteps"}``; returning False stops learning.
        """
        s = self.settings
        torch.set_num_threads(1)
        if tensorboard_log is not None and self.log is None:
            self.log = TrainingLog(Path(tensorboard_log))
        start, start_steps = time.perf_counter(), self.num_timesteps
        if self._obs is None:
            self._obs, _ = self.env.reset(seed=s.seed)
        for _ in range(int(total_steps)):
            state = self._state(self._obs)
            if self.num_timesteps < s.learning_starts:
                action = self.noise.perturb(self.rng.uniform(-1.0, 1.0, self._low.shape))
            else:
                action = self.noise.perturb(self.core.agent.act(state))
            obs, reward, terminated, truncated, info = self.env.step(self._to_env(action))
            self.num_timesteps += 1
            self._episode_steps += 1
            self._episode_return += float(reward)
            self.core.add_transition(state, action, float(reward), self._state(obs),
                                     bool(terminated))
            if (self.num_timesteps > s.learning_starts
                    and self.num_timesteps % s.train_freq == 0):
                diagnostics = self.core.train_cycle()
                if self.log is not None:
                    self.log.training(diagnostics, self.num_timesteps)
            self._obs = obs
            if terminated or truncated:
                self.episodes += 1
                success = bool(info.get("is_success", terminated))
                fps = (self.num_timesteps - start_steps) / max(time.perf_counter() - start, 1e-9)
                if self.log is not None:
                    self.log.episode("train", self._episode_steps, success,
                                     self._episode_return, self.num_timesteps, fps)
                go_on = callback is None or callback(
                    {"steps": self._episode_steps, "return": self._episode_return,
                     "success": success, "timesteps": self.num_timesteps}) is not False
                self.noise.reset(int(self.rng.integers(2**31)))
                self._obs, _ = self.env.reset()
                self._episode_steps, self._episode_return = 0, 0.0
                if not go_on or (max_episodes is not None and self.episodes >= max_episodes):
                    break
        return self

    def close(self) -> None:
        """Close the TensorBoard writer (the environment stays the caller's)."""
        if self.log is not None:
            self.log.close()
            self.log = None
