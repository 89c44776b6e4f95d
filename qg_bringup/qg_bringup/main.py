"""``qgl`` — the stack's command line: bring it up, run episodes, inspect the graph and bags.

ros2cli, launch and rosbag2 have no wheels here; ``qgl`` covers what the stack needs of them and
stays compatible with a full ROS 2 install (``ros2 run``, ``ros2 service call``).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

from qg_common.params import ConfigError, config_file

from qg_bringup.fleet import fleet_specs
from qg_bringup.launcher import Launcher
from qg_bringup.ros_env import exports, stack_env
from qg_bringup.stack_file import StackConfigError, load_stack, recording_argument, with_recording

__all__ = ["main", "build_parser"]


def _cmd_up(args: argparse.Namespace) -> int:
    from qg_bringup.episode_guard import supervise
    specs, policy = load_stack(Path(args.config) if args.config else config_file("stack.yaml"))
    specs = fleet_specs(with_recording(specs, args.recording), args.robots)
    if args.policy:     # the actor of a policy file, frozen: no learner (policy.py)
        from qg_bringup.policy import frozen_stack
        specs = frozen_stack(specs, Path(args.policy))
    launcher = Launcher(env=stack_env(), log_dir=Path(args.log_dir) if args.log_dir else None,
                        policy=policy)
    stopping = False

    def on_signal(signum: int, frame: object) -> None:
        nonlocal stopping
        stopping = True
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_signal)
    launcher.start(specs)
    print(f"[qgl] started {', '.join(f'{n} (pid {p})' for n, p in launcher.pids().items())}; "
          "Ctrl-C stops all", flush=True)
    try:
        name, code = supervise(launcher, specs)     # restarts what respawns (stack file)
        print(f"[qgl] {launcher.reasons.get(name, f'process {name!r} exited with code {code}')}"
              "; stopping the stack", flush=True)
        launcher.stop()
        return code if code != 0 else 1
    except KeyboardInterrupt:
        codes = launcher.stop()
        bad = {n: c for n, c in codes.items() if c not in (0, -signal.SIGINT)}
        print(f"[qgl] stopped: {codes}", flush=True)
        return 1 if bad else 0


def _cmd_episode(args: argparse.Namespace) -> int:
    import uuid

    from qg_common import topics
    from qg_common.ros_client import RESEND_AFTER, CliNode, call_service
    from qg_interfaces.srv import StartEpisode, StopEpisode

    from qg_bringup.episode_wait import wait_for_episode
    with CliNode() as cli:
        if args.action == "start":
            req = StartEpisode.Request(mode=args.mode, initial_pose=args.initial_pose,
                                       seed=args.seed, reward=args.reward,
                                       request_id=uuid.uuid4().hex)
            service = topics.robot_topic(args.robot, topics.START_EPISODE)
            resp = call_service(cli, StartEpisode, service, req, args.timeout,
                                resend_after=RESEND_AFTER)
        else:
            service = topics.robot_topic(args.robot, topics.STOP_EPISODE)
            resp = call_service(cli, StopEpisode, service, StopEpisode.Request(reason=args.reason),
                                args.timeout)
        print(f"success={resp.success} episode_id={resp.episode_id!r} message={resp.message!r}")
        if resp.success and args.action == "start" and args.wait:
            return wait_for_episode(cli, resp.episode_id, args.timeout_episode, args.robot)
        return 0 if resp.success else 1


def _cmd_nodes(args: argparse.Namespace) -> int:
    from qg_common.ros_client import CliNode
    with CliNode() as cli:
        cli.spin_for(args.wait)
        own = cli.node.get_fully_qualified_name()
        nodes = sorted(name for name in cli.node_names() if name != own)
        print("nodes:")
        for n in nodes:
            print(f"  {n}")
        print("topics:")
        for name, types in sorted(cli.node.get_topic_names_and_types()):
            if name not in ("/rosout", "/parameter_events"):
                print(f"  {name} [{', '.join(types)}]")
        print("services:")
        for name, types in sorted(cli.node.get_service_names_and_types()):
            if not any(name.endswith(s) for s in _PARAM_SERVICES):
                print(f"  {name} [{', '.join(types)}]")
    return 0


_PARAM_SERVICES = ("/describe_parameters", "/get_parameter_types", "/get_parameters",
                   "/list_parameters", "/set_parameters", "/set_parameters_atomically",
                   "/get_type_description")


def _robot_namespace(text: str) -> str:
    """``--robot``: a namespace ROS accepts (refused by argparse with the reason otherwise)."""
    from qg_common import topics
    try:
        topics.robot_topic(text, topics.START_EPISODE)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="qgl", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    up = sub.add_parser("up", help="start the stack's processes; Ctrl-C stops all")
    up.add_argument("--config", default=None,
                    help="stack file listing the processes (default: the stack.yaml that "
                         "qg_learning_node installs, share/qg_learning_node/config)")
    up.add_argument("--log-dir", default=None, help="also write each process's output here")
    up.add_argument("--robots", type=int, default=1,
                    help="N > 1: N robot stacks in the namespaces /robot0../robot<N-1> and one "
                         "learner at the root that learns from all of them (see qg_bringup/fleet.py)")
    up.add_argument("--policy", default=None, metavar="FILE",
                    help="run this policy file's actor frozen (`qgl export-policy`), without "
                         "the learner; a file that does not fit the stack is refused at start")
    up.add_argument("--recording", type=recording_argument, action="append", default=[],
                    metavar="NAME=VALUE", help="a recording.* setting of the recorder: mode="
                    "all|rl_rate|every_k, every_k, keep_last, budget_mb, min_free_mb (repeatable)")
    up.set_defaults(func=_cmd_up)

    ep = sub.add_parser("episode", help="start or stop an episode")
    ep_sub = ep.add_subparsers(dest="action", required=True)
    start = ep_sub.add_parser("start", help="call /executor/start_episode")
    start.add_argument("--mode", default="train", help="train | test")
    start.add_argument("--initial-pose", type=int, default=-1, help="-1 (next) or 0..7")
    start.add_argument("--seed", type=int, default=0)
    start.add_argument("--reward", default="", help="sparse | dense (default: configured)")
    start.add_argument("--wait", action="store_true", help="wait until the episode ends")
    start.add_argument("--timeout-episode", type=float, default=600.0)
    stop = ep_sub.add_parser("stop", help="call /executor/stop_episode")
    stop.add_argument("--reason", default="stopped from qgl")
    for p in (start, stop):
        p.add_argument("--timeout", type=float, default=10.0, help="service timeout [s]")
        p.add_argument("--robot", default="", metavar="NAMESPACE", type=_robot_namespace,
                       help="the robot's namespace under `qgl up --robots N` (robot0, robot1, "
                            "...); default: the robot at the root")
    ep.set_defaults(func=_cmd_episode)

    nodes = sub.add_parser("nodes", help="list discovered nodes, topics and services")
    nodes.add_argument("--wait", type=float, default=2.0, help="discovery time [s]")
    nodes.set_defaults(func=_cmd_nodes)

    # (answered before qgl enters the stack's environment, see main())
    sub.add_parser("env", help='print the stack\'s environment as exports: eval "$(qgl env)"')

    from qg_bringup import demo, policy, render, train, training_run
    demo.add_parser(sub, one_robot=training_run.run_demo)
    training_run.add_parser(sub)
    policy.add_parser(sub)
    train.add_parser(sub)
    render.add_parser(sub)
    try:
        from qg_bringup import bag_commands
    except ImportError:
        bag_commands = None
    if bag_commands is not None:
        bag_commands.add_parsers(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # A shell starts a background job with SIGINT ignored, and its children inherit that: qgl
    # stops on Ctrl-C (SIGINT) however it was started, and so do the processes it starts.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    if argv == ["env"]:      # what a shell lacks to run the stack's Python (benchmarks, nodes)
        try:
            print(exports())
        except FileNotFoundError as exc:
            print(f"qgl: {exc}", file=sys.stderr)
            return 2
        return 0
    if os.environ.get("QG_STACK_ENV") != "1":
        # Type support of our interfaces needs LD_LIBRARY_PATH before Python starts.
        try:
            env = stack_env()
        except FileNotFoundError as exc:
            print(f"qgl: {exc}", file=sys.stderr)
            return 2
        os.execve(sys.executable, [sys.executable, "-m", "qg_bringup.main", *argv], env)
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (StackConfigError, ConfigError, TimeoutError, FileNotFoundError, RuntimeError) as exc:
        print(f"qgl: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
