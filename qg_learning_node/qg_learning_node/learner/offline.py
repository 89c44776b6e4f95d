"""Rebuilding the learner's replay memory and Q-Graph from recorded episodes.

The recorded `/transitions` are exactly what the learner received online, in the same order, so
feeding them to a fresh `LearnerCore` with the same configuration reproduces its replay memory
and Q-Graph (and therefore its census) without running the robot; training on them afterwards is
optional. Used by `qgl replay --into-learner` and by analysis scripts.

Under many robots (`qgl up --robots N`) each robot records its own episodes, and the one
learner received the robots' transitions interleaved, each tagged with its robot, which keeps
one trajectory chain per robot in replay memory. The rebuild does the same: the robot of a bag
is the one its episode id names (`robot1_...`, `executor/episode_id.py`; "" for a robot at the
root), each robot's bags are read one after another in the order given, and the robots' streams
are merged by recorded log time, so the rebuilt memory interleaves them as the learner's did and
links each step only to its own robot's previous one. A bag's log time is its robot's loop
clock: the wall clock in realtime mode, that robot's simulated time in lockstep, where the
merged order across robots is therefore approximate (each robot's own order is exact; its
chains and the Q-Graph do not depend on how the robots interleave, unless a bounded replay
memory evicts by arrival order).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from qg_recording.bag_reader import read_bag
from tqdm import tqdm

from qg_learning_node.executor.episode import TransitionRecord
from qg_learning_node.executor.episode_id import robot_of_episode

__all__ = ["OfflineResult", "iter_transitions", "robot_transitions", "rebuild_from_bags"]

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
    robots: dict[str, int] = field(default_factory=dict)  # robot ("" = the root) -> transitions


def iter_transitions(paths: Iterable[Path]) -> Iterator[TransitionRecord]:
    """The recorded transitions of the given bags, bag after bag, in recording order."""
    for path in paths:
        for _, transition in _logged(path):
            yield transition


def _logged(path: Path) -> Iterator[tuple[int, TransitionRecord]]:
    for _, _, t_ns, msg in read_bag(path, topics=[TRANSITIONS_TOPIC]):
        yield t_ns, TransitionRecord.from_message(msg)


def _bag_robot(path: Path) -> str | None:
    """The robot that recorded ``path`` (from its first transition); None if it has none."""
    stream = _logged(path)
    try:
        first = next(stream, None)
    finally:
        stream.close()
    return None if first is None else robot_of_episode(first[1].episode_id)


def robot_transitions(paths: Iterable[Path], on_bag_done: Any = None
                      ) -> Iterator[tuple[str, TransitionRecord]]:
    """(robot, transition) of the given bags in the order one learner of all their robots
    received them (see the module docstring): each robot's bags one after another in the given
    order, the robots merged by recorded log time. One robot: exactly bag after bag.

    :param on_bag_done: called with no argument once per bag when it has been read (progress).
    """
    done = on_bag_done or (lambda: None)
    by_robot: dict[str, list[Path]] = {}
    for path in paths:
        robot = _bag_robot(path)
        if robot is None:
            done()
        else:
            by_robot.setdefault(robot, []).append(path)

    def stream(robot: str, bags: list[Path]) -> Iterator[tuple[int, str, TransitionRecord]]:
        for bag in bags:
            for t_ns, transition in _logged(bag):
                yield t_ns, robot, transition
            done()

    merged = heapq.merge(*(stream(robot, bags) for robot, bags in by_robot.items()),
                         key=lambda item: item[0])
    for _, robot, transition in merged:
        yield robot, transition


def rebuild_from_bags(
    paths: Iterable[Path],
    learner_core: Any | None = None,
    config: Any | None = None,
    train_iterations: int = 0,
    progress: bool = False,
) -> OfflineResult:
    """Feed every recorded transition to a learner core; optionally train; return the census.

    :param paths: episode bags (directories or .mcap files), fed in this order, each robot's
        in this order and the robots' interleaved by log time (``robot_transitions``).
    :param learner_core: a `LearnerCore` to extend; if None, one is built from `config` (default
        `LearnerConfig()`) with the dimensions of the first recorded transition.
    :param train_iterations: train steps after the rebuild, in whole training cycles (rounded up).
    :param progress: show progress bars (per bag, then per training cycle) with rate and ETA.
    :raises ValueError: if the bags hold no transition and no learner core was given.
    """
    # torch: only when used
    from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore

    if train_iterations < 0:
        raise ValueError(f"train_iterations must be >= 0, got {train_iterations}")
    core = learner_core
    count, episodes, robots = 0, [], {}
    paths = list(paths)
    bar = tqdm(total=len(paths), desc="rebuild", unit="bag", dynamic_ncols=True,
               disable=not progress)
    with bar:
        for robot, transition in robot_transitions(paths, on_bag_done=lambda: bar.update(1)):
            if core is None:
                core = LearnerCore(config if config is not None else LearnerConfig(),
                                   state_dim=transition.state.size,
                                   action_dim=transition.action.size)
            core.add_transition(transition.state, transition.action, transition.reward,
                                transition.next_state, transition.terminal, robot=robot)
            count += 1
            robots[robot] = robots.get(robot, 0) + 1
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
        learner_core=core, robots=robots)
