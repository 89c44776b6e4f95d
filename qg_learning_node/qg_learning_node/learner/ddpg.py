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

With ``DDPGConfig.self_loop_tol`` set, a transition whose state did not move (at rest, in a
deterministic world, a self-loop) takes ``r / (1 - gamma)`` as its TD target before the bounds:
the exact value of repeating its action forever.

With ``DDPGConfig.twin_critics`` (TD3's clipped double Q) two critics are fitted to one target
built from the minimum of both, and the actor maximises that minimum; ``target_noise`` smooths
the target action (TD3's target policy smoothing). Both are off by default (the thesis).

The actor's loss is ``-Q(s, pi(s))``, plus, if ``DDPGConfig.actor_preact_penalty`` is set, that
weight times the mean squared pre-tanh output: a bound that lifts a whole goal-reaching chain at
once can drive the tanh into saturation on every state, where it passes no gradient back.

No target networks by default (the thesis argues they delay divergence, not prevent it); they can
be switched on with a soft update rate ``tau``.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import torch
from torch import nn

from qg_learning_node.learner.adam import Adam
from qg_learning_node.learner.learner_config import (
    ACTOR_ACTIVATION_NAMES,
    APRIORI_BOUNDS,
    BOUND_MODES,
    GRAPH_BOUNDS,
    DDPGConfig,
    realisable_range,
)
from qg_learning_node.learner.replay import Batch, NStepContext

__all__ = ['BOUND_MODES', 'DDPG', 'DDPGConfig', 'build_mlp', 'realisable_range']

#: The modules of the actor's hidden activations (``learner_config.ACTOR_ACTIVATION_NAMES``).
ACTOR_ACTIVATIONS = dict(zip(ACTOR_ACTIVATION_NAMES, (nn.Tanh, nn.ReLU), strict=True))
DIAGNOSTIC_KEYS = ('critic_loss', 'actor_loss', 'mean_q', 'frac_raised_lower',
                   'frac_lowered_upper', 'frac_outside_range')


def _tensor(x: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x), dtype=torch.float32)


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
            elif init == 'normal_1e-3':
                nn.init.normal_(linear.weight, 0.0, 1e-3, generator=generator)
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


def _min_q(critic: Critic, twin: Critic | None, states: torch.Tensor,
           actions: torch.Tensor) -> torch.Tensor:
    """``critic``'s value, or the minimum of it and its ``twin``'s."""
    q = critic(states, actions)
    return q if twin is None else torch.minimum(q, twin(states, actions))


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
        self.actor_opt = Adam(self.actor.parameters(), lr=config.effective_actor_lr)
        self.critic_opt = Adam(self.critic.parameters(), lr=config.critic_lr)
        # The twin (drawn after the thesis's networks, so they are the same with or without it).
        self.critic2: Critic | None = None
        self.critic2_target: Critic | None = None
        self.critic2_opt: Adam | None = None
        if config.twin_critics:
            self.critic2 = Critic(build_mlp([state_dim + action_dim, *config.critic_hidden, 1],
                                            nn.ReLU, None, config.critic_init, generator))
            self.critic2_target = (copy.deepcopy(self.critic2) if config.target_networks
                                   else self.critic2)
            self.critic2_opt = Adam(self.critic2.parameters(), lr=config.critic_lr)
        self.target_noise_rng = torch.Generator().manual_seed(config.seed + 1)
        self.range = realisable_range(config.r_min, config.r_max, config.gamma)
        self.train_steps = 0

    def act(self, state: np.ndarray) -> np.ndarray:
        """Deterministic action in [-1, 1] (no exploration noise)."""
        with torch.no_grad():
            return self.actor(torch.as_tensor(state, dtype=torch.float32)).double().numpy()

    def q_values(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Critic predictions for a batch of state-action pairs (:meth:`q`, without gradients)."""
        with torch.no_grad():
            return self.q(torch.as_tensor(states, dtype=torch.float32),
                          torch.as_tensor(actions, dtype=torch.float32)).double().numpy()

    def q(self, states: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """The value the actor maximises: the critic's, or with twins their minimum."""
        return _min_q(self.critic, self.critic2, states, actions)

    def _target_q(self, next_states: torch.Tensor) -> torch.Tensor:
        """The target critics' value of the target actor's (smoothed) action at ``next_states``."""
        actions = self.actor_target(next_states)
        sigma = self.config.target_noise
        if sigma > 0:
            noise = torch.randn(actions.shape, generator=self.target_noise_rng) * sigma
            actions = torch.clamp(actions + noise.clamp(-2.5 * sigma, 2.5 * sigma), -1.0, 1.0)
        return _min_q(self.critic_target, self.critic2_target, next_states, actions)

    def _target_bounds(self, batch: Batch, reward_range: tuple[float, float] | None
                       ) -> tuple[np.ndarray | float, float]:
        mode, g = self.config.bounds, self.config.gamma
        lower: np.ndarray | float = -np.inf
        upper = np.inf
        if mode in APRIORI_BOUNDS:
            lower, upper = self.range
        if mode == 'empirical':
            if reward_range is None:
                raise ValueError('bounds="empirical" needs the reward_range of the replay memory')
            lower, upper = realisable_range(reward_range[0], reward_range[1], g)
        if mode in GRAPH_BOUNDS:
            lower = np.maximum(np.asarray(batch.lower_bounds, dtype=np.float64), lower)
        return lower, upper

    def _self_loops(self, batch: Batch) -> torch.Tensor:
        """The batch's non-terminal transitions whose state moved by at most ``self_loop_tol``."""
        moved = np.abs(np.asarray(batch.next_states) - np.asarray(batch.states)).max(axis=1)
        return torch.as_tensor((moved <= self.config.self_loop_tol)
                               & ~np.asarray(batch.terminals, dtype=bool))

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
            y_td = r + self.config.gamma * (1.0 - done) * self._target_q(s2)
            if self.config.self_loop_tol > 0:
                y_td = torch.where(self._self_loops(batch), r / (1.0 - self.config.gamma), y_td)
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
        fitted = critic_loss
        if self.critic2 is not None:
            fitted = fitted + torch.mean((y - self.critic2(s, a)) ** 2)
        for opt in self._critic_opts():
            opt.zero_grad()
        fitted.backward()
        for opt in self._critic_opts():
            opt.step()

        # The actor's loss goes through the critics, whose weights it does not train: frozen
        # for it, their weight gradients are not computed at all (~a tenth of an update; the
        # actor's gradient is the same to the bit).
        critics = [c for c in (self.critic, self.critic2) if c is not None]
        for critic in critics:
            critic.requires_grad_(False)
        try:
            pre_tanh = self.actor[:-1](s)      # the actor without its output tanh
            actor_loss = -self.q(s, torch.tanh(pre_tanh)).mean()
            if self.config.actor_preact_penalty > 0:
                actor_loss = actor_loss + (self.config.actor_preact_penalty
                                           * torch.mean(pre_tanh ** 2))
            self.actor_opt.zero_grad()
            actor_loss.backward()
        finally:
            for critic in critics:
                critic.requires_grad_(True)
        self.actor_opt.step()

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

    def _critic_opts(self) -> list[Adam]:
        return [self.critic_opt] + ([self.critic2_opt] if self.critic2_opt is not None else [])

    def _soft_update(self) -> None:
        tau = self.config.tau
        pairs = [(self.actor, self.actor_target), (self.critic, self.critic_target)]
        if self.critic2 is not None:
            pairs.append((self.critic2, self.critic2_target))
        with torch.no_grad():
            for net, target in pairs:
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
        for optimizer, lr in [(opt, critic_lr) for opt in self._critic_opts()] + [
                (self.actor_opt, actor_lr)]:
            for group in optimizer.param_groups:
                group['lr'] = lr

    def state_dict(self) -> dict:
        state = {'actor': self.actor.state_dict(), 'critic': self.critic.state_dict(),
                 'actor_opt': self.actor_opt.state_dict(),
                 'critic_opt': self.critic_opt.state_dict(), 'train_steps': self.train_steps,
                 'target_noise_rng': self.target_noise_rng.get_state()}
        if self.config.target_networks:
            state['actor_target'] = self.actor_target.state_dict()
            state['critic_target'] = self.critic_target.state_dict()
        if self.critic2 is not None:
            state['critic2'] = self.critic2.state_dict()
            state['critic2_opt'] = self.critic2_opt.state_dict()
            if self.config.target_networks:
                state['critic2_target'] = self.critic2_target.state_dict()
        return copy.deepcopy(state)  # a snapshot: live tensors would keep changing

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state['actor'])
        self.critic.load_state_dict(state['critic'])
        self.actor_opt.load_state_dict(state['actor_opt'])
        self.critic_opt.load_state_dict(state['critic_opt'])
        self.train_steps = state['train_steps']
        if 'target_noise_rng' in state:     # checkpoints from before TD3's smoothing noise had none
            self.target_noise_rng.set_state(state['target_noise_rng'])
        if self.config.target_networks:
            self.actor_target.load_state_dict(state['actor_target'])
            self.critic_target.load_state_dict(state['critic_target'])
        if self.critic2 is not None:
            if 'critic2' not in state:
                raise ValueError('this checkpoint has one critic; ddpg.twin_critics needs two')
            self.critic2.load_state_dict(state['critic2'])
            self.critic2_opt.load_state_dict(state['critic2_opt'])
            if self.config.target_networks:
                self.critic2_target.load_state_dict(state['critic2_target'])
