"""The package split stays enforced: cores never import rclpy, the learning package imports no
robot stack, only the experiments compose bridge and learner; executables are installed."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORE_FILES = [
    *ROOT.glob("sim_robot_node/sim_robot_node/core/**/*.py"),
    *ROOT.glob("franka_robot_node/franka_robot_node/core/**/*.py"),
    *ROOT.glob("franka_sim_node/franka_sim_node/core/**/*.py"),
    *(p for p in ROOT.glob("ros_ws/src/qg_common/qg_common/*.py")
      if p.name not in ("callback_executor.py", "conversions.py", "node_parameters.py",
                        "node_runtime.py", "ros_client.py", "topics.py")),
    *ROOT.glob("robot_bridge_node/robot_bridge_node/core/**/*.py"),
    *ROOT.glob("qg_learning_node/qg_learning_node/executor/**/*.py"),
    *ROOT.glob("qg_learning_node/qg_learning_node/learner/**/*.py"),
    *ROOT.glob("qg_experiments/qg_experiments/core/**/*.py"),
]


def test_cores_do_not_import_rclpy():
    offenders = [str(p.relative_to(ROOT)) for p in CORE_FILES
                 if p.exists() and re.search(r"^\s*(import|from)\s+rclpy", p.read_text(), re.M)]
    assert len([p for p in CORE_FILES if p.exists()]) >= 5
    assert offenders == []


#: The project's Python packages and their source folders (qg_interfaces is generated).
PACKAGE_DIRS = {"qg_common": "ros_ws/src/qg_common", "qg_recording": "ros_ws/src/qg_recording",
                "robot_bridge_node": "robot_bridge_node", "sim_robot_node": "sim_robot_node",
                "franka_robot_node": "franka_robot_node", "franka_sim_node": "franka_sim_node",
                "qg_learning_node": "qg_learning_node", "qg_experiments": "qg_experiments",
                "qg_bringup": "qg_bringup"}
PROJECT = {*PACKAGE_DIRS, "qg_interfaces"}
#: What the executor and learner may import from the project: nothing of a robot stack.
LEARNING_MAY_IMPORT = {"qg_common", "qg_interfaces", "qg_recording", "qg_learning_node"}
#: Never imported by qg_learning_node, not even lazily inside a function.
LEARNING_MUST_NOT_IMPORT = {"robot_bridge_node", "sim_robot_node", "qg_experiments", "pinocchio",
                            "pybullet"}


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, at any depth (imports inside functions count), plus the
    names given to ``importlib.import_module``; relative imports resolved within the package."""
    package = ".".join(path.relative_to(_source_root(path)).with_suffix("").parts[:-1])
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            found.add(".".join(p for p in (base, node.module or "") if p))
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"):
            found.add(str(node.args[0].value))
    return found


def _source_root(path: Path) -> Path:
    """The folder a module's dotted name starts from (the one holding its top package)."""
    root = path.parent
    while (root / "__init__.py").is_file():
        root = root.parent
    return root


def sources(package: str, below: str = "") -> list[Path]:
    return sorted((ROOT / PACKAGE_DIRS[package] / package / below).rglob("*.py"))


def top_levels(paths: list[Path]) -> set[str]:
    return {name.split(".")[0] for path in paths for name in imported_modules(path)}


def test_the_import_scan_sees_lazy_relative_and_dynamic_imports(tmp_path):
    """The scan the layout tests rely on finds an import however it is written."""
    package = tmp_path / "qg_learning_node" / "learner"
    package.mkdir(parents=True)
    (package.parent / "__init__.py").write_text("")
    (package / "__init__.py").write_text("")
    module = package / "sneaky.py"
    module.write_text("import numpy as np\n"
                      "from . import replay\n"
                      "from ..cli import main\n"
                      "def later():\n"
                      "    from robot_bridge_node.core import robot_loop\n"
                      "    import importlib\n"
                      "    return importlib.import_module('pinocchio')\n")
    assert imported_modules(module) == {"numpy", "qg_learning_node.learner",
                                        "qg_learning_node.cli", "robot_bridge_node.core",
                                        "importlib", "pinocchio"}
    assert top_levels([module]) & LEARNING_MUST_NOT_IMPORT == {"robot_bridge_node", "pinocchio"}


