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

from qg_bringup.episode_schedule import EpisodeJob, EpisodeOutcome
from qg_bringup.run_journal import RunJournal, RunMismatch, RunPlan

__all__ = ["add_parser", "run_training", "learner_record", "MAX_ATTEMPTS"]

#: Attempts at one slot cut short before the run stops with the reason (a slot that keeps
#: failing is a fault to look at, not to loop on).
MAX_ATTEMPTS = 5
#: [s] how long a completed episode waits for the learner's checkpoint after it.
CHECKPOINT_WAIT = 60.0
#: [s] how long a run waits for its stack (robot, executor, learner) to come up.
STACK_TIMEOUT = 180.0


def learner_record(run_dir: Path) -> dict[str, Any] | None:
    """The learner's ``learner.json`` in ``run_dir`` (its last checkpoint), None if none."""
    from qg_learning_node.learner_node import CHECKPOINT_INFO_NAME
    path = run_dir / "checkpoints" / CHECKPOINT_INFO_NAME
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


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
            runner = _SlotRunner(cli, launcher, guard, lane, journal, run_dir, label)
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


class _SlotRunner:
    """Runs one slot to completion: again after an attempt cut short, waiting out restarts.

    A slot is complete once its episode ended ``done`` and the learner checkpointed after it.
    If the learner died before that checkpoint, the episode's transitions died with it (the
    restarted learner resumes from the checkpoint before), so the slot runs again; and after
    any restart the next attempt waits until the stack answers again (a learner that is not yet
    subscribed would miss the transitions).
    """

    def __init__(self, cli: Any, launcher: Any, guard: Any, lane: Any, journal: RunJournal,
                 run_dir: Path, label: str) -> None:
        self.cli, self.launcher, self.guard, self.lane = cli, launcher, guard, lane
        self.journal, self.run_dir, self.label = journal, run_dir, label
        self.refusals = 0
        self.deaths: list[str] = []     # restarts seen during the running attempt
        self.restarted = False          # a process came back: wait for the stack to answer
        self.learner_died = False       # during the running attempt or before its checkpoint

    def run(self, job: EpisodeJob) -> None:
        """One attempt at ``job``'s slot: complete in the journal, or cut short (the caller
        runs the slot again).

        :raises RuntimeError: a process stays dead, or the slot keeps failing.
        """
        from qg_bringup.stack_start import wait_for_stack
        self.lane.queue.append(job)
        self.learner_died = False
        while True:
            self._check_processes()
            if self.launcher.restarting():      # not before the stack is whole again
                self.cli.spin_for(0.1)
                continue
            if self.restarted and self.lane.job is None:
                wait_for_stack(self.cli, timeout=STACK_TIMEOUT)
                self.restarted = False
            try:
                outcome = self.lane.advance()
            except RuntimeError as exc:         # refused: a restarted peer not yet discovered
                self.refusals += 1
                if self.refusals > 20:
                    raise
                print(f"[{self.label}] slot {job.index + 1}: {exc}; asking again in 3 s",
                      flush=True)
                self._requeue(job)
                self.cli.spin_for(3.0)
                continue
            if outcome is not None:
                break
            self.cli.executor.spin_once(timeout_sec=0.01)
        self.refusals, deaths, self.deaths = 0, self.deaths, []
        if outcome.state == "done":
            record = self._learner_after(outcome.episode_id)
            if record is not None or not self.learner_died:
                self.journal.complete(outcome, record)
                return
            self._cut(job, outcome.episode_id, "the learner restarted before it checkpointed "
                      "the episode: its transitions are lost", outcome.steps)
            return
        self._cut(job, outcome.episode_id, "; ".join([outcome.message or "aborted", *deaths]),
                  outcome.steps)

    def _check_processes(self) -> None:
        died = self.launcher.poll()
        if died:
            name, code = died[0]
            raise RuntimeError(self.launcher.reasons.get(name, f"process {name} exited with "
                                                               f"code {code}"))
        for death in self.launcher.take_respawns():
            ended = self.guard.process_died(death)
            self.deaths.append(death.reason)
            self.restarted = True
            role = self.guard.roles.get(death.name)
            if role is not None and role.robot is None:
                self.learner_died = True
            print(f"[{self.label}] {death.reason} in {death.delay:.1f} s"
                  + (f"; episode {', '.join(ended)} ended aborted" if ended else ""), flush=True)
            if role is not None and role.executor and self.lane.job is not None \
                    and not self.lane.episode_id:
                # It died before naming the episode: no status will ever end it.
                job = self.lane.forget()
                self._cut(job, "", death.reason)
                self._requeue(job)

    def _requeue(self, job: EpisodeJob) -> None:
        self.lane.forget()
        if not self.lane.queue:
            self.lane.queue.append(job)

    def _cut(self, job: EpisodeJob, episode_id: str, reason: str, steps: int = 0) -> None:
        self.journal.cut(job.index, episode_id, reason, steps)
        attempts = self.journal.attempts(job.index)
        print(f"[{self.label}] slot {job.index + 1} ({job.mode}) cut short ({reason}): "
              f"running it again (attempt {attempts + 1})", flush=True)
        if attempts >= MAX_ATTEMPTS:
            raise RuntimeError(f"slot {job.index + 1} was cut short {attempts} times, last: "
                               f"{reason}")

    def _learner_after(self, episode_id: str) -> dict[str, Any] | None:
        """The learner's record once it has checkpointed after ``episode_id``; None (with a
        warning) if it did not within ``CHECKPOINT_WAIT`` seconds."""
        deadline = time.monotonic() + CHECKPOINT_WAIT
        while time.monotonic() < deadline:
            record = learner_record(self.run_dir)
            if record is not None and record.get("episode_id") == episode_id:
                return record
            self._check_processes()
            if self.learner_died:               # its checkpoint of this episode never comes
                return None
            self.cli.spin_for(0.05)
        print(f"[{self.label}] the learner did not checkpoint after {episode_id} within "
              f"{CHECKPOINT_WAIT:.0f} s; the journal goes on without its count", flush=True)
        return None


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
