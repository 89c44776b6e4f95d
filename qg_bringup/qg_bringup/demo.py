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
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path

from qg_common.params import config_file, runs_dir
from qg_learning_node.learner.learner_config import SCHEDULES
from qg_learning_node.learner.training_log import TrainingLog

from qg_bringup.episode_schedule import (
    EpisodeJob,
    EpisodeOutcome,
    robot_name,
    run_episode_by_service,
    run_lanes,
    split_over_robots,
)
from qg_bringup.fleet import fleet_specs, robot_namespace
from qg_bringup.launcher import Launcher, ProcessSpec, load_stack
from qg_bringup.ros_env import install_dir, stack_env

__all__ = ["add_parser", "DemoSettings", "EpisodeOutcome", "StepMonitor", "demo_schedule",
           "run_episode_by_service", "start_stack", "wait_for_stack"]


@dataclass(frozen=True)
class DemoSettings:
    """What the demo changes in the executor and learner (``-p`` ROS arguments).

    Training episodes are capped shorter than the executor's default (a demo should end in
    minutes, and a jammed early episode teaches little after its first tens of steps), and the
    learner runs the grid cell where every QG-DDPG seed inserted all 8 test poses
    (docs/learning.md, section 4).
    :param train_max_steps: step cap of training episodes (the executor's default is 1000).
    :param critic_lr: critic learning rate (the actor's is one tenth).
    :param iterations: training iterations per 20-step cycle (schedule ``cycle``).
    :param schedule: ``cycle`` (the thesis) | ``async`` (train while the robot moves).
    :param updates_per_step: train steps per RL step (schedule ``async``).
    """
    train_max_steps: int = 50
    critic_lr: float = 1e-2
    iterations: int = 50
    schedule: str = "cycle"
    updates_per_step: float = 10.0


@dataclass
class _RobotProgress:
    """What the progress line shows of one robot: its episode and the step it is at."""
    label: str = "idle"
    episode_id: str = ""
    steps: int = 0


class StepMonitor:
    """Follows the running stack for the demo: a progress line per RL step, training scalars.

    :param bar: the tqdm bar (one unit per episode) whose postfix shows the current step.
    :param log: where episode and learner scalars go.
    :param robots: the robots' namespaces ("" = one robot at the root); every robot's
        ``transitions`` move the bar, and with many robots the line shows each one's episode.
    """

    def __init__(self, cli, bar, log: TrainingLog, episodes: int,
                 robots: Sequence[str] = ("",)) -> None:
        from qg_common.topics import LEARNER_DIAGNOSTICS, RELIABLE_DEEP, TRANSITIONS
        from qg_interfaces.msg import LearnerDiagnostics, Transition
        self.bar, self.log, self.episodes = bar, log, episodes
        self.steps = 0
        self.rate_since = time.monotonic()
        self.robots = {robot: _RobotProgress() for robot in robots}
        self.last_return = float("nan")
        self.successes = {"train": [0, 0], "test": [0, 0]}
        self.actor_version = -1
        self.learner_transitions = 0     # as the learner's last heartbeat counts them
        for robot in robots:
            cli.node.create_subscription(Transition, robot_name(robot, TRANSITIONS),
                                         partial(self._on_transition, robot=robot), RELIABLE_DEEP)
        cli.node.create_subscription(LearnerDiagnostics, "/" + LEARNER_DIAGNOSTICS,
                                     self._on_diagnostics, 10)

    @property
    def fps(self) -> float:
        """RL steps per wall second since the first episode started."""
        return self.steps / max(1e-9, time.monotonic() - self.rate_since)

    def begin(self, index: int, mode: str, robot: str = "") -> None:
        if index == 0:
            self.rate_since = time.monotonic()
        self.robots[robot] = _RobotProgress(f"{mode} {index + 1}/{self.episodes}")
        self._show()

    def _on_transition(self, msg, robot: str = "") -> None:
        progress = self.robots[robot]
        if msg.episode_id != progress.episode_id:
            progress.episode_id, progress.steps = msg.episode_id, 0
        self.steps += 1
        progress.steps = int(msg.step) + 1
        self._show()

    def _on_diagnostics(self, msg) -> None:
        self.learner_transitions = int(msg.transitions)
        if int(msg.actor_version) != self.actor_version:      # a new training cycle, not a heartbeat
            self.actor_version = int(msg.actor_version)
            if self.actor_version > 0:
                self.log.training({"critic_loss": msg.critic_loss, "actor_loss": msg.actor_loss,
                                   "mean_q": msg.mean_q,
                                   "frac_raised_lower": msg.frac_raised_lower}, self.steps)

    def end(self, outcome: EpisodeOutcome) -> None:
        done = self.successes[outcome.mode]
        done[0] += int(outcome.success)
        done[1] += 1
        self.last_return = outcome.episode_return
        self.log.episode(outcome.mode, outcome.steps, outcome.success, outcome.episode_return,
                         self.steps, self.fps)
        if len(self.robots) > 1:       # (one robot: the line keeps its last episode)
            self.robots[outcome.robot] = _RobotProgress()
        self.bar.update(1)
        self._show()

    def _where(self) -> str:
        """``train 3/40 step 12``; many robots: each one's, ``r0 train 3/40 step 12, r1 idle``."""
        if list(self.robots) == [""]:
            progress = self.robots[""]
            return f"{progress.label} step {progress.steps}"
        return ", ".join(f"{robot.replace('robot', 'r', 1)} {p.label}"
                         + (f" step {p.steps}" if p.label != "idle" else "")
                         for robot, p in self.robots.items())

    def _show(self) -> None:
        train, test = self.successes["train"], self.successes["test"]
        self.bar.set_postfix_str(
            f"{self._where()} | {self.fps:.1f} steps/s | last return "
            f"{self.last_return:.2f} | inserted: train {train[0]}/{train[1]}"
            + (f", test {test[0]}/{test[1]}" if test[1] else ""))


