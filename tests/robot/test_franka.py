"""``robot:=franka`` (franka_robot_node) against franky-sim's MuJoCo FR3 on a private loopback
address: the bridge's model of the FR3 matches the simulated arm, the plugin connects and holds,
subtracts exactly the gravity the robot adds, the bridge's loop moves the free arm the way a
wrench setpoint says, refused torques never reach libfranka, a missed signal timeout is a fault
until recovered, and an unreachable address is refused in time with its reason."""
from __future__ import annotations

import contextlib
import os
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from franka_robot_node.core.fr3_description import FR3_READY, fr3_arm
from franka_robot_node.core.franka_arm import (
    FCI_PORT,
    FrankaConnectError,
    FrankaFault,
    TorqueRejected,
)
from franka_robot_node.core.franka_config import FrankaConfig
from franka_robot_node.plugin import FRANKA, describe_franka
from franka_sim_node.core.franky_sim_host import FrankySimHost
from franka_sim_node.core.franky_sim_scene import CELL_PREFIX, PARK_HEIGHT, parked_q
from franka_sim_node.franka_sim import DEFAULT_SCENE, scene_extensions, scene_params, spawn
from qg_common.shaft_task import ShaftTaskGeometry
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.arm_model import ArmModel
from robot_bridge_node.core.hardware_interface import robot_defaults
from robot_bridge_node.core.loop_clock import MAX_STATE_GAP, StateClock
from robot_bridge_node.core.robot_loop import build_loop
from sim_robot_node.core.shaft_scene_config import ShaftSceneConfig

#: A loopback address of this test run's own (franky-sim binds libfranka's fixed port 1337).
ADDRESS = f"127.0.{35 + os.getpid() % 200}.{1 + os.getpid() % 200}"
UNSERVED = f"127.0.{35 + os.getpid() % 200}.250"
DEMO_SCENE = "franka_sim_node.core.franky_sim_scene:demo_scene"


def test_the_bridges_fr3_model_is_franky_sims_arm():
    """Pinocchio reads franky-sim's FR3 URDF (hand, fingers locked): its joints, the datasheet's
    limits, and within 0.05 kg and 0.25 Nm the masses and gravity torques of franky-sim's MuJoCo
    arm (its hand weighs 0.76 kg there, 0.71 kg in the URDF)."""
    model = ArmModel.from_description(describe_franka({"franka": {"tool": {"mass": 0.0}}}))
    assert model.joint_names == tuple(f"fr3_joint{i}" for i in range(1, 8))
    np.testing.assert_array_equal(model.limits.torque, [87, 87, 87, 87, 12, 12, 12])
    np.testing.assert_array_equal(model.limits.torque_rate, np.full(7, 1000.0))
    host = FrankySimHost(UNSERVED)
    try:
        m, d = host.sim.model, host.sim.data
        link1 = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "robot0_fr3_link1")
        assert m.body_subtreemass[link1] == pytest.approx(
            sum(i.mass for i in model.model.inertias[1:]), abs=0.05)
        rng = np.random.default_rng(0)
        for _ in range(3):
            q = np.array(FR3_READY) + rng.uniform(-0.4, 0.4, 7)
            d.qpos[host.robot._qpos_addrs] = q
            d.qvel[:] = 0.0
            mujoco.mj_forward(m, d)
            np.testing.assert_allclose(d.qfrc_bias[host.robot._dof_addrs], model.gravity(q),
                                       atol=0.25)
            assert np.abs(model.gravity(q)).max() > 10.0
        # The ready pose holds the tool centre point down, 0.45 m in front and 0.31 m up.
        kinematics = model.kinematics(np.array(FR3_READY))
        np.testing.assert_allclose(kinematics.position, [0.45, 0.0, 0.31], atol=1e-3)
        np.testing.assert_allclose(kinematics.rotation, np.diag([1.0, -1.0, -1.0]), atol=1e-3)
    finally:
        host.close()
    assert pin.buildModelFromUrdf(fr3_arm().urdf).nq == 9       # 7 joints and 2 fingers


