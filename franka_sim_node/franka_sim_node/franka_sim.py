"""``franka_sim``: franky-sim's MuJoCo FR3 with the task's scene, serving libfranka on loopback.

    ros2 run franka_sim_node franka_sim [--address 127.0.0.1] [--scene module:function]

The address and the held part come from ``config/franka.yaml`` (``franka.address``,
``franka.tool``: the same numbers the plugin connects with), the cell from
``config/shaft_task.yaml`` (its geometry and the housing's pose) and ``config/panda_scene.yaml``
(its physics); ``--params-file`` (any of those sections) or ``--address`` override them.
``--scene`` names the function that returns the scene's extensions from the held part and those
parameters (default: the shaft task's cell, ``franky_sim_scene.shaft_scene``). The arm starts
with the shaft upright 5 cm above the bearing face (``franky_sim_scene.parked_q``). A known wrench on the hand
(base frame, at the tool centre point): ``--hand-wrench Fx Fy Fz Tx Ty Tz`` from the start, or a
line ``wrench Fx Fy Fz Tx Ty Tz`` on standard input at any time (acknowledged on standard
output). Runs until SIGINT/SIGTERM or ``--seconds``; prints its step rate at the end.
``--realtime-priority`` steps at ``SCHED_FIFO`` priority, as a robot's own computer would.
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

from franka_robot_node.core.franka_config import FrankaConfig
from franka_robot_node.plugin import describe_franka
from qg_common.params import ConfigError, load_ros_params, merge_params, package_config
from qg_common.shaft_task import SHAFT_TASK_SECTION, ShaftTaskGeometry
from robot_bridge_node.core.arm_model import ArmModel

from franka_sim_node.core.franky_sim_host import FrankySimHost, SceneExtension
from franka_sim_node.core.franky_sim_scene import SCENE_CONFIG_FILES, parked_q

__all__ = ["main", "scene_params", "scene_extensions", "spawn", "DEFAULT_SCENE"]

#: The scene ``franka_sim`` builds unless told otherwise.
DEFAULT_SCENE = "franka_sim_node.core.franky_sim_scene:shaft_scene"


def scene_params(params_file: Path | None = None) -> dict[str, Any]:
    """The installed ``SCENE_CONFIG_FILES``' parameters, ``params_file``'s over them.

    :raises ConfigError: if a file is missing or malformed.
    """
    params: dict[str, Any] = {}
    for package, name in SCENE_CONFIG_FILES:
        params = merge_params(params, load_ros_params(package_config(package, name)))
    if params_file is not None:
        params = merge_params(params, load_ros_params(params_file))
    return params


def scene_extensions(name: str, config: FrankaConfig,
                     params: dict[str, Any]) -> list[SceneExtension]:
    """The extensions ``module:function`` returns for the configured held part and the
    scene's parameters (``scene_params``).

    :raises ValueError: if ``name`` is not ``module:function`` or cannot be imported.
    """
    module, _, function = name.partition(":")
    if not module or not function:
        raise ValueError(f"--scene must be module:function, got {name!r}")
    try:
        make = getattr(importlib.import_module(module), function)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"--scene {name!r}: {exc}") from exc
    return list(make(config.tool, params))


def spawn(address: str, *args: str, timeout: float = 30.0) -> subprocess.Popen:
    """``franka_sim`` serving at ``address`` as a child process (``python -m``), returned once
    it serves; its standard input takes ``wrench`` lines, its output is a pipe.

    :param args: more of ``franka_sim``'s arguments.
    :raises RuntimeError: if it ended or did not serve within ``timeout`` seconds (with what it
        printed).
    """
    process = subprocess.Popen([sys.executable, "-m", "franka_sim_node.franka_sim",
                                "--address", address, *args], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               bufsize=1)
    lines: list[str] = []
    ready = threading.Event()

    def pump() -> None:
        for line in process.stdout:
            lines.append(line.rstrip())
            if "serving libfranka" in line:
                ready.set()
        ready.set()

    threading.Thread(target=pump, daemon=True, name="franka_sim output").start()
    if not ready.wait(timeout) or process.poll() is not None:
        process.kill()
        raise RuntimeError(f"franka_sim did not serve at {address} within {timeout} s: "
                           + " | ".join(lines))
    process.output = lines  # type: ignore[attr-defined]
    return process


def _serve_stdin(host: FrankySimHost, stdin: TextIO, out: TextIO) -> None:
    """Lines ``wrench Fx Fy Fz Tx Ty Tz`` set the hand's wrench; others are refused."""
    for line in stdin:
        words = line.split()
        if not words:
            continue
        try:
            if words[0] != "wrench":
                raise ValueError(f"unknown command {words[0]!r} (known: wrench)")
            host.set_hand_wrench([float(w) for w in words[1:]])
            print(f"hand wrench {' '.join(words[1:])}", file=out, flush=True)
        except ValueError as exc:
            print(f"refused: {exc}", file=out, flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--params-file", type=Path, default=None,
                        help="ROS 2 parameter file over the installed config/franka.yaml, "
                             "shaft_task.yaml and panda_scene.yaml (any of their sections)")
    parser.add_argument("--address", default=None, help="loopback address to serve on "
                        "(default: franka.address)")
    parser.add_argument("--scene", default=DEFAULT_SCENE, help="module:function returning the "
                        "scene's extensions for the held part and the parameters")
    parser.add_argument("--hand-wrench", type=float, nargs=6, default=None,
                        metavar=("FX", "FY", "FZ", "TX", "TY", "TZ"))
    parser.add_argument("--seconds", type=float, default=0.0, help="stop after this long "
                        "(0: run until stopped)")
    parser.add_argument("--realtime-priority", type=int, default=0, help="SCHED_FIFO priority "
                        "of the stepping thread (0: the normal scheduler); the simulated arm "
                        "stands in for a robot with a computer of its own")
    args = parser.parse_args(argv)
    try:
        params = scene_params(args.params_file)
        config = FrankaConfig.from_dict(params.get("franka", {}))
        extensions = scene_extensions(args.scene, config, params)
        address = args.address or config.address
        park = parked_q(ArmModel.from_description(describe_franka(params)),
                        ShaftTaskGeometry.from_dict(params.get(SHAFT_TASK_SECTION.prefix, {})))
        host = FrankySimHost(address, extensions, initial_q=park)
        if args.hand_wrench is not None:
            host.set_hand_wrench(args.hand_wrench)
    except (ConfigError, ValueError, OSError, RuntimeError) as exc:
        print(f"franka_sim: {exc}", file=sys.stderr, flush=True)
        return 2
    if args.realtime_priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(args.realtime_priority))
        except OSError as exc:
            print(f"franka_sim: no realtime priority {args.realtime_priority} ({exc}); "
                  "running unprioritised", file=sys.stderr, flush=True)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    if args.seconds > 0.0:
        threading.Timer(args.seconds, stop.set).start()
    threading.Thread(target=_serve_stdin, args=(host, sys.stdin, sys.stdout), daemon=True,
                     name="stdin commands").start()
    print(f"franka_sim: franky-sim's FR3 serving libfranka at {address} (scene {args.scene})",
          flush=True)
    start = time.monotonic()
    try:
        host.run(stop)
    finally:
        elapsed = time.monotonic() - start
        host.close()
        print(f"franka_sim: {host.steps} steps in {elapsed:.1f} s "
              f"({host.steps / max(elapsed, 1e-9):.0f} a second), {host.dropped} dropped",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
