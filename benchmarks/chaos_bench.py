"""Chaos: a long training run through the stack while processes are killed with SIGKILL.

Runs ``qgl run --episodes N`` (the stack with respawn, the resumable journal) and, at seeded
random training episodes, ``kill -9`` one of its processes (robot, learner or executor, chosen
at random) a seeded random moment into that episode. At the end it checks what a run that
lasts days needs:

- the run finished: the journal holds exactly N completed training episodes;
- nothing was lost: the learner's last checkpoint holds the transitions of every completed
  episode (training and test: it learns from both), plus those of attempts cut short while it
  stayed up (it keeps what it received; a restarted learner resumes without them), and every
  completed episode's learner count is that running sum (continuous across its restarts);
- at most the running episode was cut short per kill;
- memory stays flat: each process's resident set size, from its sample after ``--warmup``
  episodes of its life to the end of it (killed instances count up to their death).

Run: ``eval "$(.venv/bin/qgl env)" && .venv/bin/python benchmarks/chaos_bench.py [--episodes
2000] [--kills 10] [--max-steps 5]``; the last line is JSON.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from qg_common.process_info import child_processes, rss_kib

ROLES = ("robot", "learner", "executor")


def stack_processes(parent: int) -> dict[str, int]:
    """The stack's processes (role -> pid) among the children of ``parent`` (``qgl run``):
    ``ros2 run <package> <executable>`` runs the executable, which names the role."""
    found = {}
    for pid, argv in child_processes(parent).items():
        names = {Path(a).name for a in argv[:3]}
        for role in ROLES:
            if role in names:
                found[role] = pid
    return found


def journal(run_dir: Path) -> dict:
    try:
        return json.loads((run_dir / "journal.json").read_text())
    except (OSError, ValueError):
        return {}


class Chaos(threading.Thread):
    """Kills one of the stack's processes at each planned training episode, a random moment
    into it, and samples every process's RSS once an episode."""

    def __init__(self, qgl: subprocess.Popen, run_dir: Path, at: list[int], seed: int,
                 warmup: int) -> None:
        super().__init__(daemon=True)
        self.qgl, self.run_dir, self.at, self.warmup = qgl, run_dir, sorted(at), warmup
        self.rng = random.Random(seed)
        self.kills: list[dict] = []
        #: pid -> {role, born (episodes done at first sight), first (RSS at warm-up), last}
        self.lives: dict[int, dict] = {}

    def run(self) -> None:
        seen = -1
        while self.qgl.poll() is None:
            done = journal(self.run_dir).get("training_done", 0)
            procs = stack_processes(self.qgl.pid)
            for role, pid in procs.items():
                life = self.lives.setdefault(pid, {"role": role, "born": done, "first": 0,
                                                   "last": 0})
                rss = rss_kib(pid)
                if rss:
                    life["last"] = rss
                    if not life["first"] and done - life["born"] >= self.warmup:
                        life["first"] = rss
            if self.at and done >= self.at[0] and done != seen:
                seen = done
                self.at.pop(0)
                time.sleep(self.rng.uniform(0.0, 1.5))       # a moment into the episode
                procs = stack_processes(self.qgl.pid)
                role = self.rng.choice(ROLES)
                if role in procs:
                    os.kill(procs[role], signal.SIGKILL)
                    self.kills.append({"episode": done, "role": role, "pid": procs[role],
                                       "at": time.time()})
                    print(f"[chaos] killed {role} (pid {procs[role]}) after {done} training "
                          f"episodes", flush=True)
            time.sleep(0.2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=2000)
    parser.add_argument("--kills", type=int, default=10)
    parser.add_argument("--max-steps", type=int, default=5, help="step cap of each episode")
    parser.add_argument("--warmup", type=int, default=20,
                        help="episodes of a process's life before its RSS baseline")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--run-dir", type=Path, default=None,
                        help="the run's folder (an existing one continues)")
    parser.add_argument("--domain-id", default="79", help="private ROS_DOMAIN_ID")
    args = parser.parse_args()
    run_dir = args.run_dir or Path(tempfile.mkdtemp(prefix="qg_chaos_"))
    rng = random.Random(args.seed)
    at = sorted(rng.sample(range(args.warmup, max(args.warmup + args.kills, args.episodes - 5)),
                           args.kills))
    env = dict(os.environ, ROS_DOMAIN_ID=args.domain_id, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(run_dir / "ros_log"))
    command = [str(Path(sys.executable).parent / "qgl"), "run", "--episodes", str(args.episodes),
               "--test-every", "0", "--test-poses", "1", "--train-max-steps", str(args.max_steps),
               "--run-dir", str(run_dir), "--recording", "mode=rl_rate",
               "--seed", str(args.seed)]
    print(f"[chaos] qgl {' '.join(command[1:])}; kills after training episodes {at}", flush=True)
    started = time.monotonic()
    run_dir.mkdir(parents=True, exist_ok=True)
    log = open(run_dir / "chaos_qgl.log", "a")      # qgl's own output
    qgl = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)
    chaos = Chaos(qgl, run_dir, at, args.seed, args.warmup)
    chaos.start()
    code = qgl.wait()
    chaos.join(timeout=5.0)
    wall = time.monotonic() - started

    data = journal(run_dir)
    completed = data.get("completed", [])
    train = [c for c in completed if c["mode"] == "train"]
    steps = sum(c["steps"] for c in completed)
    cut = data.get("cut_short", [])
    # what a learner that stayed up kept of the attempts cut short (the learner's own death
    # takes them with it)
    kept = [c for c in cut if "learner" not in c["reason"]]
    running_sum, gaps, counted = 0, 0, 0
    events = sorted([(c["started"], c["steps"]) for c in completed]
                    + [(k["at"], k.get("steps", 0)) for k in kept])
    counts = {c["started"]: c.get("learner_transitions") for c in completed}
    for at, n in events:
        running_sum += n
        if counts.get(at) is not None:
            counted += 1
            gaps += counts[at] != running_sum
    try:
        learner = json.loads((run_dir / "checkpoints" / "learner.json").read_text())
    except (OSError, ValueError):
        learner = {}
    expected = steps + sum(k.get("steps", 0) for k in kept)
    growth = {}
    for life in chaos.lives.values():
        if life["first"] and life["last"]:
            change = (life["last"] - life["first"]) / life["first"]
            role = life["role"]
            growth[role] = max(growth.get(role, change), change)
    for role in ROLES:
        lives = [lf for lf in chaos.lives.values() if lf["role"] == role]
        print(f"{role:9s} {len(lives)} instance(s); largest RSS growth after warm-up "
              f"{growth.get(role, float('nan')):+.1%}")
    print(f"training episodes completed {len(train)} of {args.episodes}; kills {len(chaos.kills)}; "
          f"attempts cut short {len(cut)}; transitions: completed episodes {steps}, kept of cut "
          f"attempts {expected - steps}, learner {learner.get('transitions')}; learner counts "
          f"off the running sum {gaps} of "
          f"{counted}; {wall:.0f} s; qgl exit code {code}; run folder {run_dir}")
    print(json.dumps({
        "episodes": args.episodes, "max_steps": args.max_steps, "kills": len(chaos.kills),
        "killed": [k["role"] for k in chaos.kills],
        "training_completed": len(train), "all_completed": len(train) == args.episodes,
        "cut_short": len(cut), "cut_short_per_kill_ok": len(cut) <= len(chaos.kills),
        "completed_steps": steps, "kept_of_cut_attempts": expected - steps,
        "learner_transitions": learner.get("transitions"),
        "lost_transitions": None if learner.get("transitions") is None
        else expected - int(learner["transitions"]),
        "learner_count_discontinuities": gaps, "learner_counts_checked": counted,
        "rss_growth": {k: round(v, 4) for k, v in growth.items()},
        "wall_time_s": round(wall, 1), "qgl_exit_code": code}))


if __name__ == "__main__":
    main()