def test_the_fr3s_urdf_is_the_plugins_own_and_franky_sims_model():
    """The real arm's plugin ships the FR3's URDF (a real arm's computer needs no simulator),
    and it is franky-sim's: the same joints, limits, masses and inertias."""
    import importlib.util
    ours = fr3_arm().urdf
    assert "franky_sim" not in ours and Path(ours).is_file()
    spec = importlib.util.find_spec("franky_sim")
    if spec is None:
        pytest.skip("franky-sim is not installed")
    theirs = Path(next(iter(spec.submodule_search_locations))) / "assets" / "fr3.urdf"
    a, b = pin.buildModelFromUrdf(ours), pin.buildModelFromUrdf(str(theirs))
    assert list(a.names) == list(b.names) and a.nq == b.nq == 9
    for field in ("effortLimit", "velocityLimit", "lowerPositionLimit", "upperPositionLimit"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    for x, y in zip(a.inertias, b.inertias):
        assert x.mass == y.mass and np.array_equal(x.inertia, y.inertia)
    assert sum(i.mass for i in a.inertias) > 16.0


@pytest.fixture(scope="module")
def franky_sim():
    # The demo's block and held cylinder, not the task's cell: these tests hold the arm with
    # gravity alone, which the cell's unknown payload (the realistic arm's 0.1 kg) would sag.
    process = spawn(ADDRESS, "--realtime-priority", "40", "--scene", DEMO_SCENE)
    yield process
    process.terminate()
    process.wait(10)


@pytest.fixture(scope="module")
def connected(franky_sim):
    """The robot, driven at the loop process's realtime priority (SCHED_FIFO 50: libfranka's
    thread inherits it) as the stack drives it: at normal priority a loaded test machine stalls
    the test's loop past the 50 ms signal timeout."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
    except OSError:
        pass
    robot = FRANKA.create({"franka": {"address": ADDRESS}})
    yield robot
    robot.hardware.close()
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


@pytest.fixture
def robot(connected):
    """The connected robot; its torque motion stopped after the test (a test that pauses longer
    than the signal timeout, building a loop say, would otherwise find it ended)."""
    yield connected
    connected.hardware.close()


def _hold(arm, seconds: float) -> list[float]:
    stamps = []
    end = arm.state_time() + seconds
    while arm.state_time() < end:
        arm.read()
        stamps.append(arm.state_time())
        arm.write(arm.robot_gravity())
    return stamps


@pytest.mark.ros
def test_the_plugin_connects_holds_and_sends_what_libfranka_expects(robot):
    """One second of gravity-only torques: every read is a new millisecond of the robot's, the
    arm stays within 5 mrad, and what the robot applied (``tau_J``) minus what it was sent
    (``tau_J_d``) is the gravity the plugin subtracted, to 0.05 Nm."""
    arm = robot.hardware
    q0 = arm.read().q.copy()
    stamps = _hold(arm, 1.0)
    assert np.all(np.diff(stamps) > 0.0)
    assert len(stamps) > 500                     # a busy test machine misses some states
    assert np.abs(arm.read().q - q0).max() < 5e-3
    state = arm.robot.state
    added = np.asarray(state.tau_J) - np.asarray(state.tau_J_d)
    np.testing.assert_allclose(added, arm.robot_gravity(), atol=0.05)
    assert np.abs(added).max() > 10.0
    assert arm.command_success_rate() == 1.0


@pytest.mark.ros
def test_a_wrench_setpoint_moves_the_free_arm_the_way_it_says(robot):
    """The bridge's loop (config/bridge.yaml, the EKF, the robot's state clock) on the arm: a
    15 N push along the tool axis (down) moves the tool down, a 15 N pull moves it up."""
    from robot_bridge_node.core.torque_kind import build_ekf
    bridge = robot_defaults(FRANKA, (("robot_bridge_node", "bridge.yaml"),), "bridge")
    loop = build_loop(robot, bridge, lambda robot, model: build_ekf({}, model),
                      StateClock(robot.hardware, MAX_STATE_GAP))
    loop.begin()
    loop.settle_here()                        # the episode starts where the arm is
    moved = {}
    for force in (-15.0, 15.0):
        loop.execute(WrenchSetpoint.residual(0.0, 0.0, 0.0))     # from rest (damped)
        z0 = loop.controller.tool.position[2]
        loop.execute(WrenchSetpoint.residual(force, 0.0, 0.0))
        moved[force] = loop.controller.tool.position[2] - z0
    assert moved[-15.0] < -0.005 and moved[15.0] > 0.005, moved
    assert np.all(np.isfinite(loop.wrench_estimate))


@pytest.mark.ros
def test_a_refused_torque_never_reaches_libfranka(robot):
    """NaN and beyond-the-limit torques raise ``TorqueRejected`` in ``write``: libfranka's
    commanded torque (``tau_J_d``) stays the last good one."""
    arm = robot.hardware
    _hold(arm, 0.05)
    good = np.asarray(arm.robot.state.tau_J_d).copy()
    bad = arm.robot_gravity()
    for value in (np.nan, np.inf, 200.0):
        tau = bad.copy()
        tau[0] = value
        arm.read()
        with pytest.raises(TorqueRejected):
            arm.write(tau)
    with pytest.raises(TorqueRejected):
        arm.write(np.zeros(6))
    time.sleep(0.01)
    commanded = np.asarray(arm.robot.state.tau_J_d)
    assert np.all(np.isfinite(commanded))
    np.testing.assert_allclose(commanded, good, atol=0.5)
    _hold(arm, 0.05)                              # the motion still takes good torques


@pytest.mark.ros
def test_a_missed_signal_timeout_is_a_fault_until_recovered(robot):
    """A loop silent for longer than ``signal_timeout`` (50 ms): the next read raises
    ``FrankaFault`` with libfranka's reason, writes are refused until ``recover``."""
    arm = robot.hardware
    _hold(arm, 0.05)
    time.sleep(0.15)
    with pytest.raises(FrankaFault, match="TorqueSignalTimeout"):
        arm.read()
    # the reason says whether commands had been reaching the robot (here they had, until the
    # silence: libfranka's rate over its last 100 commands)
    assert re.search(r"command success rate (0\.9\d|1\.00) at the last state",
                     arm.fault), arm.fault
    arm.read()
    with pytest.raises(FrankaFault, match="recover"):
        arm.write(arm.robot_gravity())
    assert "succeeded" in arm.recover()
    assert arm.fault is None
    assert len(_hold(arm, 0.1)) > 50


