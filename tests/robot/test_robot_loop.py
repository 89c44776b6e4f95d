"""The 1 kHz loop on the simulated task, on pybullet (``sim_panda_pybullet``) at the 0.25 s step
these numbers were measured on: the three properties SPEC section 1 asks of the scene (zero
residual jams, random residuals insert, the last millimetres need > 10 N) on the realistic arm;
step completion, and the safety paths (rejection, tilt cone, watchdog) on the ideal arm, whose
motion the control law predicts exactly. The default engine's (MuJoCo's) properties at its
default step, which ends at rest, are ``test_mujoco_world.py``'s."""
from __future__ import annotations

import math

import numpy as np
import pytest
from arms import ideal, start
from qg_common.types import N_START_POSES, PoseReference, WrenchSetpoint
from robot_bridge_node.core.hardware_interface import load_robot, robot_defaults, robot_plugin
from robot_bridge_node.core.loop_clock import StateClock, TickClock
from robot_bridge_node.core.loop_core import LoopConfig
from robot_bridge_node.core.robot_loop import RobotLoop, build_loop
from robot_bridge_node.core.safety import SetpointRejected
from robot_bridge_node.core.wrench_source import MeasuredWrench

PUSH = -15.0  # [N] the constant base policy (contact convention: pressing in)


#: pybullet's step before steps ended at rest: the limit these tests' numbers were measured at.
PYBULLET_STEP = {"rest": {"max_time": 0.25}}


def _loop(params: dict | None) -> RobotLoop:
    return build_loop(load_robot("sim_panda_pybullet", params), PYBULLET_STEP,
                      estimator=lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench))


@pytest.fixture(scope="module")
def loop() -> RobotLoop:
    """The default simulated arm: the realistic Panda."""
    loop = _loop(None)
    yield loop
    loop.simulation.scene.close()


@pytest.fixture(scope="module")
def ideal_loop() -> RobotLoop:
    loop = _loop(ideal())
    yield loop
    loop.simulation.scene.close()


def run_episode(loop: RobotLoop, pose: int, max_steps: int,
                rng: np.random.Generator | None) -> tuple[bool, int, int]:
    """Residual-policy episode; ``rng`` None is the zero residual. (success, steps, at rest)."""
    loop.reset(start(pose))
    rested = 0
    for step in range(1, max_steps + 1):
        torques = (0.0, 0.0) if rng is None else tuple(3.0 * rng.uniform(-1.0, 1.0, 2))
        result = loop.execute(WrenchSetpoint.residual(PUSH, *torques))
        rested += not result.timed_out
        if result.ground_truth.success:
            return True, step, rested
    return False, max_steps, rested


@pytest.mark.parametrize("arm", ["realistic", "ideal"])
@pytest.mark.slow
def test_zero_residual_jams_from_most_starts(loop: RobotLoop, ideal_loop: RobotLoop,
                                            arm: str) -> None:
    """The base push alone jams on either arm. On the ideal arm a jammed step ends by the rest
    detector; on the realistic one the unknown payload keeps turning the shaft about its tip a
    little every step (the reference is reset at each step), so fewer steps come to rest."""
    loop = loop if arm == "realistic" else ideal_loop
    outcomes = [run_episode(loop, k, 40, None) for k in range(N_START_POSES)]
    jammed = sum(not success for success, _, _ in outcomes)
    assert jammed >= 6, outcomes
    rest_fraction = sum(r for _, _, r in outcomes) / sum(n for _, n, _ in outcomes)
    assert rest_fraction > (0.9 if arm == "ideal" else 0.2)
    depth = loop.simulation.scene.ground_truth().insertion_depth
    assert 0.0 < depth < 0.005  # wedged at the bore entrance


@pytest.mark.ros     # full tier only: 7 of the 8 episodes (up to 100 steps) decide: 17 s of CPU
@pytest.mark.slow
def test_uniform_random_residuals_insert_from_at_least_six_of_eight_starts(
        loop: RobotLoop, let_alone_tests_in) -> None:
    """The issue's bar: uniform random residuals insert from >= 6 of the 8 starts, each within
    100 steps (benchmarks/force_depth.py: 16/16 over two seeds, mean 41 steps; real robot: 32;
    the report's random bar, Gaussian: 48.4 steps). The cap was 1000: one start took 270 steps
    and half the test's time."""
    rng = np.random.default_rng(0)
    outcomes = []
    for k in range(8):       # the starts in order, until the bar is met or missed
        let_alone_tests_in()
        outcomes.append(run_episode(loop, k, 100, rng))
        failed = sum(not success for success, _, _ in outcomes)
        if failed > 2 or len(outcomes) - failed >= 6:
            break
    inserted = [steps for success, steps, _ in outcomes if success]
    print(f"random residual: {len(inserted)} of the first {len(outcomes)} starts inserted, "
          f"mean {np.mean(inserted):.1f} steps")
    assert len(inserted) >= 6, outcomes


