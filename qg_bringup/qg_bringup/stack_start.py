"""The stack brought up for a run: its processes with the run's learning settings, and the wait
until every part answers.

``qgl demo``, ``qgl run`` and the benchmarks start the processes of a stack file (``launcher``)
with a run's overrides (the executor's step cap, the learner's rate, iterations and schedule, the
robot plugin) and the run folder as where episodes, checkpoints and logs go.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cache
from importlib.metadata import entry_points
from pathlib import Path

from qg_common.plugins import ROBOT_PLUGIN_GROUP, registering_packages

from qg_bringup.episode_schedule import robot_name
from qg_bringup.fleet import fleet_specs
from qg_bringup.launcher import Launcher
from qg_bringup.ros_env import stack_env
from qg_bringup.stack_file import ProcessSpec, load_stack

__all__ = ["DemoSettings", "robot_executables", "with_parameters",
           "with_run_settings", "start_stack", "is_learner", "wait_for_stack"]

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


#: The bridge's executables, which load a robot plugin by their ``robot`` parameter.
BRIDGE_EXECUTABLES = {("robot_bridge_node", "robot"), ("robot_bridge_node", "bridge"),
                      ("robot_bridge_node", "wrench_estimator")}


@cache
def robot_executables() -> frozenset[tuple[str, str]]:
    """The executables that load a robot plugin by their ``robot`` parameter: the bridge's, and
    the ``sim`` node of every package that registers robots (found in the plugin registry)."""
    simulators = {(ep.dist.name, ep.name) for ep in entry_points(group="console_scripts")
                  if ep.name == "sim" and ep.dist is not None}
    robots = registering_packages(ROBOT_PLUGIN_GROUP)
    return frozenset(BRIDGE_EXECUTABLES | {(package, name) for package, name in simulators
                                           if package in robots})


def with_parameters(spec: ProcessSpec, params: dict[str, object]) -> ProcessSpec:
    """``spec`` with ``-p key:=value`` ROS arguments added."""
    if not params:
        return spec
    ros_args = () if "--ros-args" in spec.args else ("--ros-args",)
    extra = tuple(x for key, value in params.items() for x in ("-p", f"{key}:={value}"))
    return replace(spec, args=spec.args + ros_args + extra)


def with_run_settings(spec: ProcessSpec, settings: DemoSettings,
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
    if robot is not None and (spec.package, spec.executable) in robot_executables():
        params["robot"] = robot
    return with_parameters(spec, params)


def start_stack(run_dir: Path, settings: DemoSettings, config: Path,
                domain_id: str | None = None, robots: int = 1,
                robot: str | None = None, resume: bool = False
                ) -> tuple[Launcher, dict[str, str]]:
    """Start the processes of ``config`` with ``settings`` (``robots`` > 1: that many robots and
    one learner, ``fleet.py``); episodes, checkpoints, logs and ROS logs go under
    ``run_dir``; processes respawn as the stack file says. :param robot: the robot plugin to
    run (``None``: the processes' default). :param resume: the learner starts from the
    checkpoint in ``run_dir`` if there is one (a training run that continues), and the
    logs of the run's earlier sessions are kept (appended to).
    :returns: the launcher (stop it, its ``running`` specs) and the stack's environment."""
    env = stack_env(log_dir=run_dir / "ros_log")
    env["QG_RUNS_DIR"] = str(run_dir)     # episodes/ (MCAP) and checkpoints/ go here
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = domain_id
    specs, policy = load_stack(config)
    launcher = Launcher(env=env, out=None, log_dir=run_dir / "logs", policy=policy,
                        append_logs=resume)
    specs = [with_run_settings(spec, settings, robot) for spec in specs]
    if resume:
        specs = [with_parameters(s, {"resume": "true"}) if is_learner(s) else s for s in specs]
    launcher.start(fleet_specs(specs, robots))
    return launcher, env


def is_learner(spec: ProcessSpec) -> bool:
    return (spec.package, spec.executable) == ("qg_learning_node", "learner")


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