def test_learning_imports_only_common_interfaces_and_recording():
    """The executor and learner run beside any robot: no bridge, simulator, experiment or
    Pinocchio import anywhere in qg_learning_node."""
    paths = sources("qg_learning_node")
    assert len(paths) >= 25
    offenders = {str(p.relative_to(ROOT)): sorted(top_levels([p]) & LEARNING_MUST_NOT_IMPORT)
                 for p in paths if top_levels([p]) & LEARNING_MUST_NOT_IMPORT}
    assert offenders == {}
    assert top_levels(paths) & PROJECT == LEARNING_MAY_IMPORT


def test_executor_and_learner_cores_import_no_rclpy_and_nothing_above_them():
    """``executor/`` and ``learner/`` are the pure cores: no rclpy, no messages, and from their
    own package only each other (never the node adapters or the CLI above them)."""
    cores = {"executor": sources("qg_learning_node", "executor"),
             "learner": sources("qg_learning_node", "learner")}
    assert len(cores["executor"]) >= 7 and len(cores["learner"]) >= 7
    allowed = ("qg_learning_node.executor", "qg_learning_node.learner")
    for paths in cores.values():
        for path in paths:
            names = imported_modules(path)
            where = path.relative_to(ROOT)
            assert not {n.split(".")[0] for n in names} & {"rclpy", "qg_interfaces"}, where
            upward = [n for n in names if n.startswith("qg_learning_node")
                      and not n.startswith(allowed)]
            assert upward == [], where


def test_only_the_experiments_compose_the_bridge_and_the_learner():
    """The bridge and learning packages never meet except in qg_experiments, and nothing
    imports the experiments or the command line."""
    imports = {package: top_levels(sources(package)) & PROJECT - {package}
               for package in PACKAGE_DIRS}
    composers = {p for p, used in imports.items()
                 if {"robot_bridge_node", "qg_learning_node"} <= used | {p}}
    assert composers == {"qg_experiments"}
    assert imports["qg_experiments"] >= {"robot_bridge_node", "qg_learning_node", "qg_common"}
    assert [p for p, used in imports.items() if "qg_experiments" in used] == []
    # qgl drives the processes: it starts without the robot stack, and nothing imports it
    assert not imports["qg_bringup"] & LEARNING_MUST_NOT_IMPORT
    assert [p for p, used in imports.items() if "qg_bringup" in used] == []
    # Robots are loaded by name; only franky-sim's rehearsal (a simulator itself) builds on the
    # simulated cell and the Franka's description, and the real-arm plugin imports no simulator.
    assert [p for p, used in imports.items() if "sim_robot_node" in used] == ["franka_sim_node"]
    assert [p for p, used in imports.items() if "franka_robot_node" in used] == ["franka_sim_node"]
    assert [p for p, used in imports.items() if "franka_sim_node" in used] == []


def _exec_depends(package: str) -> set[str]:
    xml = ET.parse(ROOT / PACKAGE_DIRS[package] / "package.xml")
    return {e.text for e in xml.getroot() if e.tag in ("depend", "exec_depend")}


def test_package_xml_declares_what_the_sources_import_and_learning_needs_no_robot():
    for package in PACKAGE_DIRS:
        imported = top_levels(sources(package)) & PROJECT - {package}
        assert imported <= _exec_depends(package), package
    learning = _exec_depends("qg_learning_node")
    assert learning & PROJECT == {"qg_common", "qg_interfaces", "qg_recording"}
    assert not {d for d in learning if "pinocchio" in d or "robot_bridge" in d}


