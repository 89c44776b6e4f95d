"""Plugins found by name through entry points: robots, interface kinds, task scenes,
renderers, environments.

A package registers an object under an entry-point group (its ``setup.py``); the stack looks it
up by name here, so no package imports another it merely uses at run time (a simulator, a real
arm's driver, a renderer).
"""
from __future__ import annotations

from importlib.metadata import entry_points
from typing import Any

__all__ = ["ROBOT_PLUGIN_GROUP", "registered_names", "load_registered", "registering_packages"]

#: The entry-point group robots register under (``name = module:RobotPlugin instance``).
ROBOT_PLUGIN_GROUP = "robot_bridge_node.robots"


def registered_names(group: str) -> list[str]:
    """Names registered under the entry-point ``group``."""
    return sorted(ep.name for ep in entry_points(group=group))


def load_registered(group: str, name: str, expected: type = object, what: str = "plugin") -> Any:
    """The object registered as ``name`` under the entry-point ``group``.

    :param what: what it is, for the messages (``robot plugin``).
    :raises ValueError: if no installed package registers that name (lists those that do).
    :raises TypeError: if the entry point is not an ``expected``.
    """
    found = [ep for ep in entry_points(group=group) if ep.name == name]
    if not found:
        raise ValueError(f"no {what} named {name!r}; installed: {registered_names(group)}")
    loaded = found[0].load()
    if not isinstance(loaded, expected):
        raise TypeError(f"entry point {name!r} is {type(loaded).__name__}, "
                        f"not a {expected.__name__}")
    return loaded


def registering_packages(group: str) -> set[str]:
    """The installed distributions (packages) that register something under ``group``."""
    return {ep.dist.name for ep in entry_points(group=group) if ep.dist is not None}