def wait_for_stack(cli, timeout: float, robots: Sequence[str] = ("",)) -> None:
    """Until every robot answers resets, its executor takes episodes and the learner is alive.

    The start-episode clients are the node's kept ones (``CliNode.client``): the episodes'
    requests then go through clients the executors have long matched.
    """
    from qg_common.topics import LEARNER_DIAGNOSTICS, MOVE_TO_START, START_EPISODE
    from qg_interfaces.msg import LearnerDiagnostics
    from qg_interfaces.srv import MoveToStart, StartEpisode
    heartbeats: list = []
    sub = cli.node.create_subscription(LearnerDiagnostics, "/" + LEARNER_DIAGNOSTICS,
                                       heartbeats.append, 10)
    resets = {robot_name(r, MOVE_TO_START): cli.node.create_client(MoveToStart,
                                                                   robot_name(r, MOVE_TO_START))
              for r in robots}
    clients = {**resets, **{robot_name(r, START_EPISODE):
                            cli.client(StartEpisode, robot_name(r, START_EPISODE)) for r in robots}}
    try:
        ready = cli.spin_until(lambda: all(c.service_is_ready() for c in clients.values())
                               and bool(heartbeats), timeout)
        if not ready:
            missing = [n for n, c in clients.items() if not c.service_is_ready()]
            raise TimeoutError(f"the stack did not come up within {timeout:.0f} s: "
                               f"{', '.join(missing) or 'no learner heartbeat'} missing")
    finally:
        for c in resets.values():
            cli.node.destroy_client(c)
        cli.node.destroy_subscription(sub)


def default_random_bar() -> Path:
    """The simulation's random bar on the report seeds, as ``docs/results.md`` measured it
    (``docs/data/thesis/random_bar.json`` of the checkout this stack was built from)."""
    try:
        return install_dir().parent.parent / "docs" / "data" / "thesis" / "random_bar.json"
    except FileNotFoundError:
        return Path("docs") / "data" / "thesis" / "random_bar.json"


def load_random_bar(path: Path) -> dict | None:
    """``{label, mean, low, high, episodes, seeds}``, or None (with a note) if unreadable."""
    try:
        bar = json.loads(Path(path).read_text())
        return {k: bar[k] for k in ("label", "mean", "low", "high", "episodes", "seeds")}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"[qgl demo] no random bar drawn ({path}: {exc})", file=sys.stderr)
        return None


def _plot(outcomes: list[EpisodeOutcome], path: Path, bar: dict | None,
          robot: str = "the simulated Panda") -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.8))
    for mode, colour in (("train", "tab:blue"), ("test", "tab:green")):
        runs = [o for o in outcomes if o.mode == mode]
        ax.plot([o.index for o in runs], [o.steps for o in runs], "-", color=colour, alpha=0.5)
        for success, marker in ((True, "o"), (False, "x")):
            sel = [o for o in runs if o.success == success]
            ax.plot([o.index for o in sel], [o.steps for o in sel], marker, color=colour,
                    label=f"{mode}, {'inserted' if success else 'not inserted'}")
    if bar is not None:
        ax.axhline(bar["mean"], color="grey", ls="--", lw=1,
                   label=f"random bar: {bar['label']}, {bar['mean']:.1f} steps (sim, "
                         f"{bar['episodes']} episodes on the report seeds)")
        ax.axhspan(bar["low"], bar["high"], color="grey", alpha=0.15, label="its 95 % interval")
    ax.set_xlabel("episode")
    ax.set_ylabel("steps to insert (cap = not inserted)")
    ax.set_title(f"QG-DDPG on {robot}, through the ROS stack")
    ax.grid(alpha=0.3)
    # Below the axes: inside, the legend would hide the first episodes and the bar.
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


#: The executables that load a robot plugin by their ``robot`` parameter.
ROBOT_EXECUTABLES = {("robot_bridge_node", "robot"), ("robot_bridge_node", "bridge"),
                     ("robot_bridge_node", "wrench_estimator"), ("sim_robot_node", "sim")}


def _with_parameters(spec: ProcessSpec, params: dict[str, object]) -> ProcessSpec:
    """``spec`` with ``-p key:=value`` ROS arguments added."""
    if not params:
        return spec
    ros_args = () if "--ros-args" in spec.args else ("--ros-args",)
    extra = tuple(x for key, value in params.items() for x in ("-p", f"{key}:={value}"))
    return replace(spec, args=spec.args + ros_args + extra)


