"""``franka_sim``: franky-sim's MuJoCo FR3 with the task's scene, serving libfranka on loopback.

    ros2 run franka_robot_node franka_sim [--address 127.0.0.1] [--scene module:function]

The address and the held part come from ``config/franka.yaml`` (``franka.address``,
``franka.tool``: the same numbers the plugin connects with), ``--params-file`` or
``--address`` override them. ``--scene`` names the function that returns the scene's extensions
from the held part (default: the demo's fixture and held cylinder). A known wrench on the hand
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
from typing import TextIO

from qg_common.params import ConfigError, load_ros_params, package_config

from franka_robot_node.core.franka_config import FrankaConfig
from franka_robot_node.core.franky_sim_host import FrankySimHost, SceneExtension

__all__ = ["main", "scene_extensions", "spawn", "DEFAULT_SCENE"]

#: The scene ``franka_sim`` builds unless told otherwise.
DEFAULT_SCENE = "franka_robot_node.core.franky_sim_scene:demo_scene"


def scene_extensions(name: str, config: FrankaConfig) -> list[SceneExtension]:
    """The extensions ``module:function`` returns for the configured held part.

    :raises ValueError: if ``name`` is not ``module:function`` or cannot be imported.
    """
    module, _, function = name.partition(":")
    if not module or not function:
        raise ValueError(f"--scene must be module:function, got {name!r}")
    try:
        make = getattr(importlib.import_module(module), function)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"--scene {name!r}: {exc}") from exc
    return list(make(config.tool))


def spawn(address: str, *args: str, timeout: float = 30.0) -> subprocess.Popen:
    """``franka_sim`` serving at ``address`` as a child process (``python -m``), returned once
    it serves; its standard input takes ``wrench`` lines, its output is a pipe.

    :param args: more of ``franka_sim``'s arguments.
    :raises RuntimeError: if it ended or did not serve within ``timeout`` seconds (with what it
        printed).
    """
    process = subprocess.Popen([sys.executable, "-m", "franka_robot_node.franka_sim",
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
                        help="ROS 2 parameter file with the franka section "
                             "(default: the installed config/franka.yaml)")
    parser.add_argument("--address", default=None, help="loopback address to serve on "
                        "(default: franka.address)")
    parser.add_argument("--scene", default=DEFAULT_SCENE, help="module:function returning the "
                        "scene's extensions for the held part")
    parser.add_argument("--hand-wrench", type=float, nargs=6, default=None,
                        metavar=("FX", "FY", "FZ", "TX", "TY", "TZ"))
    parser.add_argument("--seconds", type=float, default=0.0, help="stop after this long "
                        "(0: run until stopped)")
    parser.add_argument("--realtime-priority", type=int, default=0, help="SCHED_FIFO priority "
                        "of the stepping thread (0: the normal scheduler); the simulated arm "
                        "stands in for a robot with a computer of its own")
    args = parser.parse_args(argv)
    try:
        path = args.params_file or package_config("franka_robot_node", "franka.yaml")
        config = FrankaConfig.from_dict(load_ros_params(path).get("franka", {}))
        extensions = scene_extensions(args.scene, config)
        address = args.address or config.address
        host = FrankySimHost(address, extensions)
        if args.hand_wrench is not None:
            host.set_hand_wrench(args.hand_wrench)
    except (ConfigError, ValueError, OSError) as exc:
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
