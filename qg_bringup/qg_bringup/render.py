"""``qgl render BAG [--out episode.mp4|.gif]``: an episode bag as a video.

The bag carries the robot (``/robot_description``, ``/tf_static``, ``/scene_markers``) and its
joint states; a renderer replays them offscreen, without a display or a GPU, and writes the step,
the setpoint's residual torques, the wrench estimate and the tilt on every frame. The renderers
and the rendering are ``episode_video``'s (plugins by name under ``qg_learning_node.renderers``);
this module is the command. Without a renderer installed the command says so.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from qg_learning_node.episode_video import RENDERER_GROUP, render_episode

__all__ = ["render_episode", "add_parser"]


def _cmd_render(args: argparse.Namespace) -> int:
    bag = Path(args.bag)
    if not bag.exists():
        print(f"qgl render: no such bag: {bag}", file=sys.stderr)
        return 2
    try:
        report = render_episode(bag, Path(args.out) if args.out else None, fps=args.fps,
                                speed=args.speed, width=args.width, height=args.height,
                                renderer_name=args.renderer)
    except ValueError as exc:
        print(f"qgl render: {exc}", file=sys.stderr)
        return 2
    print(f"{report['out']}: {report['frames']} frames, {report['seconds']:.2f} s of the "
          f"episode, rendered in {report['wall_s']:.1f} s")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register ``render`` on the ``qgl`` subcommand parser."""
    render = subparsers.add_parser(
        "render", help="an episode bag as a video (offscreen: no display or GPU needed)")
    render.add_argument("bag", help="the episode's bag directory or .mcap file")
    render.add_argument("--out", default=None,
                        help="video file, .mp4 or .gif (default: beside the bag, <episode>.mp4)")
    render.add_argument("--fps", type=float, default=25.0, help="frames per second (default 25)")
    render.add_argument("--speed", type=float, default=1.0,
                        help="episode seconds per video second (default 1: as recorded)")
    render.add_argument("--width", type=int, default=448, help="[px] (default 448)")
    render.add_argument("--height", type=int, default=336, help="[px] (default 336)")
    render.add_argument("--renderer", default=None,
                        help=f"a renderer registered under {RENDERER_GROUP} (default: the first)")
    render.set_defaults(func=_cmd_render)
