"""The environment a process of the stack needs, equivalent to sourcing ``install/setup.bash``.

The interface package's type support is a set of shared libraries: ``LD_LIBRARY_PATH`` must name
them before Python starts, so ``qgl`` and the test fixture build this environment for the
processes they start, and ``qgl`` re-executes itself in it once. The workspace is the one named
by ``$QG_ROS_INSTALL`` (``scripts/*.sh`` and the ``.venv/bin/qgl`` that ``scripts/setup.sh``
writes set it) or, in a shell that sourced ``install/setup.bash``, the one the ament index names.
"""
from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from collections.abc import Mapping
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_prefix
from qg_common.params import runs_dir

__all__ = ["install_dir", "stack_env", "exports", "PACKAGES", "DEFAULT_DOMAIN_ID"]

PACKAGES = ("qg_interfaces", "qg_common", "qg_recording", "sim_robot_node", "robot_bridge_node",
            "qg_learning_node", "qg_experiments")
#: A private DDS domain, so the stack never meets other ROS graphs on the machine.
DEFAULT_DOMAIN_ID = "42"


def install_dir() -> Path:
    """The colcon install folder of the stack's workspace (the one with ``setup.bash``).

    :raises FileNotFoundError: if neither ``$QG_ROS_INSTALL`` nor the ament index names one.
    """
    env = os.environ.get("QG_ROS_INSTALL")
    if env:
        return Path(env)
    try:   # sourced: isolated installs live in <install>/<package>
        prefix = Path(get_package_prefix("qg_interfaces"))
    except (OSError, PackageNotFoundError, LookupError):
        raise FileNotFoundError("the stack's workspace is unknown: run scripts/setup.sh and use "
                                ".venv/bin/qgl, or set QG_ROS_INSTALL=<repo>/ros_ws/install") \
            from None
    return next((p for p in (prefix, prefix.parent) if (p / "setup.bash").is_file()),
                prefix.parent)


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
    env.setdefault("ROS_LOG_DIR", str(runs_dir() / "ros_log"))
    env.setdefault("PYTHONUNBUFFERED", "1")
    env["QG_STACK_ENV"] = "1"
    env["QG_ROS_INSTALL"] = str(install)
    return env


def exports(base: Mapping[str, str] | None = None) -> str:
    """Shell ``export`` lines that give a shell the stack's environment (what ``base`` lacks)."""
    import shlex
    base = os.environ if base is None else base
    return "\n".join(f"export {key}={shlex.quote(value)}"
                     for key, value in sorted(stack_env(base).items())
                     if key.isidentifier() and base.get(key) != value)


if __name__ == "__main__":
    # `eval "$(python -m qg_bringup.ros_env)"` gives a shell the stack's environment.
    print(exports())