def _with_demo_settings(spec: ProcessSpec, settings: DemoSettings,
                        robot: str | None = None) -> ProcessSpec:
    """The executor's and learner's specs with the demo's overrides, and with ``robot`` the
    robot plugin every process that loads one runs; others unchanged."""
    overrides = {("qg_learning_node", "executor"): {
                     "task.train_max_steps": settings.train_max_steps},
                 ("qg_learning_node", "learner"): {
                     "learner.ddpg.critic_lr": settings.critic_lr,
                     "learner.iterations_per_cycle": settings.iterations,
                     "learner.schedule": settings.schedule,
                     "learner.updates_per_step": float(settings.updates_per_step)}}
    params = dict(overrides.get((spec.package, spec.executable), {}))
    if robot is not None and (spec.package, spec.executable) in ROBOT_EXECUTABLES:
        params["robot"] = robot
    return _with_parameters(spec, params)


def start_stack(run_dir: Path, settings: DemoSettings, config: Path,
                domain_id: str | None = None, robots: int = 1,
                robot: str | None = None, resume: bool = False
                ) -> tuple[Launcher, dict[str, str]]:
    """Start the processes of ``config`` with ``settings`` (``robots`` > 1: that many robots and
    one learner, ``fleet.py``); episodes, checkpoints, logs and ROS logs go under
    ``run_dir``; processes respawn as the stack file says. :param robot: the robot plugin to
    run (``None``: the processes' default). :param resume: the learner starts from the
    checkpoint in ``run_dir`` if there is one (a training run that continues).
    :returns: the launcher (stop it, its ``running`` specs) and the stack's environment."""
    env = stack_env(log_dir=run_dir / "ros_log")
    env["QG_RUNS_DIR"] = str(run_dir)     # episodes/ (MCAP) and checkpoints/ go here
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = domain_id
    specs, policy = load_stack(config)
    launcher = Launcher(env=env, out=None, log_dir=run_dir / "logs", policy=policy)
    specs = [_with_demo_settings(spec, settings, robot) for spec in specs]
    if resume:
        specs = [_with_parameters(s, {"resume": "true"}) if _is_learner(s) else s for s in specs]
    launcher.start(fleet_specs(specs, robots))
    return launcher, env


def _is_learner(spec: ProcessSpec) -> bool:
    return (spec.package, spec.executable) == ("qg_learning_node", "learner")


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


def _summary(outcomes: list[EpisodeOutcome], run_dir: Path, robots: Sequence[str],
             train_wall: float, learner_transitions: int, wall: float,
             codes: dict[str, int]) -> str:
    """The demo's last line: test result, training budget and time, where the outputs are."""
    tests = [o for o in outcomes if o.mode == "test"]
    train = [o for o in outcomes if o.mode == "train"]
    bags = sorted(p.parent.name for p in (run_dir / "episodes").glob("*/metadata.yaml"))
    per_robot = "" if robots == [""] else " (" + ", ".join(
        f"{r} {sum(b.startswith(r + '_') for b in bags)}" for r in robots) + ")"
    return (f"[qgl demo] test: {sum(o.success for o in tests)}/{len(tests)} inserted, mean steps "
            f"{sum(o.steps for o in tests) / max(1, len(tests)):.1f}; training: "
            f"{sum(o.steps for o in train)} RL steps, {sum(o.success for o in train)}/{len(train)} "
            f"inserted, on {len(robots)} robot(s) in {train_wall:.0f} s; the learner received "
            f"{learner_transitions} transitions; {len(bags)} MCAP "
            f"episodes{per_robot} in {run_dir / 'episodes'}; plot "
            f"{run_dir / 'learning_curve.png'}; TensorBoard {run_dir / 'tensorboard'}; "
            f"{wall:.0f} s; exit codes {codes}")


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
    _plot(outcomes, run_dir / "learning_curve.png",
          load_random_bar(args.random_bar or default_random_bar()),
          "the simulated Panda" if args.robot is None else args.robot)
    _render_last_test(outcomes, run_dir)
    print(_summary(outcomes, run_dir, robots, train_wall, learner_transitions,
                   time.monotonic() - started, codes))
    return 0 if all(c == 0 for c in codes.values()) else 1


def _render_last_test(outcomes: list[EpisodeOutcome], run_dir: Path) -> None:
    """The last test episode as a video beside the learning curve (``qgl render``); a demo
    without a renderer or that bag says why and goes on."""
    from qg_bringup.render import render_episode
    tests = [o for o in outcomes if o.mode == "test"]
    if not tests:
        return
    bag = run_dir / "episodes" / tests[-1].episode_id
    try:
        report = render_episode(bag, run_dir / "last_test_episode.mp4")
    except (RuntimeError, ValueError, OSError) as exc:
        print(f"[qgl demo] no video of the last test episode: {exc}", flush=True)
        return
    print(f"[qgl demo] the last test episode ({tests[-1].episode_id}, {tests[-1].steps} steps) "
          f"as a video: {report['out']} ({report['wall_s']:.1f} s to render)", flush=True)


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
