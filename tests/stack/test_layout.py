"""The package split stays enforced: cores never import rclpy; executables are installed."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORE_FILES = [
    *ROOT.glob("sim_robot_node/sim_robot_node/core/**/*.py"),
    *(p for p in ROOT.glob("ros_ws/src/qg_common/qg_common/*.py")
      if p.name not in ("conversions.py", "node_parameters.py", "node_runtime.py", "topics.py")),
    *ROOT.glob("robot_bridge_node/robot_bridge_node/core/**/*.py"),
    *ROOT.glob("qg_learning_node/qg_learning_node/executor/**/*.py"),
    *ROOT.glob("qg_learning_node/qg_learning_node/learner/**/*.py"),
]


def test_cores_do_not_import_rclpy():
    offenders = [str(p.relative_to(ROOT)) for p in CORE_FILES
                 if p.exists() and re.search(r"^\s*(import|from)\s+rclpy", p.read_text(), re.M)]
    assert len([p for p in CORE_FILES if p.exists()]) >= 5
    assert offenders == []


#: Every Python source folder of the project (ros_ws/src/qg_learning_node etc. are symlinks).
SOURCE_DIRS = ("qg_learning_node", "robot_bridge_node", "sim_robot_node", "ros_ws/src/qg_common",
               "ros_ws/src/qg_recording", "benchmarks", "tests")


def test_pyflakes_finds_no_undefined_name_or_dead_import_anywhere():
    """A misspelt or undefined name in a rarely taken branch (a loop thread's error path, say)
    only shows when that branch runs; in a node it then kills the process. pyflakes finds it by
    reading the source."""
    import io

    from pyflakes.api import checkRecursive
    from pyflakes.reporter import Reporter
    out = io.StringIO()
    warnings = checkRecursive([str(ROOT / d) for d in SOURCE_DIRS], Reporter(out, out))
    assert warnings == 0, out.getvalue()


def test_executables_are_where_ros2_run_looks():
    install = ROOT / "ros_ws" / "install"
    for pkg, exe in [("sim_robot_node", "sim"), ("robot_bridge_node", "bridge"),
                     ("robot_bridge_node", "wrench_estimator"), ("robot_bridge_node", "robot"),
                     ("qg_learning_node", "executor"), ("qg_learning_node", "learner"),
                     ("qg_learning_node", "qgl")]:
        assert (install / pkg / "lib" / pkg / exe).is_file(), f"{pkg}/{exe}"
        marker = install / pkg / "share" / "ament_index" / "resource_index" / "packages" / pkg
        assert marker.is_file(), marker


#: Run in a fresh interpreter where the simulator and pybullet cannot be imported at all.
_IMPORT_EVERYTHING_WITHOUT_THE_SIMULATOR = r"""
import importlib, pkgutil, sys

class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("sim_robot_node", "pybullet"):
            raise ImportError(f"{name} must not be imported here")
        return None

sys.meta_path.insert(0, Refuse())
imported = []
for top in ("qg_common", "qg_recording", "robot_bridge_node", "qg_learning_node"):
    package = importlib.import_module(top)
    imported.append(top)
    for module in pkgutil.walk_packages(package.__path__, top + "."):
        if not module.name.endswith("__main__"):
            importlib.import_module(module.name)
            imported.append(module.name)
print(len(imported), " ".join(imported))
"""


@pytest.mark.ros
def test_bridge_and_learning_import_without_the_simulator():
    """No arrow from the bridge or learning to the simulator: every module of the common,
    recording, bridge and learning packages imports where ``sim_robot_node`` cannot."""
    out = subprocess.run([sys.executable, "-c", _IMPORT_EVERYTHING_WITHOUT_THE_SIMULATOR],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    count, names = out.stdout.strip().splitlines()[-1].split(" ", 1)
    assert int(count) >= 50, names
    for module in ("robot_bridge_node.robot_process", "robot_bridge_node.core.robot_loop",
                   "qg_learning_node.experiments.runner", "qg_learning_node.executor_node"):
        assert module in names.split()


def test_robots_are_plugins_found_by_name():
    from robot_bridge_node.core.hardware_interface import robot_names, robot_plugin
    assert "sim_panda" in robot_names()
    assert robot_plugin("sim_panda").interface == "torque"
    assert "sim_nextage" in robot_names()
    assert robot_plugin("sim_nextage").interface == "position"
    with pytest.raises(ValueError, match="no robot plugin named 'franka_typo'"):
        robot_plugin("franka_typo")


#: The sources of the packages the stack installs (build scripts excepted).
PACKAGE_SOURCES = [p for d in ("ros_ws/src/qg_common", "ros_ws/src/qg_recording", "sim_robot_node",
                               "robot_bridge_node", "qg_learning_node")
                   for p in (ROOT / d).rglob("*.py") if p.name != "setup.py"]


def test_no_package_finds_files_by_walking_up_from_its_own_source():
    assert len(PACKAGE_SOURCES) >= 50
    offenders = [str(p.relative_to(ROOT)) for p in PACKAGE_SOURCES if "__file__" in p.read_text()]
    assert offenders == []


@pytest.mark.ros
def test_config_files_are_installed_to_share_and_found_through_the_ament_index(monkeypatch):
    from qg_common.params import config_file, package_config
    monkeypatch.delenv("QG_CONFIG_DIR", raising=False)
    for package, name in [("robot_bridge_node", "bridge.yaml"), ("robot_bridge_node", "sim.yaml"),
                          ("sim_robot_node", "panda_scene.yaml"),
                          ("qg_learning_node", "executor.yaml"), ("qg_learning_node", "stack.yaml")]:
        path = package_config(package, name)
        assert path.parent.parts[-3:] == ("share", package, "config"), path
        assert "install" in path.parts
        # symlink-installed from the repository's config/, the one source of the numbers
        assert path.resolve() == (ROOT / "config" / name).resolve()
        assert config_file(name) == path


def test_runs_go_to_qg_runs_dir_or_the_current_directory(monkeypatch, tmp_path):
    from qg_common.params import runs_dir
    monkeypatch.setenv("QG_RUNS_DIR", str(tmp_path / "elsewhere"))
    assert runs_dir() == tmp_path / "elsewhere"
    monkeypatch.delenv("QG_RUNS_DIR")
    monkeypatch.chdir(tmp_path)
    assert runs_dir() == tmp_path / "runs"


#: What ``ros2 interface show`` does for a type (ros2interface, rosidl_runtime_py): find its
#: package among the ament index's ``rosidl_interfaces`` resources, read the definition from the
#: package's share folder, and do the same for every field type from another package.
_INTERFACE_SHOW = r"""
import re, sys
from ament_index_python.packages import get_package_share_directory
from ament_index_python.resources import get_resource

def show(type_name, seen):
    pkg, kind, name = type_name.split("/")
    listed, _ = get_resource("rosidl_interfaces", pkg)
    assert f"{kind}/{name}.{kind}" in listed.split(), type_name
    text = open(f"{get_package_share_directory(pkg)}/{kind}/{name}.{kind}").read()
    for field_type in re.findall(r"^\s*([A-Za-z_]\w*/[A-Za-z_]\w*)", text, re.M):
        nested_pkg, nested = field_type.split("/")
        if (nested_pkg, nested) not in seen:
            seen.add((nested_pkg, nested))
            show(f"{nested_pkg}/msg/{nested}", seen)

for type_name in sys.argv[1:]:
    seen = set()
    show(type_name, seen)
    print(type_name, len(seen))
"""


def test_sourcing_the_workspace_alone_lets_ament_tools_find_every_nested_type(tmp_path):
    """``source install/setup.bash`` in a clean shell is enough for ``ros2 interface show``:
    the pip-installed std_msgs and geometry_msgs are found through the ament index."""
    types = ["qg_interfaces/msg/AtRest", "qg_interfaces/msg/WrenchSetpoint",
             "qg_interfaces/srv/ResetSim"]
    script = tmp_path / "show.py"
    script.write_text(_INTERFACE_SHOW)
    command = (f". '{ROOT / 'ros_ws/install/setup.bash'}' && "
               f"'{sys.executable}' '{script}' {' '.join(types)}")
    result = subprocess.run(["env", "-i", "HOME=/tmp", "PATH=/usr/bin:/bin", "bash", "-c", command],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]
    counts = dict(line.split() for line in result.stdout.splitlines())
    assert int(counts["qg_interfaces/msg/AtRest"]) >= 5   # Header, Time, Wrench, Pose, ...
