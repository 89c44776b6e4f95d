"""Matplotlib for the experiments' figures, drawn to files only.

Imported when a figure is drawn, not with the modules that draw one: pyplot takes about 0.3 s of
CPU to load, and the runs themselves (pool and Ray workers, the CLI) never draw.
"""
from __future__ import annotations

from typing import Any

__all__ = ["pyplot"]


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the file-only Agg backend (no display on a robot's PC or in CI)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt
