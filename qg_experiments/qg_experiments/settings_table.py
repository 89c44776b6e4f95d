"""Every setting of the stack with its one home: the settings table of ``docs/design.md``.

Built from what the nodes declare (their ``ParameterSection`` s) and the config files each node
reads, so the table cannot drift from the code: ``tests/experiments/test_settings_table.py``
compares it with the document, and checks that no code default contradicts the YAML (a value
the YAML sets has its home there; a code default for it must be equal, or the two disagree
silently wherever the code default is used). Lives here because only the experiments package
may import both the robot side and the learning side.

``python -m qg_experiments.settings_table`` prints the table (paste it into docs/design.md).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from qg_common.node_parameters import Leaf, leaves, ros_value, shipped_defaults
from qg_common.params import ParameterSection

__all__ = ["NodeSettings", "Setting", "node_settings", "settings", "markdown", "disagreements",
           "extra_rows", "TABLE_START", "TABLE_END"]

#: The lines around the generated table in docs/design.md.
TABLE_START = "<!-- settings table: python -m qg_experiments.settings_table -->"
TABLE_END = "<!-- end of the settings table -->"


#: ``(package, file name)`` of a config file installed in ``share/<package>/config``.
ConfigFile = tuple[str, str]


@dataclass(frozen=True)
class NodeSettings:
    """One node's parameters: its sections, its own files (later ones win), and the files that
    only some robots or stacks add, by their name: a robot plugin's (``sim_nextage``) or a
    stack's ``--params-file`` (the Nextage stack's)."""
    node: str
    sections: tuple[ParameterSection, ...]
    files: tuple[ConfigFile, ...]
    overlays: tuple[tuple[str, tuple[ConfigFile, ...]], ...] = ()


@dataclass(frozen=True)
class Setting:
    """One row of the table."""
    name: str
    nodes: tuple[str, ...]
    home: str
    value: Any
    run_time: str


def node_settings() -> list[NodeSettings]:
    """The nodes of the stack and of the experiments, with what they declare and read."""
    from qg_common.peg_task import PEG_TASK_FILE, PEG_TASK_SECTION
    from qg_common.shaft_task import SHAFT_TASK_FILE, SHAFT_TASK_SECTION
    from qg_learning_node.executor.parameters import (
        EXECUTOR_SECTIONS,
        TASK_CHOICE_SECTION,
        TASK_SECTIONS,
    )
    from qg_learning_node.learner.learner_params import LEARNER_SECTIONS
    from robot_bridge_node.core.hardware_interface import ROBOT_SECTION, robot_plugin
    from robot_bridge_node.core.position_kind import POSITION
    from robot_bridge_node.core.torque_kind import EKF_SECTION, TORQUE
    from robot_bridge_node.hardware_node import HARDWARE_SECTION
    from robot_bridge_node.recorder_node import RECORDER_SECTION
    from robot_bridge_node.simulation_node import SIM_SECTION
    panda, nextage = robot_plugin("sim_panda"), robot_plugin("sim_nextage")
    franka = robot_plugin("franka")
    cells = (SHAFT_TASK_FILE, PEG_TASK_FILE)     # the tasks' cells: the robot's and the task's
    robots = tuple((name, tuple(f for f in plugin.config_files if f not in cells))
                   for name, plugin in (("sim_panda", panda), ("sim_nextage", nextage)))
    nextage_stack = "Nextage stack"
    own = [s for s in (*panda.parameters, *nextage.parameters)
           if s not in (SHAFT_TASK_SECTION, PEG_TASK_SECTION)]
    return [
        NodeSettings("sim", (ROBOT_SECTION, SIM_SECTION, SHAFT_TASK_SECTION, PEG_TASK_SECTION,
                             *own), (("robot_bridge_node", "sim.yaml"), *cells), robots),
        NodeSettings("hardware", (HARDWARE_SECTION, *franka.parameters), franka.config_files),
        NodeSettings("bridge", (ROBOT_SECTION, *TORQUE.controller_sections,
                                POSITION.controller_sections[0]),
                     (("robot_bridge_node", "bridge.yaml"),), robots),
        NodeSettings("wrench_estimator", (ROBOT_SECTION, EKF_SECTION),
                     (("robot_bridge_node", "wrench_estimator.yaml"),)),
        NodeSettings("recorder", (RECORDER_SECTION,), (("robot_bridge_node", "recorder.yaml"),)),
        NodeSettings("executor", (TASK_CHOICE_SECTION, *EXECUTOR_SECTIONS,
                                  TASK_SECTIONS["residual"], TASK_SECTIONS["peg"],
                                  SHAFT_TASK_SECTION, PEG_TASK_SECTION),
                     (("qg_learning_node", "executor.yaml"), *cells),
                     ((nextage_stack, (("qg_learning_node", "executor_nextage.yaml"),)),)),
        NodeSettings("learner", LEARNER_SECTIONS, (("qg_learning_node", "learner.yaml"),),
                     ((nextage_stack, (("qg_learning_node", "learner_nextage.yaml"),)),)),
    ]


def extra_rows() -> list[Setting]:
    """Settings that are not a node parameter, each with its one home."""
    from qg_experiments.profile import PegBudget
    return [
        Setting("state and action sizes", ("learner",),
                "the executor's latched `executor/task_spec` (from `task.observation`, or "
                "`task.kind: peg`)", "-", "follows the executor"),
        Setting("peg discount (experiments 5, 6)", ("experiments",),
                "code: `PegBudget.gamma` (a profile of config/experiments.yaml may set it)",
                PegBudget.gamma, "-"),
        Setting("experiment budgets and variants (`profiles.*`: seeds, cells, a variant's "
                "state or gamma)", ("experiments",), "config/experiments.yaml", "-", "-"),
        Setting("the free peg environment (experiment 5; every key)", ("experiments",),
                "config/peg_env.yaml (the `peg` environment plugin of sim_robot_node)", "-",
                "-"),
    ]


def _code_home(leaf: Leaf, section: ParameterSection) -> str:
    field = leaf.name[len(section.prefix) + 1:] if section.prefix else leaf.name
    return f"code: `{section.config.__name__}.{field}`"


def _run_time(section: ParameterSection, leaf: Leaf) -> str:
    field = leaf.name[len(section.prefix) + 1:] if section.prefix else leaf.name
    return f"settable, {section.applies}" if field in section.runtime else "read-only"


def settings(nodes: Sequence[NodeSettings] | None = None) -> list[Setting]:
    """One row per parameter name (a name several nodes declare alike is one row)."""
    rows: dict[str, Setting] = {}
    for node in node_settings() if nodes is None else nodes:
        shipped = shipped_defaults(node.node, node.files)
        overlays = [(label, shipped_defaults(node.node, files)) for label, files in node.overlays]
        for section in node.sections:
            for leaf in leaves(section):
                value, home = shipped.get(leaf.name, (leaf.default, _code_home(leaf, section)))
                given = [(label, *values[leaf.name]) for label, values in overlays
                         if leaf.name in values]
                if len(given) == 1 and leaf.name not in shipped \
                        and ros_value(given[0][1], leaf.type) == leaf.default:
                    home = f"{given[0][2]} ({given[0][0]} only)"    # the code default agrees
                else:
                    home += "".join(f"; {label}: {file} = {over!r}"
                                    for label, over, file in given)
                row = Setting(leaf.name, (node.node,), home, value, _run_time(section, leaf))
                known = rows.get(leaf.name)
                if known is not None and (known.home, known.value) == (row.home, row.value):
                    row = dataclasses.replace(known, nodes=known.nodes + row.nodes)
                elif known is not None:
                    raise ValueError(f"{leaf.name}: {known.nodes} and {node.node} give it "
                                     f"different homes ({known.home}, {row.home})")
                rows[leaf.name] = row
    return sorted(rows.values(), key=lambda r: (r.nodes[0], r.name)) + extra_rows()


def disagreements(nodes: Sequence[NodeSettings] | None = None) -> list[str]:
    """Every code default that differs from the value a node's shipped YAML gives it."""
    found = []
    for node in node_settings() if nodes is None else nodes:
        shipped = shipped_defaults(node.node, node.files)
        for section in node.sections:
            for leaf in leaves(section):
                if leaf.name in shipped:
                    value, file = shipped[leaf.name]
                    if ros_value(value, leaf.type) != leaf.default:
                        found.append(f"{node.node} {leaf.name}: code default {leaf.default!r}, "
                                     f"{file} {value!r}")
    return found


def markdown(rows: Sequence[Setting]) -> str:
    """The table as docs/design.md shows it."""
    lines = ["| setting | node | home | value | at run time |", "|---|---|---|---|---|"]
    for r in rows:
        value = f"`{r.value!r}`" if r.value != "-" else "-"
        lines.append(f"| `{r.name}` | {', '.join(r.nodes)} | {r.home} | {value} | "
                     f"{r.run_time} |")
    return "\n".join(lines)


def main() -> None:
    print("\n".join((TABLE_START, markdown(settings()), TABLE_END)))


if __name__ == "__main__":
    main()