def project_modules() -> dict[str, Path]:
    """Every module of the project's packages by dotted name (a package by its ``__init__``)."""
    modules = {}
    for package in PACKAGE_DIRS:
        for path in sources(package):
            parts = path.relative_to(_source_root(path)).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Which of ``modules`` each of them imports, at any depth (lazy imports, ``TYPE_CHECKING``
    blocks and constant ``import_module`` names count): ``from a import b`` is an arrow to the
    module ``a.b`` where there is one, else to ``a``."""
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = package.rsplit(".", node.level - 1)[0] if node.level else ""
                module = ".".join(p for p in (base, node.module or "") if p)
                targets.update(f"{module}.{a.name}" if f"{module}.{a.name}" in modules else module
                               for a in node.names)
            elif (isinstance(node, ast.Call) and node.args
                  and isinstance(node.args[0], ast.Constant)
                  and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"):
                targets.add(str(node.args[0].value))
        graph[name] = {t for t in targets if t in modules and t != name}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, without
    recursion): each is a set of modules that import one another in a cycle."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
    return cycles


def test_the_cycle_finder_finds_a_cycle_and_only_cycles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"d", "f"}, "f": {"e"},
             "g": {"a"}}
    assert sorted(import_cycles(graph)) == [["a", "b", "c"], ["e", "f"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_of_the_project_imports_itself_through_others():
    """No import cycles among the project's modules (the shaft scene and its worlds, the two
    run backends had one each): a leaf module holds what both sides of a cycle needed."""
    modules = project_modules()
    assert len(modules) >= 150, len(modules)
    graph = import_graph(modules)
    # the scan sees the arrows that made the old cycles
    assert "sim_robot_node.core.shaft_scene_config" in graph["sim_robot_node.core.shaft_world"]
    assert "qg_experiments.run_worker" in graph["qg_experiments.ray_backend"]
    assert import_cycles(graph) == []


#: The Gymnasium environments that need nothing but this Python (``gym_envs.ENV_IDS``); the
#: one that drives a robot process over ROS 2, ``ros_insertion``, is the exception.
GYM_IN_PROCESS = ["qg_experiments.gym_envs", "qg_experiments.gym_envs.insertion",
                  "qg_experiments.gym_envs.peg", "qg_experiments.gym_envs.residual_env",
                  "qg_experiments.gym_envs.rendering",
                  "qg_experiments.gym_envs.sparse_mountain_car"]


def test_the_design_documents_import_graph_is_the_codes():
    """docs/design.md's package graph is what the code imports (``scripts/import_graph.py``)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from import_graph import block
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    assert block() in (ROOT / "docs" / "design.md").read_text(), (
        "docs/design.md's import graph is stale: paste `python scripts/import_graph.py`")


def test_the_gym_package_imports_no_rclpy_and_no_messages():
    """What the in-process environments import, followed through every module of the project
    they reach (lazily too), never reaches rclpy or a message package: a Gymnasium user needs
    no ROS environment."""
    modules = project_modules()
    graph = import_graph(modules)
    reached, todo = set(), list(GYM_IN_PROCESS)
    while todo:
        name = todo.pop()
        if name not in reached:
            reached.add(name)
            todo.extend(graph[name])
    assert "qg_experiments.core.insertion_robot" in reached
    assert "robot_bridge_node.core.robot_loop" in reached
    # the core's robot, not the runner's training loop and its learner
    assert not [m for m in reached if m.startswith(("qg_experiments.runner",
                                                    "qg_experiments.training",
                                                    "qg_learning_node.learner.ddpg"))]
    # the frames' kinematics, not their tf messages; the renderer's lookup, not the CLI; no
    # bag code, which parses the message definitions
    assert "robot_bridge_node.core.frame_kinematics" in reached
    assert not [m for m in reached if m.startswith(("qg_recording", "qg_bringup",
                                                    "robot_bridge_node.core.robot_frames",
                                                    "robot_bridge_node.core.tick_messages"))]
    outside = {n.split(".")[0] for m in reached for n in imported_modules(modules[m])}
    assert not outside & {"rclpy", "qg_interfaces", "rosidl_runtime_py", "rosidl_adapter",
                          "torch"}, \
        sorted(m for m in reached if {n.split(".")[0] for n in imported_modules(modules[m])}
               & {"rclpy", "qg_interfaces", "rosidl_runtime_py", "rosidl_adapter", "torch"})
    # the scan would see it: the ROS environment's module imports messages and rclpy's client
    assert "qg_interfaces.msg" in imported_modules(modules["qg_experiments.gym_envs.ros_insertion"])


#: In a fresh interpreter: import the Gym package (nothing heavy may load), then make the shaft
#: insertion, check it with Gymnasium's checker and render one frame offscreen.
_GYM_IN_A_PLAIN_PYTHON = r"""
import sys
HEAVY = ("rclpy", "torch", "rosidl_adapter", "qg_interfaces", "pybullet", "mujoco")
import qg_experiments.gym_envs
print("imported", *[m for m in HEAVY if m in sys.modules])
import gymnasium
from gymnasium.utils.env_checker import check_env
env = gymnasium.make("qg_experiments:QGInsertion-v0", render_mode="rgb_array")
check_env(env.unwrapped, skip_render_check=True)
env.reset(seed=0)
frame = env.render()
print("frame", *frame.shape, frame.dtype, len({tuple(p) for p in frame.reshape(-1, 3)[::7]}))
env.close()
print("made", *[m for m in HEAVY if m in sys.modules])
"""


