"""DDPG with bounded TD targets: vanilla, QG-DDPG and the bound baselines (SPEC §2, §4).

One train step is thesis Algorithm 4: the TD target ``y = r + gamma * Q(s', pi(s'))`` (``r`` if
terminal) is clipped into ``[LB, UB]`` before the squared error is taken. What ``LB``/``UB`` are is
the only thing the variants change (``DDPGConfig.bounds``):

* ``none`` - vanilla DDPG.
* ``apriori`` - the realisable range from known rewards ``[r_min, r_max]`` (SPEC §3).
* ``empirical`` - the same formula from the lowest/highest reward in replay (can be wrong).
* ``qgraph`` - the Q-Graph bound of each transition (``Batch.lower_bounds``).
* ``qgraph+apriori`` - the tighter of both lower bounds, and the a-priori upper bound.
* ``he2017`` - He et al. (2017): n-step lower/upper bounds from the current critic along the
  trajectory, enforced as a penalty ``lambda * relu(L - Q)^2 + lambda * relu(Q - U)^2``.

No target networks by default (the thesis argues they delay divergence, not prevent it); they can
be switched on with a soft update rate ``tau``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from qg_learning_node.learner.replay import Batch, NStepContext

__all__ = ['BOUND_MODES', 'DDPG', 'DDPGConfig', 'build_mlp', 'realisable_range']

BOUND_MODES = ('none', 'apriori', 'empirical', 'qgraph', 'qgraph+apriori', 'he2017')
#: Weight inits: the thesis's two, and PyTorch's own ``nn.Linear`` init (SB3's networks).
INITS = ('glorot_uniform', 'he_uniform', 'torch_default')
#: Hidden activations of the actor: the thesis's tanh, or SB3's ReLU.
ACTOR_ACTIVATIONS = {'tanh': nn.Tanh, 'relu': nn.ReLU}
DIAGNOSTIC_KEYS = ('critic_loss', 'actor_loss', 'mean_q', 'frac_raised_lower',
                   'frac_lowered_upper', 'frac_outside_range')


def _tensor(x: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x), dtype=torch.float32)


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
    :param actor_activation: hidden activation of the actor, one of ``ACTOR_ACTIVATIONS``
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
        if self.actor_activation not in ACTOR_ACTIVATIONS:
            raise ValueError(f'actor_activation must be one of {sorted(ACTOR_ACTIVATIONS)}, '
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

    @property
    def effective_actor_lr(self) -> float:
        return self.critic_lr / 10.0 if self.actor_lr is None else self.actor_lr

    @classmethod
    def from_dict(cls, values: dict) -> 'DDPGConfig':
        unknown = set(values) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f'unknown DDPG config keys: {sorted(unknown)}')
        return cls(**values)


def build_mlp(sizes: list[int], hidden_act: type[nn.Module], out_act: type[nn.Module] | None,
              init: str, generator: torch.Generator) -> nn.Sequential:
    """Fully connected network; weights drawn with ``init`` from ``generator``, biases zero
    (``torch_default``: ``nn.Linear``'s own init, weights and biases, drawn from ``generator``)."""
    layers: list[nn.Module] = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        linear = nn.Linear(n_in, n_out, dtype=torch.float32)
        with torch.no_grad():
            if init == 'glorot_uniform':
                nn.init.xavier_uniform_(linear.weight, generator=generator)
                linear.bias.zero_()
            elif init == 'he_uniform':
                nn.init.kaiming_uniform_(linear.weight, nonlinearity='relu', generator=generator)
                linear.bias.zero_()
            else:
                nn.init.kaiming_uniform_(linear.weight, a=math.sqrt(5), generator=generator)
                nn.init.uniform_(linear.bias, -1.0 / math.sqrt(n_in), 1.0 / math.sqrt(n_in),
                                 generator=generator)
        layers.append(linear)
        last = i == len(sizes) - 2
        if not last:
            layers.append(hidden_act())
        elif out_act is not None:
            layers.append(out_act())
    return nn.Sequential(*layers)


class Critic(nn.Module):
    """Q(s, a): state and action concatenated at the input."""

    def __init__(self, net: nn.Sequential) -> None:
        super().__init__()
        self.net = net

    def forward(self, states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([states, actions], dim=-1)).squeeze(-1)


class DDPG:
    """Actor-critic pair with the bounded train step of thesis Algorithm 4.

    :param config: hyperparameters.
    :param state_dim: length of the (scaled) state vector.
    :param action_dim: length of the action vector (actor output in [-1, 1]).
    """

    def __init__(self, config: DDPGConfig, state_dim: int, action_dim: int) -> None:
        self.config = config
        generator = torch.Generator().manual_seed(config.seed)
        self.actor = build_mlp([state_dim, *config.actor_hidden, action_dim],
                               ACTOR_ACTIVATIONS[config.actor_activation], nn.Tanh,
                               config.actor_init, generator)
        self.critic = Critic(build_mlp([state_dim + action_dim, *config.critic_hidden, 1],
                                       nn.ReLU, None, config.critic_init, generator))
        self.actor_target = copy.deepcopy(self.actor) if config.target_networks else self.actor
        self.critic_target = copy.deepcopy(self.critic) if config.target_networks else self.critic
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=config.effective_actor_lr)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=config.critic_lr)
        self.range = realisable_range(config.r_min, config.r_max, config.gamma)
        self.train_steps = 0

    def act(self, state: np.ndarray) -> np.ndarray:
        """Deterministic action in [-1, 1] (no exploration noise)."""
        with torch.no_grad():
            return self.actor(torch.as_tensor(state, dtype=torch.float32)).double().numpy()

    def q_values(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Critic predictions for a batch of state-action pairs."""
        with torch.no_grad():
            return self.critic(torch.as_tensor(states, dtype=torch.float32),
                               torch.as_tensor(actions, dtype=torch.float32)).double().numpy()

    def _target_bounds(self, batch: Batch, reward_range: tuple[float, float] | None
                       ) -> tuple[np.ndarray | float, float]:
        mode, g = self.config.bounds, self.config.gamma
        lower: np.ndarray | float = -np.inf
        upper = np.inf
        if mode in ('apriori', 'qgraph+apriori'):
            lower, upper = self.range
        if mode == 'empirical':
            if reward_range is None:
                raise ValueError('bounds="empirical" needs the reward_range of the replay memory')
            lower, upper = realisable_range(reward_range[0], reward_range[1], g)
        if mode in ('qgraph', 'qgraph+apriori'):
            lower = np.maximum(np.asarray(batch.lower_bounds, dtype=np.float64), lower)
        return lower, upper

    def _he_bounds(self, batch: Batch, context: NStepContext
                   ) -> tuple[torch.Tensor, torch.Tensor]:
        """Tightest n-step lower and upper bound from the current critic (He et al. 2017)."""
        g, horizon = self.config.gamma, context.future_rewards.shape[1]
        f = _tensor
        with torch.no_grad():
            s_f = f(context.future_next_states)
            q_f = self.critic_target(s_f, self.actor_target(s_f))
            q_p = self.critic_target(f(context.past_states), f(context.past_actions))
        j = torch.arange(1, horizon + 1, dtype=torch.float32)
        returns = f(batch.rewards)[:, None] + torch.cumsum(g ** j * f(context.future_rewards), 1)
        cont = 1.0 - f(context.future_terminals)
        lower = returns + g ** (j + 1) * q_f * cont
        lower = torch.where(f(context.future_valid) > 0, lower, torch.tensor(-np.inf))
        past_sum = torch.cumsum(g ** (-j) * f(context.past_rewards), 1)
        upper = g ** (-j) * q_p - past_sum
        upper = torch.where(f(context.past_valid) > 0, upper, torch.tensor(np.inf))
        return lower.max(1).values, upper.min(1).values

    def train_step(self, batch: Batch, reward_range: tuple[float, float] | None = None,
                   context: NStepContext | None = None) -> dict:
        """One critic and one actor update on ``batch``; returns diagnostics.

        :param reward_range: (lowest, highest) reward in replay; needed for ``empirical``.
        :param context: neighbouring transitions; needed for ``he2017``.
        """
        f = _tensor
        s, a, r, s2 = f(batch.states), f(batch.actions), f(batch.rewards), f(batch.next_states)
        done = f(batch.terminals)
        with torch.no_grad():
            y_td = r + self.config.gamma * (1.0 - done) * self.critic_target(
                s2, self.actor_target(s2))
        lower, upper = self._target_bounds(batch, reward_range)
        lower_t = torch.broadcast_to(f(lower), y_td.shape)
        y = torch.clamp(torch.maximum(y_td, lower_t), max=upper)
        frac_raised = (y_td < lower_t).float().mean().item()
        frac_lowered = (y_td > upper).float().mean().item()

        q = self.critic(s, a)
        critic_loss = torch.mean((y - q) ** 2)
        if self.config.bounds == 'he2017':
            if context is None:
                raise ValueError('bounds="he2017" needs the trajectory context of the batch')
            he_lower, he_upper = self._he_bounds(batch, context)
            lam = self.config.he_lambda
            critic_loss = critic_loss + lam * torch.mean(
                torch.relu(torch.where(torch.isfinite(he_lower), he_lower - q, 0.0)) ** 2
                + torch.relu(torch.where(torch.isfinite(he_upper), q - he_upper, 0.0)) ** 2)
            frac_raised = (y_td < he_lower).float().mean().item()
            frac_lowered = (y_td > he_upper).float().mean().item()
        self.critic_opt.zero_grad()
        critic_loss.backward()
        self.critic_opt.step()

        actor_loss = -self.critic(s, self.actor(s)).mean()
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()
        self.critic_opt.zero_grad()  # the actor loss also filled critic gradients

        if self.config.target_networks:
            self._soft_update()
        self.train_steps += 1
        q_np = q.detach().double().numpy()
        lo, hi = self.range
        return {
            'critic_loss': critic_loss.item(),
            'actor_loss': actor_loss.item(),
            'mean_q': float(q_np.mean()),
            'frac_raised_lower': frac_raised,
            'frac_lowered_upper': frac_lowered,
            'frac_outside_range': float(np.mean((q_np < lo) | (q_np > hi))),
        }

    def _soft_update(self) -> None:
        tau = self.config.tau
        with torch.no_grad():
            for net, target in ((self.actor, self.actor_target), (self.critic, self.critic_target)):
                for p, p_t in zip(net.parameters(), target.parameters()):
                    p_t.mul_(1.0 - tau).add_(tau * p)

    def actor_tensors(self) -> list[tuple[str, np.ndarray]]:
        """Actor weights as (name, float32 array), weight then bias of each layer."""
        return [(name, t.detach().numpy().astype(np.float32).copy())
                for name, t in self.actor.state_dict().items()]

    def set_learning_rates(self, critic_lr: float, actor_lr: float) -> None:
        """Use these Adam step sizes from the next train step on (the moments are kept)."""
        if not critic_lr > 0 or not actor_lr > 0:
            raise ValueError(f'learning rates must be > 0, got {critic_lr}, {actor_lr}')
        for optimizer, lr in ((self.critic_opt, critic_lr), (self.actor_opt, actor_lr)):
            for group in optimizer.param_groups:
                group['lr'] = lr

    def state_dict(self) -> dict:
        state = {'actor': self.actor.state_dict(), 'critic': self.critic.state_dict(),
                 'actor_opt': self.actor_opt.state_dict(),
                 'critic_opt': self.critic_opt.state_dict(), 'train_steps': self.train_steps}
        if self.config.target_networks:
            state['actor_target'] = self.actor_target.state_dict()
            state['critic_target'] = self.critic_target.state_dict()
        return copy.deepcopy(state)  # a snapshot: live tensors would keep changing

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state['actor'])
        self.critic.load_state_dict(state['critic'])
        self.actor_opt.load_state_dict(state['actor_opt'])
        self.critic_opt.load_state_dict(state['critic_opt'])
        self.train_steps = state['train_steps']
        if self.config.target_networks:
            self.actor_target.load_state_dict(state['actor_target'])
            self.critic_target.load_state_dict(state['critic_target'])
