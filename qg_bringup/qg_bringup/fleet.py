"""Many robots, one learner: the process list of ``qgl up --robots N``.

The wiring (docs/deployment.md shows it as ``ros2 run`` lines):

- every process of the stack file except the learner is per robot and runs in the namespace
  ``/robot<k>`` (``-r __ns:=/robot<k>``): robot process, executor, their topics and services
  (``/robot0/executor/start_episode``, ``/robot0/transitions``, ...);
- the executors take the learner's two root topics by remapping (``-r
  actor_parameters:=/actor_parameters -r learner/diagnostics:=/learner/diagnostics``), so every
  executor gets the same actor (the robot process gets the same remaps; it uses neither topic);
- the one learner runs at the root and subscribes ``/<ns>/transitions`` and
  ``/<ns>/episode_status`` of every robot (``-p robot_namespaces:=[robot0,robot1]``).

Each robot's recorder hears only its own namespace, so its bags hold only its own transitions;
the executor prefixes its episode ids with its namespace (``robot0_...``), so ids, bag folders
and the learner's per-episode bookkeeping never collide.
"""
from __future__ import annotations

from dataclasses import replace

from qg_bringup.stack_file import ProcessSpec, StackConfigError

__all__ = ["robot_namespace", "fleet_specs", "LEARNER_REMAPS"]

#: What a namespaced executor remaps to reach the learner at the root.
LEARNER_REMAPS = ("-r", "actor_parameters:=/actor_parameters",
                  "-r", "learner/diagnostics:=/learner/diagnostics")


def robot_namespace(k: int) -> str:
    """The namespace of robot ``k`` (without the leading slash): ``robot0``, ``robot1``, ..."""
    return f"robot{k}"


def _is_learner(spec: ProcessSpec) -> bool:
    return spec.package == "qg_learning_node" and spec.executable == "learner"


def fleet_specs(specs: list[ProcessSpec], robots: int) -> list[ProcessSpec]:
    """The stack's processes for ``robots`` robots and one learner.

    With ``robots == 1`` the stack is returned unchanged (everything at the root, as always).
    Otherwise the learner comes first, then each robot's processes, named ``<name><k>``.
    Further ``--ros-args`` blocks are appended to each process's own arguments, which rcl reads
    after the earlier ones.
    """
    if robots < 1:
        raise StackConfigError(f"--robots must be >= 1, got {robots}")
    if robots == 1:
        return list(specs)
    learners = [s for s in specs if _is_learner(s)]
    if len(learners) != 1:
        raise StackConfigError("--robots needs a stack with exactly one learner process, got "
                               f"{len(learners)}")
    namespaces = [robot_namespace(k) for k in range(robots)]
    (learner,) = learners
    fleet = [replace(learner, args=(*learner.args, "--ros-args", "-p",
                                    f"robot_namespaces:=[{','.join(namespaces)}]"))]
    for k, ns in enumerate(namespaces):
        fleet += [replace(s, name=f"{s.name}{k}",
                          args=(*s.args, "--ros-args", "-r", f"__ns:=/{ns}", *LEARNER_REMAPS))
                  for s in specs if not _is_learner(s)]
    return fleet
