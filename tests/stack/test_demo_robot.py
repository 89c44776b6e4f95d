"""``qgl demo --robot NAME``: every process that loads a robot plugin runs NAME, nothing else
changes."""
from __future__ import annotations

from qg_bringup.stack_file import ProcessSpec, load_stack_config
from qg_bringup.stack_start import DemoSettings, with_run_settings
from qg_common.params import config_file


def test_the_robot_goes_to_the_processes_that_load_a_robot_and_to_no_other() -> None:
    settings = DemoSettings()
    specs = load_stack_config(config_file("stack.yaml")) + [
        ProcessSpec("sim", "sim_robot_node", "sim"),
        ProcessSpec("bridge", "robot_bridge_node", "bridge", ("--ros-args", "-p", "x:=1"))]
    given = {spec.name: with_run_settings(spec, settings, "sim_xarm7").args for spec in specs}
    default = {spec.name: with_run_settings(spec, settings).args for spec in specs}
    for name in ("robot", "sim", "bridge"):
        assert given[name][-2:] == ("-p", "robot:=sim_xarm7"), given[name]
        assert given[name].count("--ros-args") == 1
        assert "robot:=sim_xarm7" not in default[name]
    for name in ("learner", "executor"):
        assert given[name] == default[name] and "robot:=sim_xarm7" not in given[name]
