"""The environment a process of the stack needs, equivalent to sourcing ``install/setup.bash``.

The interface package's type support is a set of shared libraries: ``LD_LIBRARY_PATH`` must name
them before Python starts, so ``qgl`` and the test fixture build this environment for the
processes they start, and ``qgl`` re-executes itself in it once.
"""
from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from collections.abc import Mapping
from pathlib import Path

__all__ = ["repo_root", "install_dir", "stack_env", "PACKAGES", "DEFAULT_DOMAIN_ID"]

PACKAGES = ("qg_interfaces", "qg_common", "qg_recording", "sim_robot_node", "robot_bridge_node",
            "qg_learning_node")
#: A private DDS domain, so the stack never meets other ROS graphs on the machine.
DEFAULT_DOMAIN_ID = "42"


def repo_root() -> Path:
    # <repo>/qg_learning_node/qg_learning_node/cli/ros_env.py
    return Path(__file__).resolve().parents[3]


def install_dir() -> Path:
    return repo_root() / "ros_ws" / "install"


def _prepend(env: dict[str, str], key: str, paths: list[str]) -> None:
    old = [p for p in env.get(key, "").split(os.pathsep) if p]
    env[key] = os.pathsep.join(list(dict.fromkeys(paths + old)))


def _sourced_setup(base: Mapping[str, str]) -> dict[str, str]:
    """The variables ``install/setup.bash`` sets, on top of the venv as the underlay prefix."""
    env = dict(base)
    _prepend(env, "AMENT_PREFIX_PATH", [str(Path(sys.prefix))])
    script = f". '{install_dir() / 'setup.bash'}' && env -0"
    out = subprocess.run(["bash", "-c", script], env=env, capture_output=True, check=True).stdout
    pairs = (item.split("=", 1) for item in out.decode().split("\0") if "=" in item)
    keys = ("AMENT_PREFIX_PATH", "LD_LIBRARY_PATH", "PYTHONPATH", "CMAKE_PREFIX_PATH",
            "COLCON_PREFIX_PATH", "PATH")
    return {k: v for k, v in pairs if k in keys}


def stack_env(base: Mapping[str, str] | None = None, domain_id: str | None = None,
              log_dir: Path | None = None) -> dict[str, str]:
    """``base`` (default: ``os.environ``) plus what ROS needs to find our workspace.

    Loopback-only discovery and a ROS log folder are set unless ``base`` sets them already.
    """
    env = dict(os.environ if base is None else base)
    install = install_dir()
    if not (install / "setup.bash").is_file():
        raise FileNotFoundError(f"{install} has no setup.bash: run scripts/setup.sh first")
    env.update(_sourced_setup(env))
    _prepend(env, "PATH", [str(Path(sysconfig.get_paths()["scripts"]))])
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = domain_id
    env.setdefault("ROS_DOMAIN_ID", DEFAULT_DOMAIN_ID)
    if log_dir is not None:
        env["ROS_LOG_DIR"] = str(log_dir)
    env.setdefault("ROS_LOG_DIR", str(repo_root() / "runs" / "ros_log"))
    env.setdefault("PYTHONUNBUFFERED", "1")
    env["QG_STACK_ENV"] = "1"
    return env


if __name__ == "__main__":
    # `eval "$(python -m qg_learning_node.cli.ros_env)"` gives a shell the stack's environment.
    import shlex
    for key, value in sorted(stack_env().items()):
        if key.isidentifier() and os.environ.get(key) != value:
            print(f"export {key}={shlex.quote(value)}")