def press_upright(loop: RobotLoop, force: float, seconds: float) -> None:
    """Hold the shaft upright over the hole axis and press with ``force`` [N] for ``seconds``."""
    scene = loop.simulation.scene
    target = scene.geometry.target_tool_position(scene.fixture)
    upright = np.diag([1.0, -1.0, -1.0])  # tool z down
    loop.command(WrenchSetpoint(np.array([0.0, 0.0, -force, 0.0, 0.0, 0.0]),
                                PoseReference(target, upright)))
    for _ in range(round(seconds / loop.config.dt)):
        loop.tick()


@pytest.mark.parametrize("force,finishes", [(9.0, False), (10.0, False), (12.0, True)])
def test_the_last_millimetres_need_a_sustained_push_above_ten_newtons(
        loop: RobotLoop, force: float, finishes: bool) -> None:
    """On the realistic arm the unknown payload's weight (about 1 N) adds to the commanded push,
    so the ring breaks away at about 10.3 N commanded instead of 11.25 N on the ideal arm
    (benchmarks/force_depth.py --arm realistic|ideal)."""
    loop.reset(start(0))
    press_upright(loop, 3.0, 1.2)  # straighten and slide gently down onto the inner ring
    gt = loop.simulation.scene.ground_truth()
    assert gt.insertion_depth == pytest.approx(loop.simulation.scene.geometry.bore_depth, abs=0.0008)
    landed = gt.plunger_travel
    assert landed < 0.0005  # only the landing impact moved the ring
    # 12 N pushes the ring its 4 mm within 1 s; below the break-away force the ring only creeps,
    # < 0.5 mm in 1 s.
    press_upright(loop, force, 1.0)
    gt = loop.simulation.scene.ground_truth()
    assert gt.success == finishes
    if not finishes:
        assert gt.plunger_travel - landed < 0.0005  # stalled, not creeping


def test_rejected_setpoint_leaves_the_running_command(ideal_loop: RobotLoop) -> None:
    loop = ideal_loop
    loop.reset(start(0))
    loop.command(WrenchSetpoint.residual(PUSH, 0.0, 0.0))
    before = loop.setpoint
    with pytest.raises(SetpointRejected):
        loop.command(WrenchSetpoint.residual(PUSH, math.nan, 0.0))
    assert loop.setpoint is before


def test_tilt_stays_inside_the_cone_under_maximal_torque(ideal_loop: RobotLoop) -> None:
    loop = ideal_loop
    loop.reset(start(0))
    loop.command(WrenchSetpoint.residual(8.0, 0.0, 0.0))  # lift out of the counterbore
    for _ in range(300):
        loop.tick()
    worst = 0.0
    for _ in range(6):  # each step re-references and tilts further
        loop.command(WrenchSetpoint.residual(0.0, 0.0, -3.0))
        for _ in range(300):
            loop.tick()
            worst = max(worst, loop.simulation.scene.ground_truth().tilt)
    limit = loop.safety.limits.tilt_max
    assert worst > limit - 0.1  # the torque did drive it to the wall
    assert worst < limit + 0.02


def test_realtime_watchdog_holds_the_pose_when_no_step_follows_a_step(
        ideal_loop: RobotLoop) -> None:
    """A step's setpoint holds until the step ends, however long the commander is silent; the
    watchdog counts from the step's end (``safety.watchdog_timeout``, 0.1 s)."""
    loop = ideal_loop
    realtime = RobotLoop(loop.hardware, loop.controller, loop.safety, loop.rest, loop.estimator,
                         LoopConfig(realtime=True), loop.simulation)
    realtime.reset(start(0))
    realtime.command(WrenchSetpoint.residual(8.0, 0.0, 0.0))  # pulling up
    ticks = 1
    while not realtime.tick():                  # the step: no keep-alive, and no hold
        assert not realtime.holding and realtime.stepping
        ticks += 1
    assert ticks > 20                           # longer than the old 10 ms watchdog
    assert not realtime.stepping and realtime.watchdog_holds == 0
    timeout = round(realtime.safety.limits.watchdog_timeout / realtime.config.dt)
    for _ in range(timeout):
        realtime.tick()
    assert not realtime.holding                 # the commander may take the timeout
    for _ in range(2):
        realtime.tick()
    assert realtime.holding and realtime.watchdog_holds == 1
    np.testing.assert_array_equal(realtime.setpoint.wrench, np.zeros(6))
    for _ in range(300):
        realtime.tick()
    held, _ = realtime.simulation.scene.tool_pose()
    for _ in range(300):
        realtime.tick()
    now, _ = realtime.simulation.scene.tool_pose()
    assert np.linalg.norm(now - held) < 0.0005


