"""``qgl demo`` — the main job: the real ROS stack learns the insertion, episode by episode.

Brings the stack up (``config/stack.yaml``), trains QG-DDPG for a few episodes by calling
``/executor/start_episode`` like any client would, tests on the 8 initial poses, and saves a
learning-curve PNG, TensorBoard scalars (``tensorboard/``, Stable-Baselines3's tag names) and
``episodes.json`` next to the MCAP episodes the stack recorded. The progress bar follows
``/transitions``, so it moves at every RL step.
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from qg_common.params import config_file, runs_dir

from qg_learning_node.cli.fleet import fleet_specs
from qg_learning_node.cli.launcher import Launcher, ProcessSpec, load_stack_config
from qg_learning_node.cli.ros_env import stack_env
from qg_learning_node.training_log import TrainingLog

__all__ = ["add_parser", "DemoSettings", "EpisodeOutcome", "StepMonitor",
           "run_episode_by_service", "start_stack", "wait_for_stack"]


@dataclass(frozen=True)
class DemoSettings:
    """What the demo changes in the executor and learner (``-p`` ROS arguments).

    Training episodes are capped shorter than the executor's default (a demo should end in
    minutes, and a jammed early episode teaches little after its first tens of steps), and the
    learner runs the grid cell where every QG-DDPG seed learned (docs/learning.md).
    :param train_max_steps: step cap of training episodes (the executor's default is 1000).
    :param critic_lr: critic learning rate (the actor's is one tenth).
    :param iterations: training iterations per 20-step cycle (schedule ``cycle``).
    :param schedule: ``cycle`` (the thesis) | ``async`` (train while the robot moves).
    :param updates_per_step: train steps per RL step (schedule ``async``).
    """
    train_max_steps: int = 50
    critic_lr: float = 1e-3
    iterations: int = 50
    schedule: str = "cycle"
    updates_per_step: float = 10.0


@dataclass
class EpisodeOutcome:
    """What the executor reported at the end of one episode."""
    index: int
    mode: str
    episode_id: str
    initial_pose: int
    steps: int
    episode_return: float
    success: bool
    wall_time: float


class StepMonitor:
    """Follows the running stack for the demo: a progress line per RL step, training scalars.

    :param bar: the tqdm bar (one unit per episode) whose postfix shows the current step.
    :param log: where episode and learner scalars go.
    """

    def __init__(self, cli, bar, log: TrainingLog, episodes: int) -> None:
        from qg_interfaces.msg import LearnerDiagnostics, Transition

        from qg_common.topics import RELIABLE_DEEP
        self.bar, self.log, self.episodes = bar, log, episodes
        self.steps = 0
        self.started = time.monotonic()
        self.label, self.episode_id = "", ""
        self.episode_steps, self.episode_return, self.last_return = 0, 0.0, float("nan")
        self.successes = {"train": [0, 0], "test": [0, 0]}
        self.actor_version = -1
        cli.node.create_subscription(Transition, "/transitions", self._on_transition,
                                     RELIABLE_DEEP)
        cli.node.create_subscription(LearnerDiagnostics, "/learner/diagnostics",
                                     self._on_diagnostics, 10)

    @property
    def fps(self) -> float:
        """RL steps per wall second since the first episode started."""
        return self.steps / max(1e-9, time.monotonic() - self.started)

    def begin(self, index: int, mode: str) -> None:
        if index == 0:
            self.started = time.monotonic()
        self.label = f"{mode} {index + 1}/{self.episodes}"
        self.episode_steps, self.episode_return = 0, 0.0
        self._show()

    def _on_transition(self, msg) -> None:
        if msg.episode_id != self.episode_id:
            self.episode_id, self.episode_steps, self.episode_return = msg.episode_id, 0, 0.0
        self.steps += 1
        self.episode_steps = int(msg.step) + 1
        self.episode_return += float(msg.reward)
        self._show()

    def _on_diagnostics(self, msg) -> None:
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
        self.bar.update(1)
        self._show()

    def _show(self) -> None:
        train, test = self.successes["train"], self.successes["test"]
        self.bar.set_postfix_str(
            f"{self.label} step {self.episode_steps} | {self.fps:.1f} steps/s | last return "
            f"{self.last_return:.2f} | inserted: train {train[0]}/{train[1]}"
            + (f", test {test[0]}/{test[1]}" if test[1] else ""))


def run_episode_by_service(cli, index: int, mode: str, pose: int, seed: int,
                           timeout: float) -> EpisodeOutcome:
    """Start one episode by ``/executor/start_episode`` and wait for its final status."""
    from qg_interfaces.msg import EpisodeStatus
    from qg_interfaces.srv import StartEpisode

    from qg_learning_node.cli.episode_wait import FINAL_STATES
    from qg_learning_node.cli.ros_client import call_service
    from qg_common.topics import LATCHED

    # Keyed by id: the final status may arrive while the service call is still being answered.
    final: dict[str, EpisodeStatus] = {}

    def on_status(msg: EpisodeStatus) -> None:
        if msg.state in FINAL_STATES:
            final[msg.episode_id] = msg

    sub = cli.node.create_subscription(EpisodeStatus, "/episode_status", on_status, LATCHED)
    t0 = time.monotonic()
    try:
        resp = call_service(cli, StartEpisode, "/executor/start_episode",
                            StartEpisode.Request(mode=mode, initial_pose=pose, seed=seed), 30.0)
        if not resp.success:
            raise RuntimeError(f"StartEpisode refused: {resp.message}")
        if not cli.spin_until(lambda: resp.episode_id in final, timeout):
            raise TimeoutError(f"episode {resp.episode_id} did not end within {timeout:.0f} s")
    finally:
        cli.node.destroy_subscription(sub)
    msg = final[resp.episode_id]
    return EpisodeOutcome(index, mode, msg.episode_id, msg.initial_pose, int(msg.step),
                          float(msg.episode_return), bool(msg.success), time.monotonic() - t0)


def wait_for_stack(cli, timeout: float) -> None:
    """Until the robot answers resets, the executor takes episodes and the learner is alive."""
    from qg_interfaces.msg import LearnerDiagnostics
    from qg_interfaces.srv import ResetSim, StartEpisode
    heartbeats: list = []
    sub = cli.node.create_subscription(LearnerDiagnostics, "/learner/diagnostics",
                                       heartbeats.append, 10)
    clients = {name: cli.node.create_client(srv, name) for name, srv in
               (("/sim/reset", ResetSim), ("/executor/start_episode", StartEpisode))}
    try:
        ready = cli.spin_until(lambda: all(c.service_is_ready() for c in clients.values())
                               and bool(heartbeats), timeout)
        if not ready:
            missing = [n for n, c in clients.items() if not c.service_is_ready()]
            raise TimeoutError(f"the stack did not come up within {timeout:.0f} s: "
                               f"{', '.join(missing) or 'no learner heartbeat'} missing")
    finally:
        for c in clients.values():
            cli.node.destroy_client(c)
        cli.node.destroy_subscription(sub)


def _plot(outcomes: list[EpisodeOutcome], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for mode, colour in (("train", "tab:blue"), ("test", "tab:green")):
        runs = [o for o in outcomes if o.mode == mode]
        ax.plot([o.index for o in runs], [o.steps for o in runs], "-", color=colour, alpha=0.5)
        for success, marker in ((True, "o"), (False, "x")):
            sel = [o for o in runs if o.success == success]
            ax.plot([o.index for o in sel], [o.steps for o in sel], marker, color=colour,
                    label=f"{mode}, {'inserted' if success else 'not inserted'}")
    ax.axhline(32, color="grey", ls="--", lw=1, label="uniform random, real robot (32)")
    ax.set_xlabel("episode")
    ax.set_ylabel("steps to insert (cap = not inserted)")
    ax.set_title("QG-DDPG on the simulated Panda, through the ROS stack")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _with_demo_settings(spec: ProcessSpec, settings: DemoSettings) -> ProcessSpec:
    """The executor's and learner's specs with the demo's overrides; others unchanged."""
    overrides = {("qg_learning_node", "executor"): {
                     "task.train_max_steps": settings.train_max_steps},
                 ("qg_learning_node", "learner"): {
                     "learner.ddpg.critic_lr": settings.critic_lr,
                     "learner.iterations_per_cycle": settings.iterations,
                     "learner.schedule": settings.schedule,
                     "learner.updates_per_step": float(settings.updates_per_step)}}
    params = overrides.get((spec.package, spec.executable))
    if not params:
        return spec
    ros_args = () if "--ros-args" in spec.args else ("--ros-args",)
    extra = tuple(x for key, value in params.items() for x in ("-p", f"{key}:={value}"))
    return replace(spec, args=spec.args + ros_args + extra)


def start_stack(run_dir: Path, settings: DemoSettings, config: Path,
                domain_id: str | None = None,
                robots: int = 1) -> tuple[Launcher, dict[str, str]]:
    """Start the processes of ``config`` with ``settings`` (``robots`` > 1: that many robots and
    one learner, ``cli/fleet.py``); episodes, checkpoints, logs and ROS logs go under
    ``run_dir``. :returns: the launcher (stop it) and the stack's environment."""
    env = stack_env(log_dir=run_dir / "ros_log")
    env["QG_RUNS_DIR"] = str(run_dir)     # episodes/ (MCAP) and checkpoints/ go here
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = domain_id
    launcher = Launcher(env=env, out=None, log_dir=run_dir / "logs")
    launcher.start(fleet_specs([_with_demo_settings(spec, settings)
                                for spec in load_stack_config(config)], robots))
    return launcher, env


def _cmd_demo(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from qg_learning_node.cli.ros_client import CliNode
    run_dir = Path(args.runs_dir or runs_dir()) / time.strftime("demo_%Y%m%d_%H%M%S")
    run_dir.mkdir(parents=True, exist_ok=True)
    settings = DemoSettings(train_max_steps=args.train_max_steps, critic_lr=args.critic_lr,
                            iterations=args.iterations, schedule=args.schedule,
                            updates_per_step=args.updates_per_step)
    launcher, env = start_stack(run_dir, settings,
                                Path(args.config) if args.config else config_file("stack.yaml"))
    schedule = [("train", -1)] * args.train_episodes + [("test", p) for p in range(args.test_poses)]
    outcomes: list[EpisodeOutcome] = []
    log = TrainingLog(run_dir / "tensorboard")
    print(f"[qgl demo] stack up (logs: {run_dir / 'logs'}); {args.train_episodes} training "
          f"episodes, then tests on {args.test_poses} poses; TensorBoard: "
          f"tensorboard --logdir {run_dir / 'tensorboard'}", flush=True)
    started = time.monotonic()
    try:
        with CliNode("qgl_demo", domain_id=int(env["ROS_DOMAIN_ID"])) as cli, \
                tqdm(total=len(schedule), unit="episode", dynamic_ncols=True) as bar:
            wait_for_stack(cli, timeout=180.0)
            monitor = StepMonitor(cli, bar, log, len(schedule))
            for i, (mode, pose) in enumerate(schedule):
                died = launcher.poll()
                if died:
                    raise RuntimeError(f"process {died[0][0]} exited with code {died[0][1]}")
                monitor.begin(i, mode)
                outcome = run_episode_by_service(cli, i, mode, pose, seed=args.seed + i,
                                       timeout=args.episode_timeout)
                outcomes.append(outcome)
                monitor.end(outcome)
            tests = [o for o in outcomes if o.mode == "test"]
            log.evaluation([o.steps for o in tests], [o.success for o in tests], monitor.steps)
    finally:
        codes = launcher.stop()
        log.close()
    (run_dir / "episodes.json").write_text(json.dumps([asdict(o) for o in outcomes], indent=1))
    _plot(outcomes, run_dir / "learning_curve.png")
    tests = [o for o in outcomes if o.mode == "test"]
    bags = sorted(p.parent for p in (run_dir / "episodes").glob("*/metadata.yaml"))
    print(f"[qgl demo] test: {sum(o.success for o in tests)}/{len(tests)} inserted, mean steps "
          f"{sum(o.steps for o in tests) / max(1, len(tests)):.1f}; {len(bags)} MCAP episodes in "
          f"{run_dir / 'episodes'}; plot {run_dir / 'learning_curve.png'}; TensorBoard "
          f"{run_dir / 'tensorboard'}; {time.monotonic() - started:.0f} s; exit codes {codes}")
    return 0 if all(c == 0 for c in codes.values()) else 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    demo = sub.add_parser("demo", help="the main job: train on the ROS stack, test, plot")
    demo.add_argument("--config", default=None,
                      help="stack file (default: the stack.yaml qg_learning_node installs)")
    demo.add_argument("--runs-dir", default=None,
                      help="parent of the run folder (default: $QG_RUNS_DIR, else ./runs)")
    demo.add_argument("--train-episodes", type=int, default=40, help="(thesis: 40)")
    demo.add_argument("--test-poses", type=int, default=8)
    demo.add_argument("--train-max-steps", type=int, default=DemoSettings.train_max_steps,
                      help="step cap of the demo's training episodes (the executor's default "
                           "is 1000, the thesis's)")
    demo.add_argument("--critic-lr", type=float, default=DemoSettings.critic_lr,
                      help="critic learning rate (actor: one tenth)")
    demo.add_argument("--iterations", type=int, default=DemoSettings.iterations,
                      help="training iterations per 20-step cycle (schedule cycle)")
    # (learner_core.SCHEDULES; not imported: it would load torch for every `qgl` command)
    demo.add_argument("--schedule", choices=("cycle", "async"), default=DemoSettings.schedule,
                      help="cycle: train after every 20 steps (the thesis); async: the learner "
                           "trains while the robot moves")
    demo.add_argument("--updates-per-step", type=float, default=DemoSettings.updates_per_step,
                      help="train steps per RL step (schedule async)")
    demo.add_argument("--seed", type=int, default=1)
    demo.add_argument("--episode-timeout", type=float, default=900.0, help="[s]")
    demo.set_defaults(func=_cmd_demo)
