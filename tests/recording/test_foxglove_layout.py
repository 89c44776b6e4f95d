"""The shipped Foxglove layout (``config/foxglove_layout.json``) shows what the bags hold: every
panel it places is configured, and every topic and field it plots is one an episode bag records,
so a renamed topic or field fails here rather than in a user's empty plot."""
from __future__ import annotations

import json
from pathlib import Path

from qg_recording.episode_recorder import TOPICS
from qg_recording.schemas import message_fields

LAYOUT = Path(__file__).resolve().parents[2] / "config" / "foxglove_layout.json"


def _panels(tree: object) -> list[str]:
    if isinstance(tree, str):
        return [tree]
    assert isinstance(tree, dict) and tree["direction"] in ("row", "column"), tree
    return _panels(tree["first"]) + _panels(tree["second"])


def _field_type(type_name: str, path: list[str]) -> str:
    """The type of the field ``path`` (names, nested) of messages of ``type_name``."""
    for name in path:
        fields = {f.name: f for f in message_fields(type_name)}
        assert name in fields, (type_name, name, sorted(fields))
        type_name = fields[name].type_name
    return type_name


def test_the_layout_places_configured_panels_that_show_recorded_topics_and_fields() -> None:
    layout = json.loads(LAYOUT.read_text())
    panels = _panels(layout["layout"])
    assert sorted(panels) == sorted(layout["configById"])
    assert {p.split("!")[0] for p in panels} == {"3D", "Plot", "RawMessages"}
    plotted = []
    for panel, config in layout["configById"].items():
        for path in config.get("paths", []):
            topic, *fields = path["value"].split(".")
            assert topic in TOPICS, (panel, topic)
            assert _field_type(TOPICS[topic].type_name, fields) == "float64", path
            plotted.append(topic)
        if "topicPath" in config:
            assert config["topicPath"] in TOPICS
    assert {"/wrench_estimate", "/wrench_setpoint", "/sim/ground_truth"} <= set(plotted)
    three_d = layout["configById"]["3D!qg_arm"]
    (urdf,) = [layer for layer in three_d["layers"].values()
               if layer["layerId"] == "foxglove.Urdf"]
    assert (urdf["sourceType"], urdf["topic"]) == ("topic", "/robot_description")
    assert set(three_d["topics"]) <= set(TOPICS)
    assert TOPICS["/robot_description"].type_name == "std_msgs/msg/String"
