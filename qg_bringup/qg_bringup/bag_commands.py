"""`qgl info`, `qgl replay` and `qgl bag reindex`: what rosbag2's `ros2 bag info/play/reindex`
do, for our episode bags.

`replay --into-learner` does not publish: it rebuilds replay memory and Q-Graph from the recorded
transitions (see `qg_learning_node.learner.offline`), prints the graph census and can train and save
a learner checkpoint. rclpy and torch are imported only by the subcommand that needs them, so
`qgl info` works without a ROS environment.
"""

from __future__ import annotations

import argparse
import datetime
import sys
from pathlib import Path

import yaml
from qg_common.params import config_file
from qg_recording.bag_reader import BagInfo, NotABagError, bag_files, bag_info
from qg_recording.rosbag2_metadata import METADATA_FILE

__all__ = ["add_parsers", "cmd_info", "cmd_reindex", "cmd_replay", "expand_bag_paths", "format_info"]


def _fail(command: str, message: str) -> int:
    print(f"qgl {command}: {message}", file=sys.stderr)
    return 2


def expand_bag_paths(path: Path) -> list[Path]:
    """A bag (directory or .mcap file), or a runs folder: its episode bags by start time.

    :raises FileNotFoundError: if the path does not exist.
    :raises NotABagError: if it is neither a bag nor a folder of bags.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such bag: {path}")
    if path.is_dir() and not (path / METADATA_FILE).exists() and not any(path.glob("*.mcap")):
        episodes = [p for p in sorted(path.iterdir())
                    if p.is_dir() and ((p / METADATA_FILE).exists() or any(p.glob("*.mcap")))]
        if episodes:
            return sorted(episodes, key=lambda p: (bag_info(p).start_ns, p.name))
    bag_files(path)  # raises for anything that is not a bag
    return [path]


def _stamp(t_ns: int) -> str:
    when = datetime.datetime.fromtimestamp(t_ns * 1e-9, tz=datetime.UTC)
    return f"{when:%b %d %Y %H:%M:%S}.{(t_ns // 1_000_000) % 1000:03d} UTC ({t_ns // 10**9}.{t_ns % 10**9:09d})"


def format_info(info: BagInfo) -> str:
    """`ros2 bag info`-style text."""
    lines = [
        f"Files:             {', '.join(f.name for f in info.files)}",
        f"Bag size:          {info.size_bytes / 2**20:.2f} MiB",
        "Storage id:        mcap",
        f"Duration:          {info.duration_ns * 1e-9:.3f}s",
        f"Start:             {_stamp(info.start_ns)}",
        f"End:               {_stamp(info.end_ns)}",
        f"Messages:          {info.message_count}",
    ]
    for i, topic in enumerate(info.topics):
        head = "Topic information: " if i == 0 else " " * 19
        lines.append(f"{head}Topic: {topic.name} | Type: {topic.type_name} | Count: {topic.message_count} "
                     "| Serialization Format: cdr")
    if info.complete:
        lines.append("Closed cleanly:    yes")
    else:
        lines.append("Closed cleanly:    no (no MCAP summary: the recorder was killed; counted by scanning;"
                     " `qgl bag reindex` repairs it for other readers)")
    if not info.has_metadata and info.path.is_dir():
        lines.append(f"Warning:           no {METADATA_FILE} (ros2 bag will not open this directory)")
    return "\n".join(lines)


def cmd_info(args: argparse.Namespace) -> int:
    try:
        info = bag_info(Path(args.path))
    except (FileNotFoundError, NotABagError) as exc:
        return _fail("info", str(exc))
    print(format_info(info))
    return 0


def cmd_reindex(args: argparse.Namespace) -> int:
    from qg_recording.reindex import reindex

    try:
        result = reindex(Path(args.path))
    except (FileNotFoundError, NotABagError) as exc:
        return _fail("bag reindex", str(exc))
    for file in result.files:
        state = "repaired (had no summary)" if file in result.repaired else "complete"
        print(f"{file}: {state}")
    print(f"{result.messages} messages; {METADATA_FILE} regenerated" if Path(args.path).is_dir()
          else f"{result.messages} messages")
    return 0


def _learner_config(path: str) -> object:
    """The learner's LearnerConfig from a parameter file like config/learner.yaml (its
    `learner` section under `ros__parameters`) or a plain mapping of LearnerConfig fields."""
    from qg_learning_node.learner.learner_params import learner_config_from_params

    data = yaml.safe_load(Path(path).read_text()) or {}
    if isinstance(data, dict) and len(data) == 1:
        (only,) = data.values()
        if isinstance(only, dict) and "ros__parameters" in only:
            data = only["ros__parameters"]
    if isinstance(data, dict) and isinstance(data.get("learner"), dict):
        data = data["learner"]
    return learner_config_from_params(data)


def _into_learner(args: argparse.Namespace, paths: list[Path]) -> int:
    from qg_learning_node.learner.offline import rebuild_from_bags

    try:
        config = _learner_config(args.learner_config or str(config_file("learner.yaml")))
        result = rebuild_from_bags(paths, config=config, train_iterations=args.train_iterations,
                                   progress=True)
    except (ValueError, FileNotFoundError) as exc:
        return _fail("replay", str(exc))
    print(f"transitions: {result.transitions} from {len(result.episodes)} episode(s) in {len(paths)} bag(s)")
    if set(result.robots) != {""}:     # bags of several robots (or of one namespaced robot)
        print("robots: " + ", ".join(f"{robot or '(root)'} {n} transitions"
                                      for robot, n in result.robots.items())
              + " (one trajectory chain each, merged by log time)")
    census = {k: v for k, v in result.census.items() if k != "path_length_histogram"}
    print(f"graph census: {census}")
    if result.census.get("path_length_histogram"):
        print(f"path lengths to the goal (connected): {result.census['path_length_histogram']}")
    if result.train_iterations:
        print(f"trained {result.train_iterations} iterations; last cycle: "
              + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                          for k, v in result.diagnostics.items()))
    if args.save_checkpoint:
        result.learner_core.save(Path(args.save_checkpoint))
        print(f"checkpoint: {args.save_checkpoint}")
    return 0


def _publish(args: argparse.Namespace, paths: list[Path]) -> int:
    import rclpy
    from qg_recording.player import play

    rclpy.init()
    try:
        for path in paths:
            result = play(path, rate=args.rate, topics=args.topics, start_delay_s=args.start_delay,
                          wait_for_subscribers_s=args.wait_for_subscribers)
            print(f"{path}: published {result.messages} messages in {result.wall_s:.3f} s "
                  f"(recorded span {result.bag_duration_s:.3f} s, rate {args.rate:g})", flush=True)
    except KeyboardInterrupt:
        return 130
    finally:
        rclpy.try_shutdown()
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    if args.rate <= 0.0:
        return _fail("replay", f"--rate must be positive, got {args.rate}")
    if args.train_iterations < 0:
        return _fail("replay", f"--train-iterations must be >= 0, got {args.train_iterations}")
    try:
        paths = [p for path in args.paths for p in expand_bag_paths(Path(path))]
    except (FileNotFoundError, NotABagError) as exc:
        return _fail("replay", str(exc))
    return _into_learner(args, paths) if args.into_learner else _publish(args, paths)


def add_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Register `info`, `replay` and `bag` on the `qgl` subcommand parser."""
    info = subparsers.add_parser("info", help="topics, message counts and duration of a bag")
    info.add_argument("path", help="bag directory or .mcap file")
    info.set_defaults(func=cmd_info)

    bag = subparsers.add_parser("bag", help="bag tools, as `ros2 bag` (info, reindex)")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True)
    bag_info_parser = bag_sub.add_parser("info", help="the same as `qgl info`")
    bag_info_parser.add_argument("path", help="bag directory or .mcap file")
    bag_info_parser.set_defaults(func=cmd_info)
    reindex = bag_sub.add_parser(
        "reindex", help="repair a bag whose recorder was killed (adds the MCAP summary) and "
                        "regenerate its metadata.yaml, so stock readers open it")
    reindex.add_argument("path", help="bag directory or .mcap file")
    reindex.set_defaults(func=cmd_reindex)

    replay = subparsers.add_parser(
        "replay", help="republish bags with their original timing, or rebuild the learner from them")
    replay.add_argument("paths", nargs="+", metavar="PATH",
                        help="bag directory, .mcap file, or a runs folder of episode bags")
    replay.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    replay.add_argument("--topics", nargs="+", default=None, help="only these topics")
    replay.add_argument("--start-delay", type=float, default=0.5,
                        help="[s] wait after creating publishers so subscribers match (default 0.5)")
    replay.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                        help="[s] first wait up to S until every topic has a subscriber (default 0)")
    replay.add_argument("--into-learner", action="store_true",
                        help="rebuild replay memory and Q-Graph from /transitions instead of publishing")
    replay.add_argument("--train-iterations", type=int, default=0,
                        help="with --into-learner: train steps after the rebuild (whole cycles)")
    replay.add_argument("--learner-config", default=None,
                        help="with --into-learner: the learner's parameter file (default: the "
                             "learner.yaml qg_learning_node installs, as the learner node uses)")
    replay.add_argument("--save-checkpoint", default=None,
                        help="with --into-learner: write a learner checkpoint here")
    replay.set_defaults(func=cmd_replay)
