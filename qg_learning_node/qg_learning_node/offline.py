"""Rebuilding the learner's replay memory and Q-Graph from recorded episodes.

The recorded `/transitions` are exactly what the learner received online, in the same order, so
feeding them to a fresh `LearnerCore` with the same configuration reproduces its replay memory
and Q-Graph (and therefore its census) without running the robot; training on them afterwards is
optional. Used by `qgl replay --into-learner` and by analysis scripts.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from qg_recording.bag_reader import read_bag
from tqdm import tqdm

from qg_learning_node.core.episode import TransitionRecord

__all__ = ["OfflineResult", "iter_transitions", "rebuild_from_bags"]

TRANSITIONS_TOPIC = "/transitions"


@dataclass(frozen=True)
class OfflineResult:
    """What a rebuild produced."""

    transitions: int
    episodes: tuple[str, ...]
    census: dict[str, Any]
    train_iterations: int = 0
    diagnostics: dict[str, float] = field(default_factory=dict)  # of the last training cycle
    learner_core: Any = None  # the core that was fed (to checkpoint or keep training)


def iter_transitions(paths: Iterable[Path]) -> Iterator[TransitionRecord]:
    """The recorded transitions of the given bags, bag after bag, in recording order."""
    for path in paths:
        for _, _, _, msg in read_bag(path, topics=[TRANSITIONS_TOPIC]):
            yield TransitionRecord.from_message(msg)


def rebuild_from_bags(
    paths: Iterable[Path],
    learner_core: Any | None = None,
    config: Any | None = None,
    train_iterations: int = 0,
    progress: bool = False,
) -> OfflineResult:
    """Feed every recorded transition to a learner core; optionally train; return the census.

    :param paths: episode bags (directories or .mcap files), fed in this order.
    :param learner_core: a `LearnerCore` to extend; if None, one is built from `config` (default
        `LearnerConfig()`) with the dimensions of the first recorded transition.
    :param train_iterations: train steps after the rebuild, in whole training cycles (rounded up).
    :param progress: show progress bars (per bag, then per training cycle) with rate and ETA.
    :raises ValueError: if the bags hold no transition and no learner core was given.
    """
    from qg_learning_node.learner_core import LearnerConfig, LearnerCore  # torch: only when used

    if train_iterations < 0:
        raise ValueError(f"train_iterations must be >= 0, got {train_iterations}")
    core = learner_core
    count, episodes = 0, []
    if progress:
        paths = tqdm(list(paths), desc="rebuild", unit="bag", dynamic_ncols=True)
    for transition in iter_transitions(paths):
        if core is None:
            core = LearnerCore(config if config is not None else LearnerConfig(),
                               state_dim=transition.state.size, action_dim=transition.action.size)
        core.add_transition(transition.state, transition.action, transition.reward,
                            transition.next_state, transition.terminal)
        count += 1
        if not episodes or episodes[-1] != transition.episode_id:
            episodes.append(transition.episode_id)
    if core is None:
        raise ValueError("the bags hold no /transitions to rebuild from")
    diagnostics: dict[str, float] = {}
    cycles = math.ceil(train_iterations / core.config.iterations_per_cycle) if count else 0
    for _ in tqdm(range(cycles), desc="train", unit="cycle", dynamic_ncols=True,
                  disable=not progress):
        diagnostics = core.train_cycle()
    census = core.graph.census() if core.graph is not None else {}
    return OfflineResult(
        transitions=count, episodes=tuple(dict.fromkeys(episodes)), census=census,
        train_iterations=cycles * core.config.iterations_per_cycle, diagnostics=diagnostics,
        learner_core=core)
