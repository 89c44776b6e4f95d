"""``qgl render BAG [--out episode.mp4|.gif]``: an episode bag as a video.

The bag carries the robot (``/robot_description``, ``/tf_static``, ``/scene_markers``) and its
joint states; a renderer replays them offscreen, without a display or a GPU, and writes the step,
the setpoint's residual torques, the wrench estimate and the tilt on every frame. Renderers are
plugins found by name under the entry-point group ``qg_learning_node.renderers`` (a module with
``render_bag(bag, out, fps, speed, width, height)``): ``sim_robot_node`` registers ``pybullet``
(its CPU renderer). This package imports no simulator; without a renderer installed the command
says so.
"""
from __future__ import annotations

import argparse
import sys
import time
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

__all__ = ["RENDERER_GROUP", "renderer", "render_episode", "default_video_path", "add_parser"]

RENDERER_GROUP = "qg_learning_node.renderers"


def renderer(name: str | None = None) -> Any:
    """The renderer registered as ``name`` (None: the first registered).

    :raises RuntimeError: if none (or none of that name) is installed.
    """
    found = sorted(entry_points(group=RENDERER_GROUP), key=lambda ep: ep.name)
    if name is not None:
        found = [ep for ep in found if ep.name == name]
    if not found:
        known = sorted(ep.name for ep in entry_points(group=RENDERER_GROUP))
        raise RuntimeError(f"no episode renderer{'' if name is None else f' {name!r}'} "
                           f"installed (entry points {RENDERER_GROUP}: {known}); "
                           "sim_robot_node provides 'pybullet'")
    return found[0].load()


def default_video_path(bag: Path) -> Path:
    """Beside the bag: ``runs/episodes/<episode>.mp4`` for ``runs/episodes/<episode>/``."""
    bag = Path(bag)
    return (bag.parent / bag.name).with_suffix(".mp4") if bag.is_dir() else bag.with_suffix(".mp4")


def render_episode(bag: Path, out: Path | None = None, *, fps: float = 25.0,
                   speed: float = 1.0, width: int = 448, height: int = 336,
                   renderer_name: str | None = None) -> dict[str, Any]:
    """Render the episode bag ``bag`` into ``out`` (default ``default_video_path``); the
    renderer's report (frames, span) with the wall time it took."""
    out = default_video_path(bag) if out is None else Path(out)
    start = time.perf_counter()
    report = renderer(renderer_name).render_bag(Path(bag), out, fps=fps, speed=speed,
                                                width=width, height=height)
    return {**report, "wall_s": time.perf_counter() - start}


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