#: A loopback address whose command port takes no connection (``_silent_port``).
SILENT = f"127.0.{35 + os.getpid() % 200}.251"


@contextlib.contextmanager
def _silent_port(accepts: bool) -> Iterator[None]:
    """libfranka's port at ``SILENT``, listening but never answering. ``accepts`` False: its
    queue of one is full, so a connection is not even taken (an address that does not answer);
    True: connections are taken and never answered (something else listening there, or a robot
    that hangs)."""
    with socket.socket() as server:
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        server.bind((SILENT, FCI_PORT))
        server.listen(0 if not accepts else 8)
        filler = None if accepts else socket.create_connection((SILENT, FCI_PORT), timeout=1.0)
        try:
            yield
        finally:
            if filler is not None:
                filler.close()


@pytest.mark.ros
@pytest.mark.parametrize("address, reason", [(UNSERVED, "connection refused"),
                                             (SILENT, "no answer within 1.0 s")],
                         ids=["nothing_serves", "no_answer"])
def test_an_unreachable_address_is_refused_in_time_with_its_reason(address, reason):
    """Refused connections are retried for ``connect_timeout`` (franky-sim may be starting), a
    silent address is given up after it (libfranka alone waits 60 s); both name the address.
    Nothing is left running: libfranka is never called (an abandoned libfranka connect spins a
    core until its own 60 s are up: ~56 s of a test worker's CPU, before)."""
    start = time.monotonic()
    silent = _silent_port(accepts=False) if address == SILENT else contextlib.nullcontext()
    with silent, pytest.raises(FrankaConnectError, match=reason) as refused:
        FRANKA.create({"franka": {"address": address, "connect_timeout": 1.0}})
    assert time.monotonic() - start < 2.0
    assert address in str(refused.value)
    assert not [t.name for t in threading.enumerate() if t.name == "franka connect"]
    cpu = time.process_time()
    time.sleep(0.5)
    assert time.process_time() - cpu < 0.2       # (a spinning libfranka: ~0.48 s)


