"""``qgl run`` — a training run through the stack that continues where it stopped.

``qgl run --episodes N [--test-every K] --run-dir DIR`` brings the stack up with its learner's
checkpoint in ``DIR`` and runs the run's schedule (``run_journal.py``) one slot after
another by ``/executor/start_episode``; the journal in ``DIR`` notes each completed slot once
the learner has checkpointed after it. The same command on the same folder, after a Ctrl-C, a
crash or a reboot, continues at the first slot not completed, with the learner resumed from
its checkpoint: no slot is repeated or skipped, and the learner holds the completed episodes'
transitions and no others (it does not checkpoint an aborted episode).

A process of the stack that dies is restarted by the launcher (the stack file's ``respawn``);
the episode it cut short ends ``aborted`` with the reason (``episode_guard.py``) and its
slot runs again. ``qgl demo`` is this command with the demo's numbers.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from qg_common.params import config_file, runs_dir

from qg_bringup.episode_schedule import EpisodeOutcome
from qg_bringup.run_journal import RunJournal, RunMismatch, RunPlan
from qg_bringup.slot_runner import STACK_TIMEOUT, SlotRunner, learner_record

__all__ = ["add_parser", "run_training"]

class _RunObserver:
    """The lane's observer: the journal hears which episode a slot runs, the progress bar and
    training log only the completed ones."""

    def __init__(self, journal: RunJournal, monitor: Any) -> None:
        self.journal, self.monitor = journal, monitor

    def begin(self, index: int, mode: str, robot: str = "") -> None:
        self.monitor.begin(index, mode, robot)

    def started(self, index: int, episode_id: str, robot: str = "") -> None:
        self.journal.started(index, episode_id)

    def end(self, outcome: EpisodeOutcome) -> None:
        if outcome.state == "done":
            self.monitor.end(outcome)


class _Stopped(Exception):
    """SIGTERM: stop as on Ctrl-C."""


def run_training(run_dir: Path, plan: RunPlan, settings: Any, config: Path,
                 episode_timeout: float = 900.0, random_bar: Path | None = None,
                 label: str = "qgl run") -> int:
    """Run (or continue) the run in ``run_dir``; 0 once its schedule is complete, 130 when
    stopped by Ctrl-C/SIGTERM (the same call continues it), 1 if the stack failed."""
    from qg_common.ros_client import CliNode
    from qg_learning_node.learner.training_log import TrainingLog
    from tqdm import tqdm

    from qg_bringup.episode_guard import EpisodeGuard, process_roles
    from qg_bringup.episode_schedule import Lane
    from qg_bringup.stack_start import start_stack, wait_for_stack
    from qg_bringup.step_monitor import StepMonitor
    journal = RunJournal.open(run_dir, plan)
    resumed = bool(journal.sessions)
    if resumed:
        note = journal.reconcile(learner_record(run_dir))
        print(f"[{label}] continuing {run_dir} at slot {journal.next_slot + 1}/"
              f"{len(journal.slots)} ({note})", flush=True)
    if journal.finished:
        print(f"[{label}] {run_dir}: all {len(journal.slots)} slots are complete", flush=True)
        return _finish(journal, run_dir, plan, random_bar, 0.0, None, {}, label, render=False)
    journal.begin_session("resumed" if resumed else "started")

    def on_sigterm(signum: int, frame: object) -> None:
        raise _Stopped

    previous = signal.signal(signal.SIGTERM, on_sigterm)
    launcher, env = start_stack(run_dir, settings, config, robot=plan.robot, resume=True)
    specs = [r.spec for r in launcher.running]
    log = TrainingLog(run_dir / "tensorboard")
    started = time.monotonic()
    learner_transitions: int | None = None
    stopped = False
    print(f"[{label}] stack up (logs: {run_dir / 'logs'}); {plan.episodes} training episodes"
          f"{f', a test round every {plan.test_every}' if plan.test_every else ''}, tests on "
          f"{plan.test_poses} poses; slots {journal.next_slot + 1}..{len(journal.slots)} to run;"
          f" journal {run_dir / 'journal.json'}", flush=True)
    try:
        with CliNode("qgl_run", domain_id=int(env["ROS_DOMAIN_ID"])) as cli, \
                tqdm(total=len(journal.slots), initial=journal.next_slot, unit="episode",
                     dynamic_ncols=True) as bar:
            wait_for_stack(cli, timeout=STACK_TIMEOUT)
            monitor = StepMonitor(cli, bar, log, len(journal.slots))
            monitor.steps = journal.steps()
            guard = EpisodeGuard(cli, process_roles(specs))
            lane = Lane(cli, "", [], _RunObserver(journal, monitor), episode_timeout)
            runner = SlotRunner(cli, launcher, guard, lane, journal, run_dir, label)
            while not journal.finished:
                runner.run(journal.slots[journal.next_slot])
            sent = journal.steps()
            cli.spin_until(lambda: monitor.learner_transitions >= sent, 5.0)
            learner_transitions = monitor.learner_transitions
            tests = [o for o in journal.outcomes() if o.mode == "test"]
            log.evaluation([o.steps for o in tests], [o.success for o in tests], monitor.steps)
    except (KeyboardInterrupt, _Stopped):
        stopped = True
    finally:
        codes = launcher.stop()
        log.close()
        signal.signal(signal.SIGTERM, previous)
    if stopped:
        _write_outcomes(journal, run_dir)
        print(f"[{label}] stopped at slot {journal.next_slot + 1}/{len(journal.slots)} "
              f"({sum(o['mode'] == 'train' for o in journal.completed)}/{plan.episodes} "
              f"training episodes complete); the same command continues it", flush=True)
        return 130
    return _finish(journal, run_dir, plan, random_bar, time.monotonic() - started,
                   learner_transitions, codes, label)


def _write_outcomes(journal: RunJournal, run_dir: Path) -> list[EpisodeOutcome]:
    outcomes = journal.outcomes()
    (run_dir / "episodes.json").write_text(json.dumps([asdict(o) for o in outcomes], indent=1))
    return outcomes


def _finish(journal: RunJournal, run_dir: Path, plan: RunPlan, random_bar: Path | None,
            wall: float, learner_transitions: int | None, codes: dict[str, int],
            label: str, render: bool = True) -> int:
    """The completed run's outputs: episodes.json, the plot, the last test's video, a summary."""
    from qg_bringup.run_report import (
        default_random_bar,
        load_random_bar,
        plot_learning_curve,
        render_last_test,
    )
    outcomes = _write_outcomes(journal, run_dir)
    plot_learning_curve(outcomes, run_dir / "learning_curve.png",
                        load_random_bar(random_bar or default_random_bar()),
                        "the simulated Panda" if plan.robot is None else plan.robot)
    if render:
        render_last_test(outcomes, run_dir)
    tests = [o for o in outcomes if o.mode == "test"]
    train = [o for o in outcomes if o.mode == "train"]
    record = learner_record(run_dir) or {}
    bags = len(list((run_dir / "episodes").glob("*/metadata.yaml")))
    print(f"[{label}] test: {sum(o.success for o in tests)}/{len(tests)} inserted, mean steps "
          f"{sum(o.steps for o in tests) / max(1, len(tests)):.1f}; training: "
          f"{sum(o.steps for o in train)} RL steps, {sum(o.success for o in train)}/{len(train)} "
          f"inserted; the learner received "
          f"{learner_transitions if learner_transitions is not None else '?'} transitions, its "
          f"checkpoint holds {record.get('transitions', '?')} (completed episodes: "
          f"{journal.steps()} steps); {len(journal.cut_short)} attempt(s) cut short and rerun, "
          f"{len(journal.sessions)} session(s); {bags} MCAP episodes in {run_dir / 'episodes'}; "
          f"plot {run_dir / 'learning_curve.png'}; TensorBoard {run_dir / 'tensorboard'}; "
          f"{wall:.0f} s; exit codes {codes}", flush=True)
    return 0 if all(c == 0 for c in codes.values()) else 1


def plan_from_args(args: argparse.Namespace, episodes: int, test_every: int) -> tuple[RunPlan, Any,
                                                                                       Path]:
    """The run's plan, learning settings and stack file from ``qgl run``/``qgl demo``'s
    arguments."""
    from qg_bringup.stack_start import DemoSettings
    settings = DemoSettings(train_max_steps=args.train_max_steps, critic_lr=args.critic_lr,
                            iterations=args.iterations, schedule=args.schedule,
                            updates_per_step=args.updates_per_step)
    config = Path(args.config).resolve() if args.config else config_file("stack.yaml")
    plan = RunPlan(episodes=episodes, test_every=test_every, test_poses=args.test_poses,
                   seed=args.seed, settings=asdict(settings), stack=str(config),
                   robot=args.robot)
    return plan, settings, config


def _cmd_run(args: argparse.Namespace) -> int:
    try:
        run_dir = Path(args.run_dir) if args.run_dir else \
            runs_dir() / time.strftime("run_%Y%m%d_%H%M%S")
        if args.recording:   # the run's own stack file: a continued run records alike
            from qg_bringup.stack_file import stack_with_recording
            stack = Path(args.config).resolve() if args.config else config_file("stack.yaml")
            args.config = str(stack_with_recording(stack, args.recording,
                                                   run_dir / "stack_recording.yaml"))
        plan, settings, config = plan_from_args(args, args.episodes, args.test_every)
        return run_training(run_dir, plan, settings, config, args.episode_timeout,
                            args.random_bar)
    except (ValueError, RunMismatch) as exc:
        print(f"qgl run: {exc}", file=sys.stderr)
        return 2


def run_demo(args: argparse.Namespace) -> int:
    """``qgl run`` with the demo's numbers (``training_run.py``): in a new
    ``<runs>/demo_<time>`` folder, or continuing the one ``--run-dir`` names."""
    try:
        plan, settings, config = plan_from_args(args, args.train_episodes, 0)
        run_dir = Path(args.run_dir) if args.run_dir else \
            Path(args.runs_dir or runs_dir()) / time.strftime("demo_%Y%m%d_%H%M%S")
        return run_training(run_dir, plan, settings, config, args.episode_timeout,
                                         args.random_bar, label="qgl demo")
    except (ValueError, RunMismatch) as exc:
        print(f"qgl demo: {exc}", file=sys.stderr)
        return 2


def add_parser(sub: argparse._SubParsersAction) -> None:
    run = sub.add_parser("run", help="a training run through the stack that the same command "
                                     "continues after Ctrl-C, a crash or a reboot")
    run.add_argument("--episodes", type=int, required=True, help="training episodes (N)")
    run.add_argument("--test-every", type=int, default=0,
                     help="a test round after every K training episodes (0: only at the end)")
    run.add_argument("--run-dir", default=None,
                     help="the run's folder; an existing one is continued (default: a new "
                          "<runs>/run_<time>)")
    from qg_bringup.demo import add_learning_arguments
    from qg_bringup.stack_file import recording_argument
    add_learning_arguments(run)
    run.add_argument("--recording", type=recording_argument, action="append", default=[],
                     metavar="NAME=VALUE", help="a recording.* setting of the recorder (as "
                     "`qgl up --recording`); kept in the run's stack file")
    run.set_defaults(func=_cmd_run)
