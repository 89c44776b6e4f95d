"""Faults of the RL nodes with real processes: shutdown mid-episode, a learner busy training.
(A learner killed and restarted: ``test_episodes.py``.)"""
from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest
from task_spec import announce_task
from test_episodes import ROBOT, Episodes, executor_spec, wait_for_bag

pytestmark = pytest.mark.ros


def test_executor_stopped_mid_episode_aborts_it_and_exits_zero(stack):
    """SIGINT (Ctrl-C, ``qgl up`` stopping) and SIGTERM alike: the running episode ends as
    ``aborted`` (reason ``shutdown``) on the latched status, the robot gets the zero residual,
    and the process says so and exits 0 without a traceback."""
    from qg_common.topics import COMMAND_QOS
    from qg_interfaces.msg import WrenchSetpoint
    stack.start(ROBOT)
    with stack.client() as cli:
        episodes = Episodes(cli)
        setpoints: list = []
        cli.node.create_subscription(WrenchSetpoint, "/wrench_setpoint", setpoints.append,
                                     COMMAND_QOS)
        episodes.wait_for_robot()
        for name, sig in (("executor_int", signal.SIGINT), ("executor_term", signal.SIGTERM)):
            spec = executor_spec(max_steps=400, alone=True)
            stack.start((name, *spec[1:]))
            response = episodes.start(mode="train", initial_pose=1)
            assert response.success, response.message + stack.logs()
            assert cli.spin_until(lambda: any(s.episode_id == response.episode_id and s.step >= 2
                                              for s in episodes.statuses), 120.0), stack.logs()
            proc = next(r for r in stack.launcher.running if r.spec.name == name).popen
            proc.send_signal(sig)
            final = episodes.final(response.episode_id, timeout=10.0)
            assert final.state == "aborted" and final.message == "shutdown", (final, stack.logs())
            assert proc.wait(timeout=5.0) == 0, stack.logs()
            cli.spin_for(0.3)
            assert setpoints[-1].seq > final.step            # after the last step's command
            assert [setpoints[-1].wrench.force.z, setpoints[-1].wrench.torque.x,
                    setpoints[-1].wrench.torque.y] == [-15.0, 0.0, 0.0]   # the zero residual
            log = (stack.log_dir / f"{name}.log").read_text()
            assert "Traceback" not in log and "InvalidHandle" not in log, log
            said = [line for line in log.splitlines() if "shutdown" in line]
            assert len(said) == 1 and response.episode_id in said[0], log


def test_stopping_the_stack_mid_episode_records_the_abort(stack):
    """``qgl up`` stopped (its launcher's stop): the episode's bag ends with the executor's
    ``aborted`` status, not with the episode still ``running``."""
    from qg_recording.player import message_class
    from rclpy.serialization import deserialize_message
    from rosbags.highlevel import AnyReader
    stack.start(ROBOT, executor_spec(max_steps=400, alone=True))
    with stack.client() as cli:
        episodes = Episodes(cli)
        episodes.wait_for_robot()
        response = episodes.start(mode="train", initial_pose=1)
        assert response.success, response.message + stack.logs()
        assert cli.spin_until(lambda: any(s.episode_id == response.episode_id and s.step >= 2
                                          for s in episodes.statuses), 120.0), stack.logs()
    assert stack.stop(grace=5.0) == {"robot": 0, "executor": 0}, stack.logs()
    bag = wait_for_bag(Path(stack.env["QG_RUNS_DIR"]) / "episodes", response.episode_id)
    with AnyReader([bag]) as reader:
        statuses = [deserialize_message(data, message_class(c.msgtype))
                    for c, _, data in reader.messages(
                        [c for c in reader.connections if c.topic == "/episode_status"])]
    assert (statuses[-1].state, statuses[-1].message) == ("aborted", "shutdown"), stack.logs()


@pytest.mark.alone
def test_learner_heartbeat_goes_on_while_it_trains(stack, tmp_path, machine_to_itself):
    """A training cycle of several seconds must not silence the heartbeat, or the executor
    would run degraded (zero residual) while the learner is merely busy.

    The cycle here is a million updates, hours on any host, so how fast this host trains at the
    moment cannot make it too short to tell (a cycle timed beforehand to last 3 s lasted 1.4 s
    while an experiment suite ran, and 16 s on another loaded run). The test watches
    ``WATCH`` seconds of it, then kills the learner."""
    from qg_common.topics import RELIABLE_DEEP
    from qg_interfaces.msg import LearnerDiagnostics, Transition
    learner = ("learner", "qg_learning_node", "learner",
               ("--ros-args", "-p", "learner.cycle_steps:=1",
                "-p", "learner.iterations_per_cycle:=1000000",
                "-p", f"checkpoint_dir:={tmp_path / 'checkpoints'}"))
    stack.start(learner)
    with stack.client() as cli:
        beats: list[tuple[float, LearnerDiagnostics]] = []
        cli.node.create_subscription(LearnerDiagnostics, "/learner/diagnostics",
                                     lambda m: beats.append((time.monotonic(), m)), 10)
        transitions = cli.node.create_publisher(Transition, "/transitions", RELIABLE_DEEP)
        task = announce_task(cli, state_dim=6)      # the thesis state plus the tilt
        assert cli.spin_until(lambda: beats and transitions.get_subscription_count() > 0,
                              60.0), stack.logs()

        def training() -> list[tuple[float, LearnerDiagnostics]]:
            return [(t, m) for t, m in beats if m.transitions >= 1]

        # The transition starts the cycle, a core's worth of load: only once the other worker
        # has let go of the machine.
        with machine_to_itself():
            transitions.publish(Transition(episode_id="one", step=0, state=[0.1] * 6,
                                           action=[0.0, 0.1], reward=-1.0, next_state=[0.2] * 6))
            assert cli.spin_until(training, 60.0), stack.logs()      # the cycle has begun
            begun = time.monotonic()
            assert cli.spin_until(lambda: beats[-1][0] - begun >= WATCH, WATCH + 30.0), \
                stack.logs()
        del task
    next(r for r in stack.launcher.running if r.spec.name == "learner").popen.kill()
    watched = [(t, m) for t, m in training() if t >= begun]
    times = [t for t, _ in watched]
    gaps = [b - a for a, b in zip(times, times[1:])]
    print(f"{len(watched)} heartbeats in {times[-1] - times[0]:.1f} s of one training cycle; "
          f"longest gap {max(gaps):.2f} s")
    assert [m.updates for _, m in watched] == [0] * len(watched)   # all within the one cycle
    assert len(watched) >= 2 * WATCH - 1, gaps   # 0.5 s heartbeats
    assert max(gaps) < 1.2, gaps                 # some jitter on a loaded host


#: [s] how much of the endless training cycle the heartbeat test watches.
WATCH = 2.0
