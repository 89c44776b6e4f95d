"""The learner's settings, apart from the code they set: importable without PyTorch.

``DDPGConfig`` (networks, bounds, learning rates) and ``LearnerConfig`` (replay, Q-Graph,
training schedule) are checked when built, so a node or a command line that only reads and
checks settings (the learner node's parameters, ``qgl``) does so without loading torch: the
learner node refuses a bad parameter in a fraction of a second and loads torch only to build
its networks. ``ddpg`` and ``learner_core`` use them and name them again for their callers.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

__all__ = ['ACTOR_ACTIVATION_NAMES', 'APRIORI_BOUNDS', 'BOUND_MODES', 'DDPGConfig', 'GRAPH_BOUNDS',
           'INITS', 'LearnerConfig', 'RUNTIME_FIELDS', 'SCHEDULES', 'differences',
           'realisable_range', 'with_runtime_settings']

#: How the TD targets are bounded (``ddpg`` module docstring); the algorithms that combine them
#: are named in ``algorithms.REGISTRY``.
BOUND_MODES = ('none', 'apriori', 'empirical', 'qgraph', 'qgraph+apriori', 'he2017')
#: The modes that take the Q-Graph's lower bounds (and so need a graph).
GRAPH_BOUNDS = ('qgraph', 'qgraph+apriori')
#: The modes that take the a-priori range of the known rewards ``[r_min, r_max]``.
APRIORI_BOUNDS = ('apriori', 'qgraph+apriori')
#: Weight inits: the thesis's two of the Panda, the normal one of its peg's critic (ch. 8.3.2.1:
#: weights from N(0, 0.001), so Q starts near 0), and PyTorch's own ``nn.Linear`` init (SB3's).
INITS = ('glorot_uniform', 'he_uniform', 'normal_1e-3', 'torch_default')
#: Hidden activations of the actor: the thesis's tanh, or SB3's ReLU.
ACTOR_ACTIVATION_NAMES = ('tanh', 'relu')


def realisable_range(r_min: float, r_max: float, gamma: float) -> tuple[float, float]:
    """Smallest and largest possible Q-value for rewards in ``[r_min, r_max]`` (SPEC §3)."""
    return min(r_min, r_min / (1.0 - gamma)), max(r_max, r_max / (1.0 - gamma))


@dataclass(frozen=True)
class DDPGConfig:
    """Hyperparameters; the defaults are ``config/learner.yaml``'s where it sets them (a test
    keeps the two equal), else SPEC §2 (thesis ch. 9.5).

    :param gamma: discount factor (the thesis does not state it; ``config/learner.yaml``'s is
        tuned on the Panda task, docs/learning.md section 4).
    :param actor_hidden: hidden layer sizes of the actor (tanh everywhere, tanh output in [-1, 1]).
    :param critic_hidden: hidden layer sizes of the critic (ReLU, linear scalar output).
    :param actor_activation: hidden activation of the actor, one of ``ACTOR_ACTIVATION_NAMES``
        (its output is always tanh; the executor's torch-free ``ActorMLP`` runs tanh only).
    :param actor_init: weight init of the actor, one of ``INITS``.
    :param critic_init: weight init of the critic, one of ``INITS``.
    :param critic_lr: Adam learning rate of the critic.
    :param actor_lr: Adam learning rate of the actor; ``None`` = ``critic_lr / 10``.
    :param bounds: one of ``BOUND_MODES``.
    :param r_min: smallest possible reward (a-priori bounds, realisable-range diagnostic).
    :param r_max: largest possible reward.
    :param target_networks: use soft-updated target networks for the TD target.
    :param tau: soft update rate of the target networks.
    :param he_horizon: steps ahead/behind for the ``he2017`` bounds.
    :param he_lambda: penalty weight of the ``he2017`` bounds.
    :param actor_preact_penalty: weight of the mean squared pre-tanh output of the actor in its
        loss; 0 = none (the thesis, the Panda task). Why: when the graph bounds a first
        goal-reaching chain, the critic's values jump and the deterministic actor's tanh
        saturates at one end on every state; saturated, tanh passes almost no gradient back, so
        the actor stays a constant push (MountainCarContinuous-v0: docs/learning.md section 13).
        The penalty keeps the pre-activations near the range where tanh still has a slope.
    :param self_loop_tol: > 0: a non-terminal transition whose state moved by at most this (max
        norm, scaled units) is a self-loop, and its TD target is the value of repeating its
        action forever, ``r / (1 - gamma)`` (0: none, the thesis). Why: at rest the world is
        deterministic, so an action that leaves the state unchanged leaves it unchanged every
        time; a deterministic actor that chose it stays there, and ``r / (1 - gamma)`` is
        that actor's exact value (docs/learning.md section 17). Bootstrapping the same loop
        from the critic only shrinks its error by ``gamma`` per pass.
    :param twin_critics: two critics from different initialisations, both fitted to the same
        target ``r + gamma * min(Q1, Q2)(s', a')``, the actor maximising ``min(Q1, Q2)``
        (TD3's clipped double Q, with the actor pessimistic too, as SAC's). Why: the stalled
        actor sits where its single critic overestimates an action replay never held; two
        critics disagree most where neither has data, and their minimum is lower there.
    :param target_noise: standard deviation of the noise added to the target action ``a' =
        pi(s')`` (clipped to 2.5 times itself and to the action box), 0 = none (TD3's target
        policy smoothing uses 0.2): the target then values a neighbourhood of the actor's
        action, not a single point the critic can overfit.
    :param seed: seed of the network initialisation.
    """

    gamma: float = 0.9
    actor_hidden: tuple[int, ...] = (100, 100)
    critic_hidden: tuple[int, ...] = (100, 100)
    actor_activation: str = 'tanh'
    actor_init: str = 'glorot_uniform'
    critic_init: str = 'he_uniform'
    critic_lr: float = 1e-3
    actor_lr: float | None = None
    bounds: str = 'qgraph+apriori'
    r_min: float = -1.0
    r_max: float = 0.0
    target_networks: bool = False
    tau: float = 0.005
    he_horizon: int = 8
    he_lambda: float = 0.01
    actor_preact_penalty: float = 0.0
    self_loop_tol: float = 0.0
    twin_critics: bool = False
    target_noise: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'actor_hidden', tuple(int(h) for h in self.actor_hidden))
        object.__setattr__(self, 'critic_hidden', tuple(int(h) for h in self.critic_hidden))
        if not 0.0 <= self.gamma < 1.0:
            raise ValueError(f'gamma must lie in [0, 1), got {self.gamma}')
        if self.bounds not in BOUND_MODES:
            raise ValueError(f'bounds must be one of {BOUND_MODES}, got {self.bounds!r}')
        for name in ('actor_init', 'critic_init'):
            if getattr(self, name) not in INITS:
                raise ValueError(f'{name} must be one of {INITS}, got {getattr(self, name)!r}')
        if self.actor_activation not in ACTOR_ACTIVATION_NAMES:
            raise ValueError(f'actor_activation must be one of {sorted(ACTOR_ACTIVATION_NAMES)}, '
                             f'got {self.actor_activation!r}')
        if any(h < 1 for h in self.actor_hidden + self.critic_hidden):
            raise ValueError('hidden layer sizes must be >= 1')
        if self.critic_lr <= 0 or (self.actor_lr is not None and self.actor_lr <= 0):
            raise ValueError('learning rates must be > 0')
        if self.r_min > self.r_max:
            raise ValueError(f'r_min ({self.r_min}) must not exceed r_max ({self.r_max})')
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f'tau must lie in (0, 1], got {self.tau}')
        if self.he_horizon < 1 or self.he_lambda < 0:
            raise ValueError('he_horizon must be >= 1 and he_lambda >= 0')
        if not 0.0 <= self.self_loop_tol < math.inf:
            raise ValueError(f'self_loop_tol must be a finite number >= 0, got {self.self_loop_tol}')
        if not 0.0 <= self.target_noise < math.inf:
            raise ValueError(f'target_noise must be a finite number >= 0, got {self.target_noise}')
        if not 0.0 <= self.actor_preact_penalty < math.inf:
            raise ValueError('actor_preact_penalty must be a finite number >= 0, got '
                             f'{self.actor_preact_penalty}')

    @property
    def effective_actor_lr(self) -> float:
        return self.critic_lr / 10.0 if self.actor_lr is None else self.actor_lr

    @classmethod
    def from_dict(cls, values: dict) -> DDPGConfig:
        unknown = set(values) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f'unknown DDPG config keys: {sorted(unknown)}')
        return cls(**values)


SCHEDULES = ('cycle', 'async')
#: Settings a running learner can take between two training cycles (``LearnerCore.reconfigure``):
#: how much and how fast it trains, not what its networks, graph or replay memory are.
RUNTIME_FIELDS = frozenset({'iterations_per_cycle', 'cycle_steps', 'batch_size', 'census_every',
                            'ddpg.critic_lr', 'ddpg.actor_lr'})


@dataclass(frozen=True)
class LearnerConfig:
    """Learner settings; the defaults are ``config/learner.yaml``'s where it sets them (a test
    keeps the two equal).

    :param ddpg: network and bound settings.
    :param replay_capacity: replay slots, ``None`` = unbounded (SPEC: also 300 in one study).
    :param use_qgraph: maintain the Q-Graph (required by the ``qgraph*`` bound modes; without them
        it only feeds the census diagnostics).
    :param zero_action: action that leaves the state unchanged, or ``None`` (the default is the
        Panda residual's: zero torques about x and y).
    :param iterations_per_cycle: train steps after every cycle (SPEC: 10 or 50).
    :param cycle_steps: RL steps per training cycle.
    :param batch_size: minibatch size.
    :param census_every: recompute the graph census every this many cycles (it walks the whole
        graph, ~0.1 s per 80k transitions); the last census is reported in between.
    :param seed: seed of minibatch sampling (the networks use ``ddpg.seed``).
    :param graph_resolution: Q-Graph state-merging grid in scaled state units (0: exact states,
        the thesis; see ``qgraph``).
    :param schedule: ``cycle`` | ``async`` (see the module docstring).
    :param updates_per_step: ``async``: train steps per received transition.
    :param publish_every: ``async``: train steps between two published actors.
    """

    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    replay_capacity: int | None = None
    use_qgraph: bool = True
    zero_action: tuple[float, ...] | None = (0.0, 0.0)
    iterations_per_cycle: int = 10
    cycle_steps: int = 20
    batch_size: int = 64
    census_every: int = 5
    seed: int = 0
    graph_resolution: float = 0.0
    schedule: str = 'cycle'
    updates_per_step: float = 10.0
    publish_every: int = 20

    def __post_init__(self) -> None:
        if self.schedule not in SCHEDULES:
            raise ValueError(f'schedule must be one of {SCHEDULES}, got {self.schedule!r}')
        if not self.updates_per_step > 0 or self.publish_every < 1:
            raise ValueError('updates_per_step must be > 0 and publish_every >= 1')
        if self.zero_action is not None:
            object.__setattr__(self, 'zero_action', tuple(float(x) for x in self.zero_action))
        if self.replay_capacity is not None and self.replay_capacity < 1:
            raise ValueError(f'replay_capacity must be >= 1 or None, got {self.replay_capacity}')
        if self.ddpg.bounds in GRAPH_BOUNDS and not self.use_qgraph:
            raise ValueError(f'bounds={self.ddpg.bounds!r} needs use_qgraph=True')
        for name in ('iterations_per_cycle', 'cycle_steps', 'batch_size', 'census_every'):
            if getattr(self, name) < 1:
                raise ValueError(f'{name} must be >= 1, got {getattr(self, name)}')

    @classmethod
    def from_dict(cls, values: dict) -> LearnerConfig:
        unknown = set(values) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f'unknown learner config keys: {sorted(unknown)}')
        values = dict(values)
        if isinstance(values.get('ddpg'), dict):
            values['ddpg'] = DDPGConfig.from_dict(values['ddpg'])
        return cls(**values)


def with_runtime_settings(base: LearnerConfig, source: LearnerConfig) -> LearnerConfig:
    """``base`` with the ``RUNTIME_FIELDS`` of ``source`` (a learner resumed from a checkpoint
    keeps the checkpoint's other settings when its parameters change)."""
    ddpg = dataclasses.replace(base.ddpg, critic_lr=source.ddpg.critic_lr,
                               actor_lr=source.ddpg.actor_lr)
    top = {name: getattr(source, name) for name in RUNTIME_FIELDS if '.' not in name}
    return dataclasses.replace(base, ddpg=ddpg, **top)


def differences(old: Any, new: Any, prefix: str = '') -> Iterator[tuple[str, tuple[Any, Any]]]:
    """(dotted name, (old, new)) of every field in which two configs differ, nested configs
    (``ddpg``) field by field."""
    for f in dataclasses.fields(old):
        a, b = getattr(old, f.name), getattr(new, f.name)
        if dataclasses.is_dataclass(a):
            yield from differences(a, b, f'{prefix}{f.name}.')
        elif a != b:
            yield f'{prefix}{f.name}', (a, b)
