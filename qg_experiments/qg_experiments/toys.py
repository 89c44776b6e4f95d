"""Reference problems with known answers: the ch. 7 toy graphs and Baird's star (SPEC §4).

* Ch. 7 toys: offline policy evaluation on a fixed replay memory with ``s' = s + a`` in 2-D,
  reward -1 per step; a 2 x 4 ReLU critic (Xavier init, no target network) trained with TD from
  several seeds. The spread (std across seeds) of the predicted Q-value of a transition measures
  soft divergence; it should grow from directly connected to connected to loose-end/disconnected
  transitions, and along a chain with the distance to the terminal. The transition kinds come from
  the Q-Graph census, so the toys also exercise the graph.
* Baird's 7-state star: expected semi-gradient TD with linear features spirals out; the Q-Graph
  gives every state the lower bound 0 (a self-loop with reward 0 and edges into it), and clipping
  the TD targets at it makes the values converge to 0.

``main()`` writes ``docs/figures/ch7_transition_types.png`` and ``docs/figures/ch7_chain.png``.
"""

from __future__ import annotations

import itertools
import pathlib

import numpy as np
import torch
from qg_learning_node.learner.adam import Adam
from qg_learning_node.learner.qgraph import QGraph

from qg_experiments.figures import pyplot

__all__ = ['ToyTransition', 'baird_star', 'chain_std', 'chain_transitions', 'main', 'plot_chain',
           'plot_transition_types', 'three_state_subsets', 'train_critics', 'transition_type_std']

ToyTransition = tuple[tuple[float, float], tuple[float, float], float, bool]  # s, a, r, terminal

# ch. 7 example I: s0 terminal, four possible transitions (s' = s + a)
_S0, _S1, _S2 = (0.0, 0.0), (-1.0, 1.0), (1.0, 1.0)
_THREE_STATE = [(_S1, (1.0, -1.0), -1.0, True),    # 1 -> 0
                (_S2, (-2.0, 0.0), -1.0, False),   # 2 -> 1
                (_S1, (2.0, 0.0), -1.0, False),    # 1 -> 2
                (_S2, (0.0, 0.0), -1.0, False)]    # 2 -> 2


def _next(s, a) -> tuple[float, float]:
    return (s[0] + a[0], s[1] + a[1])


def three_state_subsets() -> list[list[ToyTransition]]:
    """The 15 non-empty subsets of the four transitions of ch. 7 example I."""
    return [list(c) for k in range(1, 5) for c in itertools.combinations(_THREE_STATE, k)]


def chain_transitions(length: int = 100) -> list[ToyTransition]:
    """One episode s_t = [0, t] -> s_{t-1}, reward -1 per step, s_0 terminal (example II)."""
    return [((0.0, float(t)), (0.0, -1.0), -1.0, t == 1) for t in range(1, length + 1)]


def _graph(transitions: list[ToyTransition], gamma: float) -> QGraph:
    graph = QGraph(gamma)
    for s, a, r, term in transitions:
        graph.add(np.array(s), np.array(a), r, np.array(_next(s, a)), term)
    return graph