@pytest.mark.parametrize("robot", ["sim_panda", "sim_xarm7"])
def test_the_watchdog_hold_catches_the_realistic_arm_within_a_millimetre(robot: str) -> None:
    """The loop holds the pose on its own 0.1 s after a step's end with no new setpoint: stiff
    along every axis (z too, force-controlled in the task). Pulled up at 8 N, the arm still
    rises when the step ends at its time limit; the hold catches it within 2.5 mm of where the
    hold began (measured 1.24-1.91 mm) and then keeps it within 0.6 mm against the realistic
    arm's unknown 0.1 kg payload and joint friction (0.43-0.45 mm; with the task's
    gains, z free, the Panda sank 4.2 mm in 0.6 s, with z at the lateral 250 N/m 3.8 mm)."""
    realistic = build_loop(load_robot(robot), robot_defaults(
        robot_plugin(robot), (("robot_bridge_node", "bridge.yaml"),), "bridge"),
        estimator=lambda robot, model: MeasuredWrench(robot.simulation.contact_wrench))
    realtime = RobotLoop(realistic.hardware, realistic.controller, realistic.safety,
                         realistic.rest, realistic.estimator, LoopConfig(realtime=True),
                         realistic.simulation)
    scene = realtime.simulation.scene
    try:
        for pose in (0, 3):
            realtime.reset(start(pose))
            realtime.command(WrenchSetpoint.residual(8.0, 0.0, 0.0))  # pulling up, silent after
            while not realtime.holding:
                realtime.tick()
            began, _ = scene.tool_pose()
            drift = []
            for _ in range(600):
                realtime.tick()
                drift.append(np.linalg.norm(scene.tool_pose()[0] - began))
            assert max(drift) < 0.0025, f"pose {pose}: caught {max(drift) * 1e3:.2f} mm away"
            assert max(drift[300:]) < 0.0006, f"pose {pose}: {max(drift[300:]) * 1e3:.2f} mm"
            realtime.command(WrenchSetpoint.residual(PUSH, 0.0, 0.0))   # a setpoint releases it
            assert not realtime.holding and not realtime.controller.holding
    finally:
        scene.close()


def test_ground_truth_estimator_reports_the_contact_wrench(ideal_loop: RobotLoop) -> None:
    loop = ideal_loop
    loop.reset(start(3))
    result = loop.execute(WrenchSetpoint.residual(PUSH, 0.0, 0.0))
    # read one tick before the step ended, at rest: equal to the final truth within noise
    np.testing.assert_allclose(result.wrench_estimate, result.ground_truth.wrench, atol=0.01)
    assert result.wrench_estimate[2] == pytest.approx(PUSH, abs=0.5)


class MissingLink:
    """The simulated Panda behind a link on which the loop takes only every ``every``-th state
    (as the separate bridge does on a busy machine): the arm keeps the last command meanwhile,
    and each state carries its simulated time."""

    def __init__(self, robot, every: int) -> None:
        self.robot = robot
        self.every = every
        self.stamp = 0.0

    def read(self):
        self.stamp = self.robot.scene.time
        return self.robot.read()

    def write(self, tau: np.ndarray) -> None:
        for _ in range(self.every):
            self.robot.write(tau)

    def state_time(self) -> float:
        return self.stamp


def test_a_loop_missing_states_ends_the_step_at_its_time_limit_of_the_states_clock(
        loop: RobotLoop) -> None:
    link = MissingLink(loop.hardware, every=3)
    remote = RobotLoop(link, loop.controller, loop.safety, loop.rest, loop.estimator,
                       LoopConfig(), loop.simulation, clock=StateClock(link, max_period=0.02))
    remote.reset(start(1))
    scene = loop.simulation.scene
    began, settled = scene.time, remote.ticks
    result = remote.execute(WrenchSetpoint.residual(PUSH, 3.0, 0.0))
    elapsed = scene.time - began
    # The step's duration is the arm's time (to within the one tick its states are apart), not
    # ticks times 1 ms (a third of it here).
    assert result.duration == pytest.approx(elapsed, abs=0.0031)
    assert remote.ticks - settled == pytest.approx(elapsed / 0.003, abs=1)
    assert elapsed <= loop.rest.config.max_time + 0.003


def test_state_clock_counts_the_stamp_differences_within_bounds() -> None:
    class Stamps:
        t = 10.0

        def state_time(self) -> float:
            return self.t

    stamps = Stamps()
    clock = StateClock(stamps, max_period=0.02)
    clock.restart()
    for t, period, time in ((10.003, 0.003, 0.003),   # missed two states
                            (10.003, 0.0, 0.003),     # the same state again
                            (11.0, 0.02, 0.023),      # a stall counts max_period
                            (10.9, 0.0, 0.023)):      # an older state: no time passes
        stamps.t = t
        assert clock.period() == pytest.approx(period)
        clock.advance(clock.period())
        assert clock.time == pytest.approx(time)
    with pytest.raises(ValueError, match="max_period"):
        StateClock(stamps, max_period=0.0)


def test_tick_clock_is_ticks_times_the_period() -> None:
    clock = TickClock(0.001)
    for _ in range(250):
        clock.advance(clock.period())
    assert clock.time == 250 * 0.001    # a product, as before the clocks: runs repeat exactly
    clock.restart()
    assert clock.time == 0.0
