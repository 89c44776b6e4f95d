"""Soak: many consecutive episodes through the ROS stack, nothing lost, memory flat.

Brings the stack up as the demo does (``config/stack.yaml``: robot process, executor, learner),
runs ``--episodes`` training episodes back to back by ``/executor/start_episode``, and checks
what a long unattended run needs:

- every transition arrives everywhere: the executor's step count (from the final episode
  statuses) equals the learner's ``transitions`` counter (``/learner/diagnostics``) and the
  ``/transitions`` messages in the episodes' MCAP bags, and every episode has a complete bag;
- memory does not grow: each process's resident set size after ``--warmup`` episodes and at the
  end (``/proc/<pid>/status`` VmRSS).

Run: ``eval "$(.venv/bin/qgl env)" && .venv/bin/python benchmarks/soak_bench.py``. The last line
is JSON; goals: 0 lost transitions, RSS growth < 10 % after warm-up.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from qg_bringup.episode_schedule import run_episode_by_service
from qg_bringup.stack_start import DemoSettings, start_stack, wait_for_stack
from qg_common.params import config_file
from qg_common.process_info import rss_kib
from qg_common.ros_client import CliNode
from qg_recording.bag_reader import bag_info
from tqdm import tqdm


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--max-steps", type=int, default=10, help="step cap of each episode")
    parser.add_argument("--warmup", type=int, default=10, help="episodes before the RSS baseline")
    parser.add_argument("--domain-id", default="77", help="private ROS_DOMAIN_ID")
    args = parser.parse_args()
    run_dir = Path(tempfile.mkdtemp(prefix="qg_soak_"))
    launcher, env = start_stack(run_dir, DemoSettings(train_max_steps=args.max_steps),
                                config_file("stack.yaml"), domain_id=args.domain_id)
    pids = {r.spec.name: r.popen.pid for r in launcher.running}
    learner_counts: list[int] = []
    baseline: dict[str, int] = {}
    steps = 0
    started = time.monotonic()
    try:
        from qg_interfaces.msg import LearnerDiagnostics
        with CliNode("qg_soak", domain_id=int(env["ROS_DOMAIN_ID"])) as cli:
            cli.node.create_subscription(LearnerDiagnostics, "/learner/diagnostics",
                                         lambda m: learner_counts.append(int(m.transitions)), 10)
            wait_for_stack(cli, timeout=180.0)
            with tqdm(total=args.episodes, unit="episode", dynamic_ncols=True) as bar:
                for i in range(args.episodes):
                    died = launcher.poll()
                    if died:
                        raise RuntimeError(f"process {died[0][0]} exited with code {died[0][1]}")
                    outcome = run_episode_by_service(cli, i, "train", -1, seed=i, timeout=120.0)
                    steps += outcome.steps
                    if i + 1 == args.warmup:
                        baseline = {name: rss_kib(pid) for name, pid in pids.items()}
                    bar.set_postfix(steps=steps, learner=learner_counts[-1] if learner_counts
                                    else 0)
                    bar.update()
            # The learner's counter comes with its heartbeat: wait for the last transitions.
            cli.spin_until(lambda: bool(learner_counts) and learner_counts[-1] >= steps, 10.0)
            end_rss = {name: rss_kib(pid) for name, pid in pids.items()}
            wall = time.monotonic() - started
    finally:
        codes = launcher.stop()
    bags = sorted(p.parent for p in (run_dir / "episodes").glob("*/metadata.yaml"))
    infos = [bag_info(b) for b in bags]
    bag_transitions = sum(t.message_count for info in infos for t in info.topics
                          if t.name == "/transitions")
    learner = learner_counts[-1] if learner_counts else 0
    growth = {name: (end_rss[name] - baseline[name]) / baseline[name]
              for name in pids if baseline.get(name)}
    for name in pids:
        print(f"{name:10s} RSS after warm-up {baseline.get(name, 0) / 1024:7.1f} MiB, at the end "
              f"{end_rss[name] / 1024:7.1f} MiB ({growth.get(name, float('nan')):+.1%})")
    print(f"episodes {args.episodes} (complete bags {sum(i.complete for i in infos)}), "
          f"transitions: executor {steps}, learner {learner}, bags {bag_transitions}; "
          f"{wall:.0f} s, {steps / wall:.1f} steps/s; exit codes {codes}; run folder {run_dir}")
    print(json.dumps({
        "episodes": args.episodes, "complete_bags": sum(i.complete for i in infos),
        "executor_transitions": steps, "learner_transitions": learner,
        "bag_transitions": bag_transitions,
        "lost_transitions": max(steps - learner, steps - bag_transitions, 0),
        "rss_growth": {k: round(v, 4) for k, v in growth.items()},
        "max_rss_growth": round(max(growth.values(), default=0.0), 4),
        "wall_time_s": round(wall, 1), "exit_codes": codes}))


if __name__ == "__main__":
    main()