def train_critics(datasets: list[list[ToyTransition]], options: dict, seeds: int, steps: int,
                  gamma: float, lr: float = 3e-4) -> list[np.ndarray]:
    """Q-predictions (seeds x transitions, per data set) of 2 x 4 ReLU critics after full-batch
    TD training, all data sets and seeds trained at once as a batch of independent networks.

    :param options: state -> candidate actions of the greedy policy (taken from the full graph,
        so the policy may pick an action the data does not contain, as in DDPG).
    """
    n = max(len(d) for d in datasets)
    width = max(len(v) for v in options.values())
    x = torch.zeros(len(datasets), n, 4)  # (s, a) per data set, padded
    r = torch.zeros(len(datasets), n)
    cont = torch.zeros(len(datasets), n)
    mask = torch.zeros(len(datasets), n)
    x_next = torch.zeros(len(datasets), n, width, 4)  # (s', candidate action)
    valid = torch.zeros(len(datasets), n, width, dtype=torch.bool)
    for d, data in enumerate(datasets):
        for i, (s, a, rew, term) in enumerate(data):
            x[d, i] = torch.tensor(s + a)
            r[d, i], cont[d, i], mask[d, i] = rew, 0.0 if term else 1.0, 1.0
            for j, act in enumerate(options.get(_next(s, a), [])):
                x_next[d, i, j], valid[d, i, j] = torch.tensor(_next(s, a) + act), True
    batch = len(datasets) * seeds  # network k = (data set k // seeds, seed k % seeds)
    expand = lambda v: v.repeat_interleave(seeds, 0)  # noqa: E731
    x, r, cont, mask, valid = expand(x), expand(r), expand(cont), expand(mask), expand(valid)
    x_next = expand(x_next).reshape(batch, n * width, 4)
    params = _xavier_critics(seeds, len(datasets), [4, 4, 4, 1])
    opt = Adam(params, lr=lr)
    for _ in range(steps):
        with torch.no_grad():
            q_next = _forward(params, x_next).reshape(batch, n, width)
            q_next = torch.where(valid, q_next, -torch.inf).max(-1).values
            y = r + gamma * torch.where(cont > 0, q_next, 0.0)  # no bootstrap after terminal
        loss = (((_forward(params, x) - y) ** 2) * mask).sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        q = _forward(params, x).reshape(len(datasets), seeds, n).numpy()
    return [q[d, :, :len(data)] for d, data in enumerate(datasets)]


def _xavier_critics(seeds: int, copies: int, sizes: list[int]) -> list[torch.Tensor]:
    """Per-seed Xavier-uniform weights (seed k identical across the copies), zero biases."""
    params = []
    for layer, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        weights = torch.empty(seeds, n_in, n_out)
        for k in range(seeds):
            torch.nn.init.xavier_uniform_(
                weights[k], generator=torch.Generator().manual_seed(100 * k + layer))
        params += [weights.repeat(copies, 1, 1).requires_grad_(),
                   torch.zeros(seeds * copies, 1, n_out, requires_grad=True)]
    return params