@pytest.mark.slow
def test_the_gym_environments_work_in_a_plain_python_without_ros():
    """``gymnasium.make("qg_experiments:QGInsertion-v0")``, Gymnasium's checker and an
    ``rgb_array`` frame in the venv's Python with a bare environment (no ROS environment
    sourced, no variable of the stack set), as a Gymnasium user runs it. (3.4-4.7 s on the
    two cores, 26 s while others load them: most of it both engines and the robot.)"""
    plain = {"PATH": "/usr/bin:/bin", "HOME": str(Path.home())}
    out = subprocess.run(["env", "-i", *(f"{k}={v}" for k, v in plain.items()), sys.executable,
                          "-c", _GYM_IN_A_PLAIN_PYTHON], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    lines = {line.split()[0]: line.split()[1:] for line in out.stdout.splitlines()
             if line.split() and line.split()[0] in ("imported", "frame", "made")}
    assert lines["imported"] == []               # registering loads none of them
    height, width, channels, dtype, colours = lines["frame"]
    assert (int(height), int(width), int(channels), dtype) == (336, 448, 3, "uint8")
    assert int(colours) > 20                     # a picture, not a blank frame
    # making the environment loads the simulator, never ROS or the learner's torch
    assert not {"rclpy", "torch", "rosidl_adapter", "qg_interfaces"} & set(lines["made"]), \
        lines["made"]


#: What the experiments' core (``qg_experiments.core``: settings, robot, task) never loads.
CORE_MUST_NOT_IMPORT = {"rclpy", "torch", "qg_interfaces", "rosidl_adapter", "rosidl_runtime_py",
                        "rosbags", "qg_recording"}


#: Words of one task (the shaft in its bearing) that the hardware-agnostic bridge never names.
TASK_WORDS = ("shaft", "bore", "bearing", "housing", "peg")


def task_identifiers(path: Path) -> set[str]:
    """The names ``path`` defines or uses (functions, classes, arguments, variables,
    attributes) that contain one of ``TASK_WORDS``; docstrings and comments do not count."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.append(node.name)
        elif isinstance(node, ast.arg):
            names.append(node.arg)
        elif isinstance(node, ast.Name):
            names.append(node.id)
        elif isinstance(node, ast.Attribute):
            names.append(node.attr)
        found.update(n for n in names if any(w in n.lower() for w in TASK_WORDS))
    return found


def test_the_bridge_names_no_task(tmp_path):
    """The bridge drives any arm at any task: its code names no part of the shaft task (its
    resets speak of a held part, a fixture and an approach axis)."""
    sneaky = tmp_path / "sneaky.py"
    sneaky.write_text("def _withdraw(start):\n    out_of_bore = -start.axis\n    return out_of_bore\n")
    assert task_identifiers(sneaky) == {"out_of_bore"}
    offenders = {str(p.relative_to(ROOT)): sorted(task_identifiers(p))
                 for p in sources("robot_bridge_node") if task_identifiers(p)}
    assert offenders == {}


def test_the_experiments_core_depends_on_nothing_that_composes_it():
    """The core builds the settings, the robot and the task from the bridge's and executor's
    cores only: every module it reaches (lazily too) imports no ROS, no torch and no message
    definitions, and nothing of ``qg_experiments`` outside ``core``; the runner's training, the
    Gym environment and the run specs are built on it."""
    modules = project_modules()
    graph = import_graph(modules)
    core = [m for m in modules if m.startswith("qg_experiments.core")]
    assert {"qg_experiments.core.stack_settings", "qg_experiments.core.insertion_robot"} <= set(core)
    reached, todo = set(), list(core)
    while todo:
        name = todo.pop()
        if name not in reached:
            reached.add(name)
            todo.extend(graph[name])
    assert "robot_bridge_node.core.robot_loop" in reached          # the scan follows the arrows
    assert [m for m in reached if m.startswith("qg_experiments")
            and not m.startswith("qg_experiments.core")] == []
    heavy = {m: sorted({n.split(".")[0] for n in imported_modules(modules[m])}
                       & CORE_MUST_NOT_IMPORT) for m in reached}
    assert {m: h for m, h in heavy.items() if h} == {}
    for user in ("qg_experiments.training", "qg_experiments.run_spec",
                 "qg_experiments.gym_envs.insertion", "qg_experiments.episodes"):
        assert any(t.startswith("qg_experiments.core") for t in graph[user]), user


def test_the_experiments_core_builds_and_steps_the_robot_where_torch_and_ros_cannot_load():
    """What the scan above reads, at run time: in a fresh interpreter that refuses rclpy, torch
    and the message packages, the core loads the settings, builds the robot and takes a step."""
    code = _REFUSE + r"""
import numpy as np
from qg_experiments.core import InsertionRobot, StackSettings
robot = InsertionRobot(StackSettings.load().with_arm_seed(0))
start = robot.reset(0)
after = robot.step(np.zeros(2))
print("stepped", robot.steps, robot.sim_time > 0, robot.settings.engine,
      bool(np.isfinite(after.tool_position).all()))
robot.close()
"""
    out = subprocess.run([sys.executable, "-c", code, ",".join(CORE_MUST_NOT_IMPORT)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split()[-5:] == ["stepped", "1", "True", "mujoco", "True"], out.stdout


def test_executables_are_where_ros2_run_looks():
    install = ROOT / "ros_ws" / "install"
    for pkg, exe in [("sim_robot_node", "sim"), ("robot_bridge_node", "bridge"),
                     ("robot_bridge_node", "wrench_estimator"), ("robot_bridge_node", "robot"),
                     ("qg_learning_node", "executor"), ("qg_learning_node", "learner"),
                     ("qg_bringup", "qgl")]:
        assert (install / pkg / "lib" / pkg / exe).is_file(), f"{pkg}/{exe}"
        marker = install / pkg / "share" / "ament_index" / "resource_index" / "packages" / pkg
        assert marker.is_file(), marker


#: Prelude of a fresh interpreter in which the top-level packages named in argv[1]
#: (comma-separated) cannot be imported at all.
_REFUSE = r"""
import importlib, pkgutil, sys

refused = set(sys.argv[1].split(","))

class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in refused:
            raise ImportError(f"{name} must not be imported here")
        return None

sys.meta_path.insert(0, Refuse())
"""
#: Then imports every module of the packages named in argv[2:].
_IMPORT_EVERYTHING_REFUSING = _REFUSE + r"""
imported = []
for top in sys.argv[2:]:
    package = importlib.import_module(top)
    imported.append(top)
    for module in pkgutil.walk_packages(package.__path__, top + "."):
        if not module.name.endswith("__main__"):
            importlib.import_module(module.name)
            imported.append(module.name)
print(len(imported), " ".join(imported))
"""


def import_everything(refused: set[str], packages: list[str],
                      env: dict[str, str] | None = None) -> list[str]:
    """The modules a fresh interpreter imported (all of ``packages``) while refusing ``refused``."""
    out = subprocess.run([sys.executable, "-c", _IMPORT_EVERYTHING_REFUSING, ",".join(refused),
                          *packages], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    count, names = out.stdout.strip().splitlines()[-1].split(" ", 1)
    assert int(count) == len(names.split())
    return names.split()


@pytest.mark.ros
def test_bridge_learning_and_experiments_import_without_the_simulator():
    """No arrow from the bridge, learning or experiments to the simulator or the Franka plugin:
    every module of the common, recording, bridge, learning and experiment packages imports
    where ``sim_robot_node``, ``franka_robot_node`` and libfranka's client cannot."""
    names = import_everything({"sim_robot_node", "pybullet", "franka_robot_node", "franky",
                               "franka_sim_node", "franky_sim", "mujoco"},
                              ["qg_common", "qg_recording", "robot_bridge_node",
                               "qg_learning_node", "qg_experiments"])
    assert len(names) >= 80, names
    for module in ("robot_bridge_node.robot_process", "robot_bridge_node.core.robot_loop",
                   "qg_experiments.runner", "qg_experiments.environments", "qg_experiments.toys",
                   "qg_learning_node.executor_node"):
        assert module in names


@pytest.mark.ros
def test_the_real_arms_plugin_imports_without_any_simulator():
    """A real Franka's computer needs libfranka's client, not a physics engine: every module of
    ``franka_robot_node`` imports where pybullet, MuJoCo, franky-sim and the simulated robots
    cannot (the FR3's URDF file is found, not imported, in franky-sim's package)."""
    names = import_everything({"sim_robot_node", "pybullet", "mujoco", "franky_sim",
                               "franka_sim_node"}, ["franka_robot_node"])
    assert {"franka_robot_node.plugin", "franka_robot_node.core.franka_arm"} <= set(names), names


@pytest.mark.ros
def test_the_nodes_and_qgl_start_without_torch_or_scipy():
    """Only the learner's networks need PyTorch: the executor runs the published actor in
    numpy, and the learner node loads torch when it builds its networks (its settings are
    checked without it, ``learner_config``). Importing torch and SciPy made every executor
    start 1.5 s slower (1.71 s against 0.22 s to import the node)."""
    code = _REFUSE + ("import qg_learning_node.executor_node, robot_bridge_node.robot_process, "
                      "qg_learning_node.learner_node, qg_bringup.main\n")
    out = subprocess.run([sys.executable, "-c", code, "torch,scipy"], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]


@pytest.mark.ros
def test_learning_imports_where_no_robot_stack_can():
    """The executor and learner nodes, the CLI and the cores import where neither bridge nor
    simulator nor experiments can: what the scan above reads, checked at run time. (Pinocchio
    still loads in the nodes, through qg_common's message conversions: ``qg_common.rotations``
    is Pinocchio's SO(3) maps. The cores import without it, see the plain-session test.)"""
    names = import_everything(LEARNING_MUST_NOT_IMPORT - {"pinocchio"},
                              ["qg_learning_node", "qg_bringup"])
    assert len(names) >= 25, names
    for module in ("qg_learning_node.executor_node", "qg_learning_node.learner_node",
                   "qg_bringup.main", "qg_learning_node.learner.learner_core"):
        assert module in names


#: Builds the QG-DDPG learner core and runs one training cycle (see test_learner_core.py).
_LEARN_WITHOUT_ROS = r"""
import numpy as np, torch
from qg_learning_node.learner.learner_core import LearnerConfig, LearnerCore
torch.manual_seed(0)
core = LearnerCore(LearnerConfig.from_dict(
    {"ddpg": {"bounds": "qgraph+apriori", "actor_hidden": [16, 16], "critic_hidden": [16, 16]},
     "zero_action": [0.0, 0.0], "iterations_per_cycle": 3}), 4, 2)
rng = np.random.default_rng(0)
s = rng.uniform(-1, 1, 4)
due = []
for t in range(20):
    s2 = rng.uniform(-1, 1, 4)
    due.append(core.add_transition(s, rng.uniform(-1, 1, 2), -1.0, s2, False))
    s = s2
print(due.index(True), core.train_cycle()["actor_version"], core.graph.num_real,
      "torch._dynamo" in sys.modules)
"""


@pytest.mark.slow
def test_executor_and_learner_cores_work_in_a_plain_python_session():
    """QG-DDPG without ROS: in an interpreter with no ROS environment, where rclpy, messages,
    bridge, simulator, experiments and Pinocchio cannot be imported, every module of the two
    cores imports and the learner core trains."""
    plain = {"PATH": "/usr/bin:/bin", "HOME": str(Path.home())}
    refused = LEARNING_MUST_NOT_IMPORT | {"rclpy", "qg_interfaces", "rosidl_runtime_py"}
    cores = ["qg_learning_node.executor", "qg_learning_node.learner"]
    out = subprocess.run([sys.executable, "-c", _IMPORT_EVERYTHING_REFUSING + _LEARN_WITHOUT_ROS,
                          ",".join(refused), *cores],
                         capture_output=True, text=True, timeout=120, env=plain)
    assert out.returncode == 0, out.stderr[-3000:]
    imported, learned = out.stdout.strip().splitlines()[-2:]
    assert {"qg_learning_node.learner.qgraph", "qg_learning_node.learner.replay",
            "qg_learning_node.learner.ddpg", "qg_learning_node.executor.episode"} \
        <= set(imported.split()[1:])
    # training is due after the 20th step; one cycle makes actor version 1; torch.optim's
    # compiler hooks (TorchDynamo, 1.2 s of CPU) are not loaded (learner/adam.py)
    assert learned.split() == ["19", "1", "20", "False"]


def test_robots_are_plugins_found_by_name():
    from robot_bridge_node.core.hardware_interface import robot_names, robot_plugin
    assert "sim_panda" in robot_names()
    assert robot_plugin("sim_panda").interface == "torque"
    assert "sim_nextage" in robot_names()
    assert robot_plugin("sim_nextage").interface == "position"
    assert robot_plugin("sim_xarm7").interface == "torque"
    with pytest.raises(ValueError, match="no robot plugin named 'franka_typo'"):
        robot_plugin("franka_typo")


def test_interface_kinds_are_registered_and_every_robot_names_a_registered_one():
    from robot_bridge_node.core.hardware_interface import robot_names, robot_plugin
    from robot_bridge_node.core.interface_kinds import interface_kind, interface_kind_names
    assert interface_kind_names() == ["position", "torque"]
    for robot in robot_names():
        kind = interface_kind(robot_plugin(robot).interface)
        assert kind.name == robot_plugin(robot).interface
    assert interface_kind("torque").command_field == "effort"
    assert [s.prefix for s in interface_kind("torque").estimator_sections] == ["ekf"]
    assert interface_kind("position").separate_estimator is None
    with pytest.raises(ValueError, match=r"no hardware interface kind named 'velocty'.*'torque'"):
        interface_kind("velocty")


#: The modules that drive any robot: they look its interface kind up, never name one.
ROBOT_AGNOSTIC = ["robot_bridge_node/robot_bridge_node/bridge_node.py",
                  "robot_bridge_node/robot_bridge_node/robot_process.py",
                  "robot_bridge_node/robot_bridge_node/estimator_node.py",
                  "robot_bridge_node/robot_bridge_node/simulation_node.py",
                  "sim_robot_node/sim_robot_node/sim_node.py"]


def test_no_node_matches_an_interface_kind_or_a_robot_by_name():
    """Interface kinds are found in the registry: no module that drives robots compares a kind's
    name, imports a kind or names a robot's description."""
    named = re.compile(r"""["'](torque|position)["']|torque_kind|position_kind|panda|xarm""",
                       re.IGNORECASE)
    offenders = {path: named.findall(_code_without_docs(ROOT / path)) for path in ROBOT_AGNOSTIC}
    assert {path: found for path, found in offenders.items() if found} == {}
    assert named.findall('if kind == "torque": ...') == ["torque"]     # the check can fail


def _code_without_docs(path: Path) -> str:
    """The module's code as Python reads it: no comments, no docstrings."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) \
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
            body[0] = ast.Pass()
    return ast.unparse(tree)


#: The sources of the packages the stack installs (build scripts excepted).
PACKAGE_SOURCES = [p for d in PACKAGE_DIRS.values()
                   for p in (ROOT / d).rglob("*.py") if p.name != "setup.py"]


def test_no_package_finds_files_by_walking_up_from_its_own_source():
    assert len(PACKAGE_SOURCES) >= 80
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
    # the experiments' profiles belong to the experiments' package
    path = package_config("qg_experiments", "experiments.yaml")
    assert path.parent.parts[-3:] == ("share", "qg_experiments", "config"), path
    assert path.resolve() == config_file("experiments.yaml").resolve() \
        == (ROOT / "config" / "experiments.yaml").resolve()


def test_config_files_are_found_in_the_workspace_without_the_ament_index(monkeypatch, tmp_path):
    """A plain Python (no sourced shell, no ament index) finds a package's config file in the
    workspace ``$QG_ROS_INSTALL`` names, which the venv's interpreter sets; with neither, the
    error says what to do."""
    from qg_common.params import ConfigError, package_config
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.setenv("QG_ROS_INSTALL", str(ROOT / "ros_ws" / "install"))
    path = package_config("sim_robot_node", "panda_scene.yaml")
    assert path.parent.parts[-3:] == ("share", "sim_robot_node", "config")
    assert path.resolve() == (ROOT / "config" / "panda_scene.yaml").resolve()
    monkeypatch.setenv("QG_ROS_INSTALL", str(tmp_path / "nowhere"))
    with pytest.raises(ConfigError, match="installed where the ament index looks.*QG_ROS_INSTALL"):
        package_config("sim_robot_node", "panda_scene.yaml")


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
             "qg_interfaces/srv/MoveToStart"]
    script = tmp_path / "show.py"
    script.write_text(_INTERFACE_SHOW)
    command = (f". '{ROOT / 'ros_ws/install/setup.bash'}' && "
               f"'{sys.executable}' '{script}' {' '.join(types)}")
    result = subprocess.run(["env", "-i", "HOME=/tmp", "PATH=/usr/bin:/bin", "bash", "-c", command],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]
    counts = dict(line.split() for line in result.stdout.splitlines())
    assert int(counts["qg_interfaces/msg/AtRest"]) >= 5   # Header, Time, Wrench, Pose, ...
