"""``qgl export-policy`` and ``qgl up --policy``: a trained actor as a file, and a stack that
runs it frozen.

A checkpoint (``learner.pt``) knows its networks and the sizes they were built for, not the
state definition: the executor owned that (``executor/task_spec``). So the spec is the
executor's, read as the node reads it (the shipped ``executor.yaml``, then ``--executor-config``
files, then ``--set`` values), or, for ``--run DIR`` of a ``qgl up`` or ``qgl demo`` run, from
what that run's executor logged at start (``task residual, observation tilt_only: ...``); the
export refuses a spec whose sizes are not the checkpoint's. The file: ``policy_file.py``.
"""
from __future__ import annotations

import argparse
import datetime
import json
import re
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from qg_common.params import (
    ConfigError,
    config_file,
    load_ros_params,
    load_yaml,
    merge_params,
    unflatten,
)
from qg_learning_node.policy_file import PolicyFileError, load_policy, save_policy, spec_for_task

from qg_bringup.stack_file import ProcessSpec, StackConfigError

__all__ = ["add_parser", "executor_task", "export_core", "run_checkpoint", "logged_task",
           "frozen_stack", "stack_robot"]

#: Where a run keeps its learner checkpoint (the learner node's ``<runs>/checkpoints``).
CHECKPOINT = Path("checkpoints") / "learner.pt"
#: The robot process's plugin when its arguments name none (``RobotChoice``'s default).
DEFAULT_ROBOT = "sim_panda"
#: What the executor logs at start (``executor_node.py``): its task kind and observation.
_TASK_LINE = re.compile(r"task (\w+), observation (\w+): (\d+)-D states, (\d+)-D actions")


def executor_task(files: list[Path] | None = None,
                  overrides: dict[str, Any] | None = None) -> tuple[str, Any]:
    """The executor's task kind and task, from its shipped parameters, ``files`` laid over them
    and ``overrides`` (dotted names) over those: what ``ros2 run ... executor --ros-args
    --params-file F -p name:=value`` would run."""
    from qg_common.peg_task import PEG_TASK_FILE, PegCell
    from qg_common.shaft_task import SHAFT_TASK_FILE
    from qg_learning_node.executor.parameters import load_geometry, load_task
    from qg_learning_node.executor.peg_task import PegTask, PegTaskConfig
    from qg_learning_node.executor.residual_task import ResidualTask
    params = load_ros_params(config_file("executor.yaml"), "executor")
    for path in files or []:
        params = merge_params(params, load_ros_params(Path(path), "executor"))
    params = merge_params(params, unflatten(dict(overrides or {})))
    kind = (params.get("task") or {}).get("kind", "residual")
    if kind == "residual":
        cell = merge_params(load_ros_params(config_file(SHAFT_TASK_FILE[1])), params)
        return kind, ResidualTask(load_task(params), load_geometry(cell))
    if kind == "peg":
        cell = merge_params(load_ros_params(config_file(PEG_TASK_FILE[1])), params)
        return kind, PegTask(PegTaskConfig.from_dict(params.get("peg") or {}),
                             PegCell.from_dict(cell.get("peg_task") or {}))
    raise ConfigError(f"task.kind must be residual or peg, got {kind!r}")


def logged_task(run_dir: Path) -> dict[str, str] | None:
    """What the executor of the run in ``run_dir`` logged of its task: ``{"kind",
    "observation"}``, or ``None`` if no log says. Read from ``logs/executor*.log`` (``qgl demo``,
    ``qgl up --log-dir``) and the ROS logs (``ros_log/*.log``, every ``qgl`` run's).

    :raises ValueError: if the run's executors logged different tasks (name one with ``--set``).
    """
    files = [*sorted((run_dir / "logs").glob("executor*.log")),
             *sorted((run_dir / "ros_log").glob("*.log"))]
    found = set()
    for log in files:
        found.update((m.group(1), m.group(2))
                     for m in _TASK_LINE.finditer(log.read_text(errors="replace")))
    if len(found) > 1:
        raise ValueError(f"the executors of {run_dir} ran several tasks "
                         f"({', '.join(f'{k} {o}' for k, o in sorted(found))}): name the one "
                         "to export with --set task.kind=... / task.observation=...")
    if not found:
        return None
    kind, observation = found.pop()
    return {"kind": kind, "observation": observation}


def run_checkpoint(run_dir: Path) -> Path:
    """The learner checkpoint of a run folder (``<run>/checkpoints/learner.pt``, or a folder
    holding ``learner.pt``).

    :raises FileNotFoundError: naming both places looked in.
    """
    for path in (run_dir / CHECKPOINT, run_dir / CHECKPOINT.name):
        if path.is_file():
            return path
    raise FileNotFoundError(f"no learner checkpoint in {run_dir} (looked for {CHECKPOINT} and "
                            f"{CHECKPOINT.name})")


