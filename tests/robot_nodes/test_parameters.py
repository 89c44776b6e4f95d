"""Declared parameters through the services ``ros2 param`` uses (``rcl_interfaces``), on real
node processes: each node lists only its own, with descriptions and ranges; a params file
overrides only what it names; a misspelt or out-of-range parameter stops the start; at run time
a change is applied or refused with a reason."""
from __future__ import annotations

import time

import pytest
from param_client import describe, get, listed, set_double, set_value, string

pytestmark = pytest.mark.ros


def test_each_robot_node_declares_only_its_own_parameters_read_only(stack):
    stack.start(("robot", "robot_bridge_node", "robot", ()))
    with stack.client() as cli:
        bridge, sim = listed(cli, "/bridge"), listed(cli, "/sim")
        estimator, recorder = listed(cli, "/wrench_estimator"), listed(cli, "/recorder")
        # The bridge loads the robot's plugin; the sim node is the plugin's (a real robot's
        # would be `hardware`).
        assert {"robot", "impedance.k_null", "safety.force_max", "rest.max_time",
                "loop.dt"} <= bridge
        assert {"sim.clock_mode", "panda_scene.shaft_mass"} <= sim and "robot" not in sim
        assert {"ekf.process_noise_force"} <= estimator
        assert {"record", "episodes_dir", "close_timeout", "recording.mode"} <= recorder
        assert not any(n.startswith(("panda_scene.", "sim.", "ekf.")) for n in bridge)
        assert not any(n.startswith(("impedance.", "safety.", "ekf.")) for n in sim)
        assert len(bridge) < 40 and len(recorder) < 12, (len(bridge), len(recorder))

        force = describe(cli, "/bridge", "safety.force_max")
        assert force.read_only and "feed-forward force" in force.description
        assert (force.floating_point_range[0].from_value,
                force.floating_point_range[0].to_value) == (0.0, 20.0)
        assert get(cli, "/bridge", "impedance.k_null", "rest.max_time") == [10.0, 3.0]
        assert get(cli, "/bridge", "robot") == ["sim_panda"]

        refused = set_double(cli, "/bridge", "impedance.k_null", 20.0)
        assert not refused.successful and "read-only" in refused.reason
        assert get(cli, "/bridge", "impedance.k_null") == [10.0]
    assert stack.launcher.poll() == []


def test_one_params_file_overrides_only_what_it_names_and_run_time_changes_apply(
        stack, tmp_path):
    params = tmp_path / "sigma.yaml"
    params.write_text("/**:\n  ros__parameters:\n    noise:\n      sigma: 0.5\n")
    stack.start(("executor", "qg_learning_node", "executor",
                 ("--ros-args", "--params-file", str(params))))
    with stack.client() as cli:
        names = listed(cli, "/executor")
        assert {"noise.sigma", "task.base_force", "step_timeout"} <= names
        assert not any(n.startswith(("learner.", "impedance.")) for n in names)
        # The file's one value, and the package YAML's (not the dataclass's) for the rest.
        assert get(cli, "/executor", "noise.sigma", "task.base_force", "task.observation",
                   "noise.kind") == [0.5, -15.0, "tilt_motion", "gaussian"]
        sigma = describe(cli, "/executor", "noise.sigma")
        assert not sigma.read_only and sigma.description
        assert sigma.floating_point_range[0].to_value == 10.0

        assert set_double(cli, "/executor", "noise.sigma", 0.7).successful
        assert get(cli, "/executor", "noise.sigma") == [0.7]
        too_big = set_double(cli, "/executor", "noise.sigma", 50.0)
        assert not too_big.successful and "out of range" in too_big.reason
        bad_kind = set_value(cli, "/executor", "noise.kind", string("brownian"))
        assert not bad_kind.successful and "noise kind" in bad_kind.reason
        assert set_value(cli, "/executor", "task.reward", string("sparse")).successful
        frozen = set_double(cli, "/executor", "task.base_force", -10.0)
        assert not frozen.successful and "read-only" in frozen.reason
        assert get(cli, "/executor", "noise.sigma", "noise.kind", "task.reward",
                   "task.base_force") == [0.7, "gaussian", "sparse", -15.0]
    assert stack.launcher.poll() == []


@pytest.mark.parametrize("args,message", [
    (("-p", "task.rewrd:=sparse"), "unknown parameter 'task.rewrd'"),
    (("-p", "noise.sigma:=50.0"), "'noise.sigma' refused"),
    (("-p", "noise.kind:=brownian"), "noise kind must be one of"),
])
def test_a_misspelt_or_out_of_range_parameter_stops_the_start(stack, args, message):
    stack.start(("executor", "qg_learning_node", "executor", ("--ros-args", *args)))
    deadline = time.monotonic() + 30.0
    exited = []
    while not exited and time.monotonic() < deadline:
        exited = stack.launcher.poll()
        time.sleep(0.1)
    assert exited == [("executor", 2)], stack.logs()
    assert message in stack.logs()
