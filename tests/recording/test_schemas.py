"""ros2msg schema texts: rosbag2's layout, and parseable by mcap_ros2 for every recorded type."""

from __future__ import annotations

import pytest
from mcap_ros2._dynamic import generate_dynamic
from qg_recording.episode_recorder import TOPICS
from qg_recording.schemas import SEPARATOR, MsgNotFoundError, normalize_type_name, schema_text


def test_joint_state_schema_inlines_each_dependency_once() -> None:
    text = schema_text("sensor_msgs/msg/JointState")
    assert text.startswith("# This is a message that holds data")
    blocks = text.split(f"\n{SEPARATOR}\n")
    assert [b.splitlines()[0] for b in blocks[1:]] == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
    assert "float64[] effort" in blocks[0]


def test_ground_truth_resolves_same_package_types() -> None:
    heads = [line for line in schema_text("qg_interfaces/msg/GroundTruth").splitlines() if line.startswith("MSG: ")]
    assert heads == ["MSG: geometry_msgs/Wrench", "MSG: geometry_msgs/Vector3", "MSG: std_msgs/Header",
                     "MSG: builtin_interfaces/Time"]


@pytest.mark.parametrize("type_name", sorted({spec.type_name for spec in TOPICS.values()}))
def test_mcap_ros2_builds_a_decoder_for_every_recorded_type(type_name: str) -> None:
    assert type_name in generate_dynamic(type_name, schema_text(type_name))


def test_bad_and_unknown_type_names() -> None:
    assert normalize_type_name("std_msgs/String") == normalize_type_name("std_msgs/msg/String") == ("std_msgs", "String")
    with pytest.raises(ValueError, match="pkg/msg/Type"):
        normalize_type_name("JointState")
    with pytest.raises(MsgNotFoundError, match="no definition of no_such_pkg/msg/Thing"):
        schema_text("no_such_pkg/msg/Thing")
