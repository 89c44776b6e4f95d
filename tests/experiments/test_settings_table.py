"""One home per setting: the settings table of docs/design.md, the shipped YAML and the code
defaults agree, and what ``ros2 param describe`` says is generated from the values."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from qg_common.node_parameters import describe, leaves, shipped_defaults
from qg_experiments.settings_table import (
    TABLE_END,
    TABLE_START,
    NodeSettings,
    disagreements,
    markdown,
    node_settings,
    settings,
)
from qg_learning_node.learner.ddpg import DDPGConfig
from qg_learning_node.learner.learner_core import LearnerConfig
from qg_learning_node.learner.learner_params import LEARNER_SECTION

DESIGN = Path(__file__).resolve().parents[2] / "docs" / "design.md"


def test_the_design_documents_table_is_the_generated_one() -> None:
    text = DESIGN.read_text()
    assert TABLE_START in text and TABLE_END in text
    documented = text.split(TABLE_START)[1].split(TABLE_END)[0].strip()
    generated = markdown(settings())
    assert documented == generated, ("docs/design.md's settings table is stale: regenerate it "
                                     "with `python -m qg_experiments.settings_table`")


def test_every_setting_is_listed_once_with_one_home() -> None:
    rows = settings()
    names = [r.name for r in rows]
    assert len(names) == len(set(names)) and len(rows) > 150
    by_name = {r.name: r for r in rows}
    assert by_name["task.observation"].home == "config/executor.yaml"
    assert by_name["task.observation"].value == "tilt_motion"
    assert by_name["learner.ddpg.gamma"].home == "config/learner.yaml"
    assert by_name["learner.ddpg.gamma"].value == 0.9
    assert "observation" not in by_name           # the learner's copy is gone
    assert "task_spec" in by_name["state and action sizes"].home
    assert by_name["learner.batch_size"].run_time == "settable, from the next training cycle"
    assert by_name["learner.ddpg.gamma"].run_time == "read-only"


def test_no_code_default_contradicts_the_shipped_yaml() -> None:
    assert disagreements() == []


@dataclasses.dataclass(frozen=True)
class OldDDPG(DDPGConfig):
    """The discount's code default before it followed learner.yaml."""
    gamma: float = 0.99


@dataclasses.dataclass(frozen=True)
class OldLearner(LearnerConfig):
    ddpg: OldDDPG = dataclasses.field(default_factory=OldDDPG)


def test_a_code_default_unlike_the_yaml_is_found() -> None:
    """The check above can fail: a learner whose gamma defaults to the old 0.99."""
    learner = next(n for n in node_settings() if n.node == "learner")
    old = NodeSettings("learner", (dataclasses.replace(LEARNER_SECTION, config=OldLearner),),
                       learner.files)
    assert disagreements([old]) == ["learner learner.ddpg.gamma: code default 0.99, "
                                    "config/learner.yaml 0.9"]


@pytest.mark.parametrize("node", [n.node for n in node_settings()])
def test_each_description_names_the_shipped_value_and_its_home(node: str) -> None:
    settings_of = next(n for n in node_settings() if n.node == node)
    shipped = shipped_defaults(node, settings_of.files)
    for section in settings_of.sections:
        for leaf in leaves(section):
            value, home = shipped.get(leaf.name, (leaf.default, "code default"))
            text = describe(section, leaf, value, home)
            assert f"Default {value!r} ({home})" in text, text
            assert ("settable with `ros2 param set`" in text) != ("read-only" in text), text
