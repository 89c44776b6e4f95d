"""Episode renderers by name, and an episode bag as a video: what ``qgl render`` and the
Gymnasium environments' ``render()`` draw with.

Renderers are plugins found by name under the entry-point group ``qg_learning_node.renderers``
(a module with ``SceneRenderer`` and ``render_bag(bag, out, fps, speed, width, height)``):
``sim_robot_node`` registers ``pybullet`` (its CPU renderer). This package imports no simulator
and no command line; without a renderer installed, a lookup says so.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from qg_common.plugins import load_registered, registered_names

__all__ = ["RENDERER_GROUP", "renderer", "render_episode", "default_video_path"]

RENDERER_GROUP = "qg_learning_node.renderers"


def renderer(name: str | None = None) -> Any:
    """The renderer registered as ``name`` (None: the first registered).

    :raises RuntimeError: if none (or none of that name) is installed.
    """
    known = registered_names(RENDERER_GROUP)
    if not known or (name is not None and name not in known):
        raise RuntimeError(f"no episode renderer{'' if name is None else f' {name!r}'} "
                           f"installed (entry points {RENDERER_GROUP}: {known}); "
                           "sim_robot_node provides 'pybullet'")
    return load_registered(RENDERER_GROUP, known[0] if name is None else name,
                           what="episode renderer")


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