@pytest.mark.ros
def test_a_port_that_takes_the_connection_but_never_answers_is_given_up_in_time():
    """Past the port, libfranka's own handshake: a robot that never answers it is given up
    after ``connect_timeout`` too. libfranka's thread is abandoned there (and spins), so the
    attempt runs in a process of its own."""
    code = ("import time\n"
            "from franka_robot_node.plugin import FRANKA\n"
            "start = time.monotonic()\n"
            "try:\n"
            f"    FRANKA.create({{'franka': {{'address': {SILENT!r}, 'connect_timeout': 1.0}}}})\n"
            "except Exception as exc:\n"
            "    print(type(exc).__name__, exc)\n"
            "print(f'after {time.monotonic() - start:.2f} s')\n")
    with _silent_port(accepts=True):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=60, check=True).stdout
    assert f"FrankaConnectError the Franka at {SILENT}" in out and "no answer within 1.0 s" in out
    assert float(re.search(r"after ([0-9.]+) s", out).group(1)) < 2.0, out


def test_franky_sims_shaft_cell_is_the_tasks():
    """franka_sim's default scene is the shaft task's cell from the same description and YAML
    as the simulated Panda's (``mujoco_world.add_shaft_cell``, config/shaft_task.yaml and
    panda_scene.yaml): the housing where the task's fixture is, the shaft in the hand with its
    grasp point at the bridge's tool frame (to 0.2 mm), the fit's friction, and the arm parked
    with the tip 5 cm above the bearing face."""
    params = scene_params()
    geometry = ShaftTaskGeometry.from_dict(params["shaft_task"])
    cell = ShaftSceneConfig.from_dict(params["panda_scene"])
    model = ArmModel.from_description(describe_franka(params))
    park = parked_q(model, geometry)
    host = FrankySimHost(UNSERVED, scene_extensions(
        DEFAULT_SCENE, FrankaConfig.from_dict(params["franka"]), params), initial_q=park)
    try:
        m, d = host.sim.model, host.sim.data
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(d.qpos[host.robot._qpos_addrs], park, atol=1e-12)
        housing = m.body(CELL_PREFIX + "housing")
        np.testing.assert_allclose(d.mocap_pos[housing.mocapid[0]], geometry.hole_position,
                                   atol=1e-12)
        shaft = m.body(CELL_PREFIX + "shaft")
        tool = model.kinematics(park)
        np.testing.assert_allclose(d.xpos[shaft.id], tool.position, atol=2e-4)
        np.testing.assert_allclose(d.xmat[shaft.id].reshape(3, 3), tool.rotation, atol=2e-3)
        tip = d.xpos[shaft.id] + geometry.grasp_height * d.xmat[shaft.id].reshape(3, 3)[:, 2]
        np.testing.assert_allclose(tip, np.add(geometry.hole_position, [0, 0, PARK_HEIGHT]),
                                   atol=2e-4)
        assert m.body_mass[shaft.id] == pytest.approx(cell.shaft_mass)
        plunger = m.joint(CELL_PREFIX + "plunger")
        assert m.dof_frictionloss[plunger.dofadr[0]] == cell.plunger_friction
        assert d.ncon == 0 or not any(CELL_PREFIX in m.geom(c.geom1).name
                                      or CELL_PREFIX in m.geom(c.geom2).name
                                      for c in d.contact[:d.ncon])      # parked clear of it
    finally:
        host.close()


def test_the_real_arms_stack_is_the_rehearsals_without_franky_sim():
    """config/stack_fr3.yaml runs what config/stack_franka.yaml runs but franky-sim, and its
    robot process reads config/franka_real.yaml over franka.yaml: the arm's address and
    ``enforce``, nothing else changed."""
    from pathlib import Path

    from qg_bringup.stack_file import load_stack_config
    from qg_common.params import load_ros_params, merge_params, package_config
    config = Path(__file__).resolve().parents[2] / "config"
    rehearsal = {s.name: s for s in load_stack_config(config / "stack_franka.yaml")}
    real = {s.name: s for s in load_stack_config(config / "stack_fr3.yaml")}
    assert set(rehearsal) - set(real) == {"franka_sim"} and set(real) <= set(rehearsal)
    args = real["robot"].args
    overlay = Path(args[args.index("--params-file") + 1])
    assert overlay == package_config("franka_robot_node", "franka_real.yaml")
    shipped = load_ros_params(package_config("franka_robot_node", "franka.yaml"))
    laid = merge_params(shipped, load_ros_params(overlay))
    changed = {k for k in shipped["franka"] if shipped["franka"][k] != laid["franka"][k]}
    assert changed == {"address", "realtime"}
    assert FrankaConfig.from_dict(laid["franka"]).realtime == "enforce"
