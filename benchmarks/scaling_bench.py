"""Many robots, one learner: transitions per wall second into the learner for N = 1, 2, 4 robots.

For each N the stack comes up as ``qgl up --robots N`` does (``config/stack.yaml``, N robot
processes and executors in ``/robot0``..., one learner at the root; N = 1: everything at the
root) with the demo's settings (episodes capped at ``--max-steps``, critic lr 1e-3, 50
iterations per 20-step cycle). Every robot runs training episodes back to back for
``--seconds`` of wall time; the learner's ``transitions`` counter (``/learner/diagnostics``)
over that window gives the rate. Episodes still running at the end are awaited and counted;
``transitions_per_s_until_learned`` is every transition over the time until the learner had
them all.

The learner trains in its transition callback, so on a busy machine its counter lags the
robots: the executors' own step rate (``robot_steps_per_s``: steps over the time until every
episode ended) is printed beside it.

Recording: each N runs twice, with the robot processes recording (the default) and with
``record:=false``. Per robot it reports the robot process's CPU time (``/proc/<pid>/stat``) per
simulated second of its RL steps (``AtRest.duration``, 1000 loop ticks; resets excluded) with
and without recording, and so the share of the loop's time that recording takes; and dropped
messages: RL steps the executors reported vs transitions the learner counted vs
``/transitions`` in the bags, and bags not closed complete (goal: 0).

Run: ``eval "$(.venv/bin/qgl env)" && .venv/bin/python benchmarks/scaling_bench.py`` (about
2 x 3 x (``--seconds`` + 30) s). The last line is JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from qg_bringup.episode_wait import FINAL_STATES
from qg_bringup.fleet import robot_namespace
from qg_bringup.stack_start import DemoSettings, start_stack
from qg_common import topics
from qg_common.params import config_file
from qg_common.ros_client import CliNode, call_service
from qg_common.topics import LATCHED
from qg_recording.bag_reader import bag_info


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far [s]."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@dataclass
class Robot:
    """One robot's episodes, started back to back through its executor's service."""
    cli: CliNode
    namespace: str                      # "" = the root (one robot)
    pid: int
    started: list[str] = field(default_factory=list)
    final: dict = field(default_factory=dict)
    step_sim_time: float = 0.0          # [s] simulated time the loop ran in RL steps

    def __post_init__(self) -> None:
        from qg_interfaces.msg import AtRest, EpisodeStatus
        self.cli.node.create_subscription(
            EpisodeStatus, topics.robot_topic(self.namespace, topics.EPISODE_STATUS),
            lambda m: self.final.setdefault(m.episode_id, m) if m.state in FINAL_STATES else None,
            LATCHED)
        self.cli.node.create_subscription(
            AtRest, topics.robot_topic(self.namespace, topics.EE_AT_REST), self._on_at_rest, 100)

    def _on_at_rest(self, event) -> None:
        if event.seq > 0:                 # seq 0: the reset's settled state
            self.step_sim_time += event.duration

    @property
    def idle(self) -> bool:
        return not self.started or self.started[-1] in self.final

    def start_next(self) -> None:
        from qg_interfaces.srv import StartEpisode
        response = call_service(self.cli, StartEpisode,
                                topics.robot_topic(self.namespace, topics.START_EPISODE),
                                StartEpisode.Request(mode="train", seed=len(self.started) + 1),
                                timeout=30.0)
        if not response.success:
            raise RuntimeError(f"{self.namespace or '/'}: StartEpisode refused: {response.message}")
        self.started.append(response.episode_id)

    def steps(self) -> int:
        return sum(int(self.final[e].step) for e in self.started)


def stack_file(run_dir: Path, record: bool) -> Path:
    """``config/stack.yaml``, with ``record:=false`` for the robot process when not recording."""
    stack = yaml.safe_load(config_file("stack.yaml").read_text())
    if not record:
        for process in stack["processes"]:
            if process["executable"] == "robot":
                process["args"] = [*process.get("args", []), "--ros-args", "-p", "record:=false"]
    path = run_dir / "stack.yaml"
    path.write_text(yaml.safe_dump(stack))
    return path


def run(robots: int, record: bool, seconds: float, max_steps: int, domain_id: str) -> dict:
    """One stack of ``robots`` robots, episodes back to back for ``seconds``; its figures."""
    from qg_interfaces.msg import LearnerDiagnostics
    run_dir = Path(tempfile.mkdtemp(prefix=f"qg_scaling_{robots}_"))
    launcher, env = start_stack(run_dir, DemoSettings(train_max_steps=max_steps),
                                stack_file(run_dir, record), domain_id, robots=robots)
    pids = [r.popen.pid for r in launcher.running if r.spec.executable == "robot"]
    heartbeats: list[tuple[float, int]] = []
    try:
        with CliNode("qg_scaling", domain_id=int(env["ROS_DOMAIN_ID"])) as cli:
            cli.node.create_subscription(
                LearnerDiagnostics, "/learner/diagnostics",
                lambda m: heartbeats.append((time.monotonic(), int(m.transitions))), 10)
            fleet = [Robot(cli, robot_namespace(k) if robots > 1 else "", pid)
                     for k, pid in enumerate(pids)]
            if not cli.spin_until(lambda: bool(heartbeats), 180.0):
                raise TimeoutError("the learner did not come up")
            cpu0 = [(cpu_seconds(r.pid), r.step_sim_time) for r in fleet]
            t0 = time.monotonic()
            deadline = t0 + seconds
            while time.monotonic() < deadline:
                for robot in fleet:
                    if robot.idle:
                        robot.start_next()
                cli.spin_until(lambda: time.monotonic() > deadline
                               or any(r.idle for r in fleet), seconds)
            before = [n for t, n in heartbeats if t <= t0]
            during = [n for t, n in heartbeats if t <= deadline]
            window = (during[-1] - (before[-1] if before else 0)) / seconds
            if not cli.spin_until(lambda: all(r.idle for r in fleet), 300.0):
                raise TimeoutError("episodes did not end")
            produced = time.monotonic() - t0
            # CPU of each robot process per simulated second of its steps (1000 loop ticks)
            cpu = [(cpu_seconds(r.pid) - c) / max(1e-9, r.step_sim_time - t)
                   for r, (c, t) in zip(fleet, cpu0)]
            steps = [r.steps() for r in fleet]
            # a learner that lags catches up (its queue is deep: RELIABLE_DEEP); none is lost
            cli.spin_until(lambda: heartbeats[-1][1] >= sum(steps), 300.0)
            learner = heartbeats[-1][1]
            learned = next((t for t, n in heartbeats if n >= sum(steps)), time.monotonic())
    finally:
        launcher.stop()
    infos = [bag_info(p.parent) for p in (run_dir / "episodes").glob("*/metadata.yaml")]
    bag_transitions = sum(t.message_count for i in infos for t in i.topics
                          if t.name == "/transitions")
    episodes = sum(len(r.started) for r in fleet)
    return {"robots": robots, "record": record, "episodes": episodes,
            "executor_steps": sum(steps), "learner_transitions": learner,
            "bag_transitions": bag_transitions if record else None,
            "incomplete_bags": (episodes - sum(i.complete for i in infos)) if record else None,
            "dropped": max(sum(steps) - learner, sum(steps) - bag_transitions if record else 0),
            "transitions_per_s": round(window, 2),
            "transitions_per_s_until_learned": round(learner / (learned - t0), 2),
            "robot_steps_per_s": round(sum(steps) / produced, 2),
            "robot_cpu_ms_per_tick": [round(c, 3) for c in cpu]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--seconds", type=float, default=60.0, help="wall time per run")
    parser.add_argument("--max-steps", type=int, default=50, help="step cap of each episode")
    parser.add_argument("--domain-id", default="78", help="private ROS_DOMAIN_ID")
    args = parser.parse_args()
    runs, summary = [], []
    for n in args.robots:
        on, off = (run(n, record, args.seconds, args.max_steps, args.domain_id)
                   for record in (True, False))
        runs += [on, off]
        for r in (on, off):
            print(json.dumps(r), flush=True)
        cpu_on = sum(on["robot_cpu_ms_per_tick"]) / n
        cpu_off = sum(off["robot_cpu_ms_per_tick"]) / n
        summary.append({
            "robots": n, "transitions_per_s": on["transitions_per_s"],
            "per_robot": round(on["transitions_per_s"] / n, 2),
            "transitions_per_s_until_learned": on["transitions_per_s_until_learned"],
            "robot_steps_per_s": on["robot_steps_per_s"],
            "transitions_per_s_unrecorded": off["transitions_per_s"],
            "robot_cpu_ms_per_tick": round(cpu_on, 3),
            "robot_cpu_ms_per_tick_unrecorded": round(cpu_off, 3),
            "recording_loop_share": round(1.0 - cpu_off / cpu_on, 3) if cpu_on else None,
            "dropped": on["dropped"] + off["dropped"], "incomplete_bags": on["incomplete_bags"]})
        s = summary[-1]
        print(f"N={n}: {s['transitions_per_s']:.1f} transitions/s into the learner "
              f"({s['per_robot']:.1f} per robot; {s['transitions_per_s_until_learned']:.1f} "
              f"until it had them all; the robots made {s['robot_steps_per_s']:.1f} "
              f"steps/s; {s['transitions_per_s_unrecorded']:.1f} transitions/s without "
              f"recording); robot process CPU per 1 ms tick {cpu_on:.3f} ms recording, "
              f"{cpu_off:.3f} ms not: recording takes {s['recording_loop_share']:.1%} of the "
              f"loop; dropped {s['dropped']}, incomplete bags {s['incomplete_bags']}", flush=True)
    base = summary[0]["transitions_per_s"]
    print(json.dumps({"cores": os.cpu_count(), "seconds": args.seconds, "summary": summary,
                      "speedup": {s["robots"]: round(s["transitions_per_s"] / base, 2)
                                  for s in summary} if base else {},
                      "runs": runs}))


if __name__ == "__main__":
    main()
