"""``qgl demo`` — the main job: the real ROS stack learns the insertion, episode by episode.

Brings the stack up (``config/stack.yaml``), trains QG-DDPG for a few episodes by calling
``/executor/start_episode`` like any client would, tests on the 8 initial poses, and saves a
learning-curve PNG, TensorBoard scalars (``tensorboard/``, Stable-Baselines3's tag names),
``episodes.json`` and a video of the last test episode (``last_test_episode.mp4``, ``qgl
render``) next to the MCAP episodes the stack recorded. The progress bar follows
``/transitions``, so it moves at every RL step.

``--robot NAME`` runs another robot plugin (``sim_xarm7``) in the same stack.
``--robots N`` brings up N namespaced robots and one learner (``fleet.py``) and deals the
training episodes to them, which run them all at once (``episode_schedule.py``): the same
number of robot steps in less wall time. The tests then run on ``robot0``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path

from qg_common.params import config_file, runs_dir
from qg_learning_node.learner.learner_config import SCHEDULES
from qg_learning_node.learner.training_log import TrainingLog

from qg_bringup.episode_schedule import EpisodeJob, EpisodeOutcome, run_lanes, split_over_robots
from qg_bringup.fleet import robot_namespace
from qg_bringup.run_report import (
    default_random_bar,
    load_random_bar,
    plot_learning_curve,
    render_last_test,
    summary_line,
)
from qg_bringup.stack_start import DemoSettings, start_stack, wait_for_stack
from qg_bringup.step_monitor import StepMonitor

__all__ = ["add_parser", "add_learning_arguments", "demo_schedule"]


def demo_schedule(train_episodes: int, test_poses: int, seed: int,
                  robots: Sequence[str]) -> tuple[dict[str, list[EpisodeJob]], list[EpisodeJob]]:
    """The demo's episodes: training dealt to the robots, then the tests on the first robot.

    Episode ``i`` has seed ``seed + i`` whatever robot runs it. One robot takes the next pose of
    its rotation (as ``qgl episode start`` does); many robots get pose ``i mod 8`` explicitly, so
    the poses of the whole training are the same as with one robot. The tests run one after
    another on one robot: the learner keeps training on test transitions, so running them
    concurrently would test other actors than one robot does.
    """
    from qg_learning_node.executor.episode_request import N_POSES
    train = [EpisodeJob(i, "train", -1 if len(robots) == 1 else i % N_POSES, seed + i)
             for i in range(train_episodes)]
    tests = [EpisodeJob(train_episodes + p, "test", p, seed + train_episodes + p)
             for p in range(test_poses)]
    return split_over_robots(train, robots), tests


def _cmd_demo(args: argparse.Namespace) -> int:
    from qg_common.ros_client import CliNode
    from tqdm import tqdm
    if args.robots < 1:
        print(f"qgl demo: --robots must be >= 1, got {args.robots}", file=sys.stderr)
        return 2
    if args.robots == 1:          # the demo is a training run with the demo's numbers
        return args.one_robot(args)
    if args.run_dir:
        print("qgl demo: --run-dir (a run that continues) is for one robot", file=sys.stderr)
        return 2
    run_dir = Path(args.runs_dir or runs_dir()) / time.strftime("demo_%Y%m%d_%H%M%S")
    run_dir.mkdir(parents=True, exist_ok=True)
    settings = DemoSettings(train_max_steps=args.train_max_steps, critic_lr=args.critic_lr,
                            iterations=args.iterations, schedule=args.schedule,
                            updates_per_step=args.updates_per_step)
    robots = [robot_namespace(k) for k in range(args.robots)] if args.robots > 1 else [""]
    launcher, env = start_stack(run_dir, settings,
                                Path(args.config) if args.config else config_file("stack.yaml"),
                                robots=args.robots, robot=args.robot)
    train, tests = demo_schedule(args.train_episodes, args.test_poses, args.seed, robots)
    outcomes: list[EpisodeOutcome] = []
    log = TrainingLog(run_dir / "tensorboard")
    print(f"[qgl demo] stack up (logs: {run_dir / 'logs'}); {args.train_episodes} training "
          f"episodes" + (f" over {len(robots)} robots at once" if len(robots) > 1 else "")
          + f", then tests on {args.test_poses} poses; TensorBoard: "
          f"tensorboard --logdir {run_dir / 'tensorboard'}", flush=True)

    def check_processes() -> None:
        died = launcher.poll()
        if died:
            raise RuntimeError(f"process {died[0][0]} exited with code {died[0][1]}")

    started = time.monotonic()
    train_wall, learner_transitions = 0.0, 0
    try:
        with CliNode("qgl_demo", domain_id=int(env["ROS_DOMAIN_ID"])) as cli, \
                tqdm(total=args.train_episodes + len(tests), unit="episode",
                     dynamic_ncols=True) as bar:
            wait_for_stack(cli, timeout=180.0, robots=robots)
            monitor = StepMonitor(cli, bar, log, args.train_episodes + len(tests), robots)
            train_started = time.monotonic()
            outcomes += run_lanes(cli, train, monitor, args.episode_timeout, check_processes)
            train_wall = time.monotonic() - train_started
            outcomes += run_lanes(cli, {robots[0]: tests}, monitor, args.episode_timeout,
                                  check_processes)
            done = [o for o in outcomes if o.mode == "test"]
            log.evaluation([o.steps for o in done], [o.success for o in done], monitor.steps)
            # The learner's heartbeat (every 0.5 s) catches up with the last transitions: one
            # per step the episodes report. (Not the steps this monitor has seen: its own
            # subscription may still be a transition behind, as the learner was once.)
            sent = sum(o.steps for o in outcomes)
            cli.spin_until(lambda: monitor.learner_transitions >= sent, 5.0)
            learner_transitions = monitor.learner_transitions
    finally:
        codes = launcher.stop()
        log.close()
    (run_dir / "episodes.json").write_text(json.dumps([asdict(o) for o in outcomes], indent=1))
    plot_learning_curve(outcomes, run_dir / "learning_curve.png",
          load_random_bar(args.random_bar or default_random_bar()),
          "the simulated Panda" if args.robot is None else args.robot)
    render_last_test(outcomes, run_dir)
    print(summary_line(outcomes, run_dir, robots, train_wall, learner_transitions,
                   time.monotonic() - started, codes))
    return 0 if all(c == 0 for c in codes.values()) else 1


def add_learning_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments a run's plan is made of, besides its episodes (``qgl run`` and ``qgl demo``)."""
    parser.add_argument("--config", default=None,
                        help="stack file (default: the stack.yaml qg_learning_node installs)")
    parser.add_argument("--test-poses", type=int, default=8, help="poses per test round")
    parser.add_argument("--train-max-steps", type=int, default=DemoSettings.train_max_steps,
                        help="step cap of training episodes (the executor's default is 1000)")
    parser.add_argument("--critic-lr", type=float, default=DemoSettings.critic_lr,
                        help="critic learning rate (actor: one tenth)")
    parser.add_argument("--iterations", type=int, default=DemoSettings.iterations,
                        help="training iterations per 20-step cycle (schedule cycle)")
    parser.add_argument("--schedule", choices=SCHEDULES, default=DemoSettings.schedule,
                        help="cycle: train after every 20 steps (the thesis); async: the "
                             "learner trains while the robot moves")
    parser.add_argument("--updates-per-step", type=float, default=DemoSettings.updates_per_step,
                        help="train steps per RL step (schedule async)")
    parser.add_argument("--robot", default=None,
                        help="the robot plugin to learn on (e.g. sim_xarm7; default: the "
                             "processes' own, sim_panda)")
    parser.add_argument("--seed", type=int, default=1, help="slot i runs with seed SEED+i")
    parser.add_argument("--episode-timeout", type=float, default=900.0, help="[s]")
    parser.add_argument("--random-bar", type=Path, default=None,
                        help="JSON of the random bar the plot draws (default: the report's)")


def add_parser(sub: argparse._SubParsersAction,
               one_robot: Callable[[argparse.Namespace], int]) -> None:
    """``qgl demo``; ``one_robot`` runs the one-robot demo (a resumable training run,
    ``training_run.run_demo``), passed in so this module does not import the run's."""
    demo = sub.add_parser("demo", help="the main job: train on the ROS stack, test, plot")
    demo.add_argument("--runs-dir", default=None,
                      help="parent of the run folder (default: $QG_RUNS_DIR, else ./runs)")
    demo.add_argument("--run-dir", default=None,
                      help="the run's own folder: an interrupted demo continues there with the "
                           "same command (one robot; `qgl run`)")
    demo.add_argument("--train-episodes", type=int, default=40, help="(thesis: 40)")
    demo.add_argument("--robots", type=int, default=1,
                      help="robots learning at once (namespaces /robot0, /robot1, ... and one "
                           "learner, as `qgl up --robots N`): the training episodes are dealt "
                           "to them and run concurrently; the tests run on robot0")
    add_learning_arguments(demo)
    demo.set_defaults(func=_cmd_demo, one_robot=one_robot)