def export_core(core: Any, task_kind: str, task: Any, robot: str, output: Path,
                source: str) -> Path:
    """Write the actor of the learner ``core`` (a ``LearnerCore``) for ``task`` on ``robot`` to
    ``output``, with its provenance; the path written.

    :raises PolicyFileError: if the learner's sizes are not the task's.
    """
    if (core.state_dim, core.action_dim) != (task.state_dim, task.action_dim):
        observation = getattr(task.config, "observation", task_kind)
        raise PolicyFileError(
            f"the learner's actor maps {core.state_dim}-D states to {core.action_dim}-D "
            f"actions; the {task_kind} task with observation {observation!r} has "
            f"{task.state_dim}-D states and {task.action_dim}-D actions (set the executor's "
            "task, e.g. --set task.observation=tilt)")
    config = core.config
    provenance = {
        "source": source, "steps": int(core.steps), "updates": int(core.updates),
        "actor_version": int(core.actor_version), "qgraph": bool(config.use_qgraph),
        "bounds": config.ddpg.bounds, "seed": int(config.ddpg.seed),
        "exported": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    spec = spec_for_task(task_kind, task, robot, config.ddpg.actor_activation, provenance)
    return save_policy(output, core.agent.actor_tensors(), spec)


def _setting(text: str) -> tuple[str, Any]:
    """``--set name=value``: the value parsed as YAML (numbers, true/false, strings)."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    return name.strip(), load_yaml(value)


def _cmd_export(args: argparse.Namespace) -> int:
    from qg_learning_node.learner.learner_core import LearnerCore
    overrides = dict(args.set)
    try:
        if args.run:
            run_dir = Path(args.run)
            checkpoint = run_checkpoint(run_dir)
            named = {"task.kind", "task.observation"} & set(overrides)
            logged = None if named else logged_task(run_dir)
            if logged is not None:  # the run's own task, unless the command line names one
                overrides["task.kind"] = logged["kind"]
                if logged["kind"] == "residual":
                    overrides["task.observation"] = logged["observation"]
            source = str(run_dir.resolve())
        else:
            checkpoint = Path(args.checkpoint)
            if not checkpoint.is_file():
                raise FileNotFoundError(f"checkpoint not found: {checkpoint}")
            source = str(checkpoint.resolve())
        kind, task = executor_task([Path(f) for f in args.executor_config], overrides)
        core = LearnerCore.load(checkpoint)
        path = export_core(core, kind, task, args.robot, Path(args.output), source)
    except ValueError as exc:       # a bad setting, or sizes that are not the checkpoint's
        print(f"qgl export-policy: {exc}", file=sys.stderr)
        return 2
    spec = load_policy(path).spec
    print(f"[qgl] policy file {path}: {spec.describe()}; from {checkpoint} "
          f"({spec.provenance['steps']} RL steps, {spec.provenance['updates']} train steps)")
    print(json.dumps({"file": str(path), "task": spec.task, "observation": spec.observation,
                      "state_dim": spec.state_dim, "action_dim": spec.action_dim,
                      "robot": spec.robot, "steps": spec.provenance["steps"]}))
    return 0


def stack_robot(specs: list[ProcessSpec]) -> str:
    """The robot plugin a stack's processes run: the ``robot:=NAME`` of their arguments, else
    the robot process's default (``sim_panda``)."""
    for spec in specs:
        for arg in spec.args:
            if arg.startswith("robot:="):
                return arg.split(":=", 1)[1]
    return DEFAULT_ROBOT


def frozen_stack(specs: list[ProcessSpec], policy: Path) -> list[ProcessSpec]:
    """``specs`` without the learner, each executor running the policy file ``policy`` frozen,
    in the file's state definition (a residual actor's ``task.observation``: a file trained
    before the default changed still runs) unless the stack file's own arguments set one, which
    then come later and win (a mismatch is refused by the executor, with its reason).

    :raises StackConfigError: if the file cannot be read (before any process starts), or the
        stack has no executor to run it.
    """
    try:
        spec = load_policy(policy).spec
    except PolicyFileError as exc:
        raise StackConfigError(str(exc)) from None
    robot = stack_robot(specs)
    executors = [s for s in specs if (s.package, s.executable) == ("qg_learning_node", "executor")]
    if not executors:
        raise StackConfigError("--policy needs a stack with an executor process")
    print(f"[qgl] frozen policy {policy}: {spec.describe()}; no learner, robot {robot}",
          flush=True)
    params = ("--ros-args", "-p", f"policy.file:={Path(policy).resolve()}",
              "-p", f"policy.robot:={robot}")
    state = (("--ros-args", "-p", f"task.observation:={spec.observation}", "--")
             if spec.task == "residual" else ())
    return [replace(s, args=(*state, *s.args, *params)) if s in executors else s for s in specs
            if (s.package, s.executable) != ("qg_learning_node", "learner")]


def add_parser(sub: argparse._SubParsersAction) -> None:
    export = sub.add_parser("export-policy", help="write the actor of a run or checkpoint as a "
                            "policy file (`qgl up --policy FILE` runs it frozen)")
    source = export.add_mutually_exclusive_group(required=True)
    source.add_argument("--checkpoint", help="a learner checkpoint (learner.pt)")
    source.add_argument("--run", help="a run folder with checkpoints/learner.pt (a `qgl demo` "
                        "run, or the runs folder of `qgl up`); its executor's logged task is used")
    export.add_argument("-o", "--output", required=True, help="the policy file to write (.npz)")
    export.add_argument("--robot", default="sim_panda",
                        help="the robot plugin it was trained on (default sim_panda)")
    export.add_argument("--executor-config", action="append", default=[], metavar="FILE",
                        help="executor parameter file over the shipped executor.yaml, as the "
                             "run's --params-file (e.g. config/executor_nextage.yaml)")
    export.add_argument("--set", type=_setting, action="append", default=[],
                        metavar="NAME=VALUE", help="an executor parameter of the run, e.g. "
                        "task.observation=tilt (repeatable)")
    export.set_defaults(func=_cmd_export)