def _forward(params: list[torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    """Batch of independent MLPs: x (networks, n, d) -> (networks, n)."""
    h = x
    for i in range(0, len(params), 2):
        h = h @ params[i] + params[i + 1]
        if i + 2 < len(params):
            h = torch.relu(h)
    return h.squeeze(-1)


def _options(transitions: list[ToyTransition]) -> dict:
    options: dict = {}
    for s, a, _, term in transitions:
        options.setdefault(s, []).append(a)
    return options


def transition_type_std(seeds: int = 10, steps: int = 4000, gamma: float = 0.99
                        ) -> dict[str, list[float]]:
    """Std across seeds of each transition's predicted Q, pooled by kind over the 15 subsets."""
    subsets = three_state_subsets()
    predictions = train_critics(subsets, _options(_THREE_STATE), seeds, steps, gamma)
    pooled: dict[str, list[float]] = {}
    for subset, q in zip(subsets, predictions):
        graph = _graph(subset, gamma)
        for i, (s, a, _, _) in enumerate(subset):
            kind, _ = graph.transition_kind(np.array(s), np.array(a))
            pooled.setdefault(kind, []).append(float(q[:, i].std()))
    return pooled


def chain_std(length: int = 100, seeds: int = 10, steps: int = 4000, gamma: float = 0.99
              ) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the terminal (transitions) and std across seeds of the predicted Q."""
    transitions = chain_transitions(length)
    q, = train_critics([transitions], _options(transitions), seeds, steps, gamma)
    graph = _graph(transitions, gamma)
    dist = np.array([graph.transition_kind(np.array(s), np.array(a))[1]
                     for s, a, _, _ in transitions])
    return dist, q.std(axis=0)


def baird_star(bounded: bool, steps: int = 5000, gamma: float = 0.9, alpha: float = 0.01
               ) -> tuple[np.ndarray, np.ndarray]:
    """Expected semi-gradient TD(0) on Baird's star; returns weight norms and final values.

    Features as in Baird (1995): V(s_i) = w0 + 2 w_i for the six outer states, V(s_7) = 2 w0 + w7;
    all weights start at 1 except w0 = 10; every state moves to s_7, s_7 to itself, reward 0.
    With ``bounded``, TD targets are clipped from below by the Q-Graph bound of each transition.
    """
    features = np.zeros((7, 8))
    features[:6, 0] = 1.0
    features[np.arange(6), np.arange(1, 7)] = 2.0
    features[6, 0], features[6, 7] = 2.0, 1.0
    states = np.eye(7)
    graph = QGraph(gamma)
    for i in range(7):
        graph.add(states[i], np.zeros(1), 0.0, states[6], False)
    lower = graph.lower_bounds(states, np.zeros((7, 1))) if bounded else np.full(7, -np.inf)
    w = np.ones(8)
    w[0] = 10.0
    norms = np.empty(steps)
    for k in range(steps):
        v = features @ w
        target = np.maximum(gamma * v[6], lower)
        w = w + alpha / 7.0 * (target - v) @ features
        norms[k] = np.linalg.norm(w)
    return norms, features @ w


def plot_transition_types(pooled: dict[str, list[float]], path: pathlib.Path) -> None:
    """Box plot of the std across seeds per transition kind (thesis Fig. 7.3)."""
    plt = pyplot()
    order = [k for k in ('directly_connected', 'connected', 'loose_end', 'disconnected')
             if k in pooled]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.boxplot([pooled[k] for k in order], tick_labels=[k.replace('_', ' ') for k in order])
    ax.set_yscale('log')
    ax.set_ylabel('std of predicted Q across seeds')
    ax.set_title('Ch. 7 example I: 15 subsets of the 3-state graph')
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_chain(dist: np.ndarray, std: np.ndarray, path: pathlib.Path, bin_width: int = 10) -> None:
    """Box plots of the std across seeds, binned by distance to the terminal (thesis Fig. 7.4)."""
    plt = pyplot()
    starts = range(0, int(dist.max()) + 1, bin_width)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.boxplot([std[(dist >= lo) & (dist < lo + bin_width)] for lo in starts],
               tick_labels=[f'{lo}-{lo + bin_width - 1}' for lo in starts])
    ax.set_xlabel("transitions from s' to the terminal")
    ax.set_ylabel('std of predicted Q across seeds')
    ax.set_title('Ch. 7 example II: 100-step chain')
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(out_dir: pathlib.Path | None = None) -> None:
    """Run both toys with 10 seeds and Baird's star, print the figures, save the box plots."""
    torch.set_num_threads(1)
    out_dir = out_dir or pathlib.Path('docs') / 'figures'   # run from the repository root
    out_dir.mkdir(parents=True, exist_ok=True)
    pooled = transition_type_std()
    for kind, stds in pooled.items():
        print(f'{kind:20s} n={len(stds):2d} median std {np.median(stds):.4f}')
    plot_transition_types(pooled, out_dir / 'ch7_transition_types.png')
    dist, std = chain_std()
    for lo in range(0, 100, 20):
        print(f'chain distance {lo:2d}-{lo + 19:2d}: median std '
              f'{np.median(std[(dist >= lo) & (dist < lo + 20)]):.3f}')
    plot_chain(dist, std, out_dir / 'ch7_chain.png')
    for bounded in (False, True):
        norms, values = baird_star(bounded)
        print(f'Baird star {"graph-bounded" if bounded else "plain"} TD: weight norm '
              f'{norms[0]:.1f} -> {norms[-1]:.3g}, max |V| {np.abs(values).max():.3g}')


if __name__ == '__main__':
    main()
