"""Across machines: the learner in one Linux network namespace, the robot (robot process and
executor) in another, joined by a veth pair; they meet only over DDS on that link, as two hosts
on one subnet do, and share no files."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
from test_episodes import ROBOT, executor_spec, wait_for_file

pytestmark = pytest.mark.ros

LEARNER_ADDRESS, ROBOT_ADDRESS = "10.200.0.1", "10.200.0.2"
#: The learner with its default checkpoint folder (``<runs>/checkpoints`` on its own host).
LEARNER = ("learner", "qg_learning_node", "learner",
           ("--ros-args", "-p", "learner.cycle_steps:=10"))


def ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True)


@contextmanager
def two_hosts() -> Iterator[tuple[str, str]]:
    """Two network namespaces ``(learner side, robot side)`` joined by a veth pair
    (10.200.0.1/24 and 10.200.0.2/24), each with loopback up and a multicast route on the link
    (DDS discovery by multicast, as on a LAN); deleted afterwards, whatever happened."""
    tag = f"qg{os.getpid()}"
    hosts = (f"{tag}a", f"{tag}b")
    if shutil.which("ip") is None:
        pytest.skip("cannot create network namespaces here: no `ip` command (iproute2)")
    probe = ip("netns", "add", hosts[0])
    if probe.returncode != 0:
        pytest.skip(f"cannot create network namespaces here: {probe.stderr.strip()}")
    try:
        commands = [("netns", "add", hosts[1]),
                    ("link", "add", f"{tag}va", "type", "veth", "peer", "name", f"{tag}vb")]
        for host, link, address in zip(hosts, (f"{tag}va", f"{tag}vb"),
                                       (LEARNER_ADDRESS, ROBOT_ADDRESS)):
            commands += [("link", "set", link, "netns", host),
                         ("-n", host, "addr", "add", f"{address}/24", "dev", link),
                         ("-n", host, "link", "set", link, "up"),
                         ("-n", host, "link", "set", "lo", "up"),
                         ("-n", host, "route", "add", "224.0.0.0/4", "dev", link)]
        for command in commands:
            done = ip(*command)
            assert done.returncode == 0, f"ip {' '.join(command)}: {done.stderr}"
        yield hosts
    finally:
        for host in hosts:          # the veth pair goes with its namespaces
            ip("netns", "delete", host)


def link_bytes(host: str) -> int:
    """Bytes received on ``host``'s end of the link."""
    stats = json.loads(ip("-n", host, "-s", "-j", "link", "show", "type", "veth").stdout)
    return sum(link["stats64"]["rx"]["bytes"] for link in stats)


@dataclass(frozen=True)
class InHost:
    """A process of the stack started inside a network namespace (``ip netns exec`` execs the
    node itself, so signals reach it as they would without)."""
    spec: object
    host: str

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def respawn(self) -> bool:
        return self.spec.respawn

    @property
    def respawn_delay(self) -> float:
        return self.spec.respawn_delay

    def command(self, respawned: bool = False) -> list[str]:
        return ["ip", "netns", "exec", self.host, *self.spec.command(respawned)]


#: How the two hosts find each other (docs/deployment.md, "Discovery"): multicast on the subnet,
#: or unicast to the other host's address only.
DISCOVERY = {
    "subnet": lambda peer: {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"},
    "static_peers": lambda peer: {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                                  "ROS_STATIC_PEERS": peer},
}


def host_env(stack, side: Path, discovery: str, peer: str) -> dict[str, str]:
    """The stack's environment on one host: ``discovery`` of the ``peer`` host; UDP only (Fast
    DDS would otherwise pass data through shared memory, which the two namespaces of one machine
    share); runs and ROS logs of its own."""
    return {**stack.env, **DISCOVERY[discovery](peer), "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",
            "QG_RUNS_DIR": str(side / "runs"), "ROS_LOG_DIR": str(side / "ros_log")}


@pytest.mark.parametrize("discovery", sorted(DISCOVERY))
def test_learner_and_robot_on_two_hosts_run_an_episode_over_the_link(stack, tmp_path, discovery):
    from qg_bringup.launcher import Launcher
    from qg_bringup.stack_file import ProcessSpec

    learner_side, robot_side = tmp_path / "learner_host", tmp_path / "robot_host"
    learner_env = host_env(stack, learner_side, discovery, peer=ROBOT_ADDRESS)
    with two_hosts() as (learner_host, robot_host):
        learner = Launcher(env=learner_env, out=None, log_dir=stack.log_dir)
        robot = Launcher(env=host_env(stack, robot_side, discovery, peer=LEARNER_ADDRESS),
                         out=None, log_dir=stack.log_dir)
        try:
            learner.start([InHost(ProcessSpec(*LEARNER), learner_host)])
            robot.start([InHost(ProcessSpec(*spec), robot_host)
                         for spec in (ROBOT, executor_spec(max_steps=15))])
            operator = subprocess.run(
                ["ip", "netns", "exec", learner_host, sys.executable,
                 str(Path(__file__).with_name("netns_operator.py")), str(stack.domain_id)],
                env=learner_env, capture_output=True, text=True, timeout=400)
            assert operator.returncode == 0, operator.stderr[-3000:] + stack.logs()
            crossed = link_bytes(learner_host), link_bytes(robot_host)
            checkpoint = wait_for_file(learner_side / "runs" / "checkpoints" / "learner.pt")
            assert learner.poll() == [] and robot.poll() == [], stack.logs()
        finally:
            learner.stop(grace=3.0)
            robot.stop(grace=3.0)
    result = json.loads(operator.stdout.strip().splitlines()[-1])
    assert 1 <= result["steps"] <= 15
    assert result["transitions"] == result["steps"], result
    assert result["actor_version"] == result["steps"] // 10   # learner_spec: cycle_steps 10
    # Every message went over the link: transitions one way, actors the other.
    assert min(crossed) > 50_000, crossed
    # No shared files: the bag stays with the robot, the checkpoint with the learner.
    assert (robot_side / "runs" / "episodes" / result["episode_id"]).is_dir()
    assert not (learner_side / "runs" / "episodes").exists()
    assert checkpoint.is_file()
    assert not (robot_side / "runs" / "checkpoints").exists()
