"""End to end with real processes: robot, executor and learner, episodes by service call."""
from __future__ import annotations

import dataclasses
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import SHORT_STEP
from live_capture import RL_TOPICS, SENSOR_TOPICS, LiveCapture, offered_qos, stamp_ns

pytestmark = pytest.mark.ros

#: The robot process of the stack tests: lockstep, and the 0.25 s step (their subject is the
#: stack, not the step; ``test_robot_process_lockstep.py`` and the demo run the default step).
ROBOT = ("robot", "robot_bridge_node", "robot",
         ("--ros-args", "-p", "sim.clock_mode:=lockstep", *SHORT_STEP))


def executor_spec(max_steps: int, alone: bool = False) -> tuple:
    """The executor; ``alone``: in a stack with no learner, so an episode need not wait its
    ``learner_grace`` for one to be discovered."""
    return ("executor", "qg_learning_node", "executor",
            ("--ros-args", "-p", f"task.train_max_steps:={max_steps}",
             "-p", "learner_timeout:=1.5", *(("-p", "learner_grace:=0.0") if alone else ())))


def learner_spec(checkpoint_dir: Path, name: str = "learner") -> tuple:
    return (name, "qg_learning_node", "learner",
            ("--ros-args", "-p", "learner.cycle_steps:=10", "-p", "resume:=true",
             "-p", f"checkpoint_dir:={checkpoint_dir}"))


class Episodes:
    """Calls StartEpisode and follows /episode_status from the test process."""

    def __init__(self, cli, robot: str = "") -> None:
        """:param robot: the robot's namespace (``robot0`` under many robots), "" = the root."""
        from qg_common.topics import LATCHED, robot_topic
        from qg_interfaces.msg import EpisodeStatus, LearnerDiagnostics
        from rclpy.qos import QoSProfile
        self.cli = cli
        self.robot = robot
        self.statuses: list = []
        self.learner_heartbeats: list = []
        # Latched like the publisher (the last status reaches a late reader), but a deep queue:
        # a busy test process must not lose "resetting" to the "running" right behind it.
        every_status = QoSProfile(depth=1000, reliability=LATCHED.reliability,
                                  durability=LATCHED.durability)
        cli.node.create_subscription(EpisodeStatus, robot_topic(robot, "episode_status"),
                                     self.statuses.append, every_status)
        cli.node.create_subscription(LearnerDiagnostics, "/learner/diagnostics",
                                     self.learner_heartbeats.append, 10)

    def wait_for_learner(self, timeout: float = 60.0) -> None:
        n = len(self.learner_heartbeats)
        assert self.cli.spin_until(lambda: len(self.learner_heartbeats) > n, timeout), \
            "the learner is not up"

    def wait_for_robot(self, timeout: float = 60.0) -> None:
        from qg_interfaces.srv import MoveToStart
        client = self.cli.node.create_client(MoveToStart, "/move_to_start")
        assert self.cli.spin_until(client.service_is_ready, timeout), "the robot is not up"
        self.cli.node.destroy_client(client)

    def start(self, **fields):
        """StartEpisode, asked again with its request id if the reply is lost."""
        import uuid

        from qg_common.ros_client import RESEND_AFTER, call_service
        from qg_common.topics import robot_topic
        from qg_interfaces.srv import StartEpisode
        fields.setdefault("request_id", uuid.uuid4().hex)
        return call_service(self.cli, StartEpisode, robot_topic(self.robot, "executor/start_episode"),
                            StartEpisode.Request(**fields), timeout=60.0, resend_after=RESEND_AFTER)

    def final(self, episode_id: str, timeout: float):
        def ended():
            return any(s.episode_id == episode_id and s.state in ("done", "aborted")
                       for s in self.statuses)
        assert self.cli.spin_until(ended, timeout), f"episode {episode_id} did not end"
        return [s for s in self.statuses if s.episode_id == episode_id][-1]


def wait_for_bag(episodes_dir: Path, episode_id: str, timeout: float = 15.0) -> Path:
    """The episode's bag once the recorder has closed it (its MCAP summary is written)."""
    from qg_recording.bag_reader import bag_info
    bag = episodes_dir / episode_id
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if bag_info(bag).complete:
                return bag
        except (FileNotFoundError, ValueError):  # not written yet
            pass
        time.sleep(0.2)
    return bag


def wait_for_file(path: Path, timeout: float = 15.0) -> Path:
    deadline = time.monotonic() + timeout
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    return path


def test_train_episode_is_recorded_and_replays_into_the_same_graph(stack, tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from qg_common.params import config_file, load_ros_params
    from qg_learning_node.learner.learner_core import LearnerCore
    from qg_learning_node.learner.learner_params import learner_config_from_params
    from qg_learning_node.learner.offline import rebuild_from_bags

    checkpoints = tmp_path / "checkpoints"
    stack.start(ROBOT, learner_spec(checkpoints), executor_spec(max_steps=25))
    with stack.client() as cli:
        live = LiveCapture(cli)
        episodes = Episodes(cli)
        episodes.wait_for_learner()
        assert cli.spin_until(lambda: all(offered_qos(cli, t) for t in live.received), 30.0)
        graph = {topic: offered_qos(cli, topic) for topic in live.received}
        response = episodes.start(mode="train", initial_pose=2, seed=7, reward="dense")
        assert response.success, response.message + stack.logs()
        final = episodes.final(response.episode_id, timeout=240.0)
        assert final.state == "done", final.message + stack.logs()
        assert 1 <= final.step <= 25
        states = [s.state for s in episodes.statuses if s.episode_id == response.episode_id]
        assert states.index("resetting") < states.index("running") < states.index("done")
        cli.spin_for(0.5)

    bag = wait_for_bag(Path(stack.env["QG_RUNS_DIR"]) / "episodes", response.episode_id)
    recorded = check_bag_against_live(bag, live, graph, response.episode_id)
    counts: dict[str, int] = {}
    steps, step_ticks = [], []
    with open(next(bag.glob("*.mcap")), "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/transitions":
                steps.append(msg.step)
                assert len(msg.state) == 3 and np.all(np.abs(msg.state) <= 1.0)   # tilt_motion
            if channel.topic == "/ee_at_rest" and msg.seq > 0:
                step_ticks.append(round(msg.duration / 1e-3))
    assert counts["/transitions"] == final.step, counts
    # Every tick of the loop is in the bag: the settled start, then each step's 1 ms ticks.
    assert len(step_ticks) == final.step and counts["/joint_states"] == 1 + sum(step_ticks)
    assert sorted(steps) == list(range(final.step))
    for topic in ("/joint_states", "/wrench_estimate", "/ee_pose", "/ee_twist",
                  "/wrench_setpoint", "/episode_status", "/sim/ground_truth"):
        assert counts.get(topic, 0) > 0, (topic, counts)
    assert counts["/joint_states"] > 10 * final.step   # 1 kHz data: many ticks per RL step

    online = LearnerCore.load(wait_for_file(checkpoints / "learner.pt"))
    params = load_ros_params(config_file("learner.yaml"), "learner")["learner"]
    params["cycle_steps"] = 10
    offline = rebuild_from_bags([bag], config=learner_config_from_params(params))
    kinds = ("directly_connected", "connected", "disconnected", "loose_end")
    assert online.steps == final.step
    assert {k: offline.census[k] for k in kinds} == {k: online.graph.census()[k] for k in kinds}

    # Replay to subscribers with the live QoS (transient-local /episode_status included).
    stack.stop()
    replayed = RL_TOPICS + ("/ee_pose",)
    with stack.client("replay_listener") as cli:
        live = LiveCapture(cli, replayed)
        player = subprocess.Popen(
            [sys.executable, "-m", "qg_bringup.main", "replay", str(bag), "--rate", "4",
             "--topics", *replayed, "--wait-for-subscribers", "20", "--start-delay", "1.0"],
            env=stack.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert cli.spin_until(lambda: all(len(live.received[t]) >= len(recorded[t]) for t in RL_TOPICS),
                                  60.0), {t: (len(live.received[t]), len(recorded[t])) for t in RL_TOPICS}
            out, err = player.communicate(timeout=60)
        finally:
            player.kill()
    assert player.returncode == 0, err
    for topic in RL_TOPICS:  # reliable: everything, in order, byte for byte
        assert live.received[topic] == [data for _, data in recorded[topic]], topic
    pose_stamps = {t for t, _ in recorded["/ee_pose"]}
    got = [stamp_ns(m) for m in live.decoded("/ee_pose")]  # best effort: a subset, in order
    assert got and set(got) <= pose_stamps and got == sorted(got)


def check_bag_against_live(bag: Path, live, graph: dict, episode_id: str) -> dict:
    """Read every message of ``bag`` with rosbags (types from the bag's own definitions, type
    hashes checked) and compare topics, QoS, type hashes, stamps and bytes with what the live
    graph showed; returns the recorded (log time, bytes) per topic."""
    from qg_recording.player import message_class
    from rclpy.serialization import deserialize_message
    from rosbags.highlevel import AnyReader

    recorded: dict[str, list[tuple[int, bytes]]] = {}
    with AnyReader([bag]) as reader:
        connections = {c.topic: c for c in reader.connections}
        for connection, t_ns, data in reader.messages():
            recorded.setdefault(connection.topic, []).append((t_ns, bytes(data)))
        start, end = reader.start_time, reader.end_time
    # The recorded offered QoS and type hash are those of the live publishers.
    for topic, publishers in graph.items():
        (qos,) = connections[topic].ext.offered_qos_profiles
        mine = (qos.reliability.name.lower(), qos.durability.name.lower(), connections[topic].digest)
        assert publishers and all(p == mine for p in publishers), (topic, publishers, mine)

    def messages(topic: str) -> list:
        cls = message_class(connections[topic].msgtype)
        return [(t, deserialize_message(data, cls)) for t, data in recorded[topic]]

    # One time base: the bag starts with the episode's first status, before the first tick.
    statuses = messages("/episode_status")
    assert statuses[0][1].state == "resetting" and statuses[0][0] == start
    assert start <= recorded["/joint_states"][0][0] and recorded["/joint_states"][-1][0] < end
    # RL-rate messages are logged when they arrive, on the loop's clock that stamps the events.
    for t_ns, event in messages("/ee_at_rest"):
        assert 0 <= t_ns - stamp_ns(event) < 10**9, (t_ns, stamp_ns(event))
    # Every live 1 kHz message in the bag's span is recorded with the same stamp and bytes.
    for topic in SENSOR_TOPICS:
        by_stamp = {stamp_ns(deserialize_message(data, message_class(connections[topic].msgtype))): data
                    for _, data in recorded[topic]}
        in_span = [(stamp_ns(m), data) for m, data in zip(live.decoded(topic), live.received[topic])
                   if min(by_stamp) <= stamp_ns(m) <= max(by_stamp)]
        assert len(in_span) >= 5, topic
        assert all(by_stamp.get(t) == data for t, data in in_span), topic
    # RL-rate messages: what the executor published for this episode, byte for byte, up to and
    # past its end. The executor's status heartbeat goes on after the end, and the bag and the
    # capture each stop taking it at their own moment, so only their common prefix is compared.
    mine = [(data, m.state) for data, m in zip(live.received["/episode_status"], live.decoded("/episode_status"))
            if m.episode_id == episode_id]
    ended = next(i for i, (_, state) in enumerate(mine) if state in ("done", "aborted"))
    in_bag = [data for _, data in recorded["/episode_status"]]
    common = min(len(in_bag), len(mine))
    assert common > ended and in_bag[:common] == [data for data, _ in mine[:common]], (len(in_bag), len(mine))
    assert sorted(data for _, data in recorded["/transitions"]) == sorted(live.received["/transitions"])
    first_of_seq = {}
    for data, m in zip(live.received["/wrench_setpoint"], live.decoded("/wrench_setpoint")):
        first_of_seq.setdefault(m.seq, data)
    assert [data for _, data in recorded["/wrench_setpoint"]] == list(first_of_seq.values())
    step_events = [data for data, m in zip(live.received["/ee_at_rest"], live.decoded("/ee_at_rest"))
                   if m.seq >= 1]
    assert [data for _, data in recorded["/ee_at_rest"]][-len(step_events):] == step_events
    return recorded


def test_async_learner_trains_while_the_robot_moves(stack, tmp_path):
    """``learner.schedule: async``: the learner's own thread trains ``updates_per_step`` per
    transition and publishes an actor every ``publish_every`` updates, during the episode."""
    learner = ("learner", "qg_learning_node", "learner",
               ("--ros-args", "-p", "learner.schedule:=async", "-p",
                "learner.updates_per_step:=4.0", "-p", "learner.publish_every:=4",
                "-p", f"checkpoint_dir:={tmp_path / 'checkpoints'}"))
    stack.start(ROBOT, learner, executor_spec(max_steps=12))
    with stack.client() as cli:
        episodes = Episodes(cli)
        episodes.wait_for_learner()
        response = episodes.start(mode="train", initial_pose=1, seed=3)
        assert response.success, response.message + stack.logs()
        final = episodes.final(response.episode_id, timeout=240.0)
        assert final.state == "done" and not final.degraded, final.message + stack.logs()

        def caught_up():
            d = episodes.learner_heartbeats[-1]
            return d.transitions == final.step and d.updates == 4 * final.step
        assert cli.spin_until(caught_up, 30.0), episodes.learner_heartbeats[-1]
    # 4 updates per step in chunks of 4: one new actor per step
    assert episodes.learner_heartbeats[-1].actor_version == final.step


@pytest.mark.slow                 # three episodes and two learners: 20-30 s on loaded cores
def test_learner_killed_mid_episode_degrades_then_resumes(stack, tmp_path, let_alone_tests_in):
    """The executor runs degraded without the learner and is back to normal as soon as a
    restarted learner speaks; the restarted learner resumes from the checkpoint and does not
    checkpoint again the episode that ended while it was down (its latched status)."""
    from param_client import integer, set_value
    from qg_learning_node.learner_node import CHECKPOINT_GRACE
    checkpoints = tmp_path / "checkpoints"

    def cap_steps(steps: int) -> None:
        """The executor's step cap from its next episode on."""
        result = set_value(cli, "/executor", "task.train_max_steps", integer(steps))
        assert result.successful, result.reason

    # The first and the last episode need only a few steps (a checkpoint; the resumed actor).
    stack.start(ROBOT, learner_spec(checkpoints), executor_spec(max_steps=20))
    with stack.client() as cli:
        episodes = Episodes(cli)
        episodes.wait_for_learner()
        first = episodes.start(mode="train", initial_pose=0)
        assert first.success, first.message
        episodes.final(first.episode_id, timeout=240.0)
        assert wait_for_file(checkpoints / "learner.pt").exists(), stack.logs()

        let_alone_tests_in()   # between two episodes
        # An RL step takes ~40 ms of wall time here: 80 steps outlast the executor's 1.5 s
        # learner_timeout after the kill at step 2 (25 steps ended before the learner was
        # missed).
        cap_steps(80)
        second = episodes.start(mode="train", initial_pose=1)
        assert second.success, second.message
        assert cli.spin_until(lambda: any(s.episode_id == second.episode_id and s.step >= 2
                                          for s in episodes.statuses), 120.0), stack.logs()
        learner = next(r for r in stack.launcher.running if r.spec.name == "learner")
        learner.popen.send_signal(signal.SIGKILL)
        degraded = cli.spin_until(lambda: any(s.episode_id == second.episode_id and s.degraded
                                              for s in episodes.statuses), 30.0)
        final = episodes.final(second.episode_id, timeout=240.0)
        if not degraded:   # the episode may end before the learner is missed
            degraded = any(s.degraded for s in episodes.statuses)
        assert degraded, "the executor must report the silent learner"
        assert final.state == "done", final.message

        stack.start(learner_spec(checkpoints, name="learner2"))
        episodes.wait_for_learner()
        restarted = time.monotonic()
        # Back before any new episode: the executor's idle status heartbeat says so.
        assert cli.spin_until(lambda: not episodes.statuses[-1].degraded, 3.0), stack.logs()
        assert episodes.statuses[-1].episode_id == second.episode_id
        cap_steps(20)
        third = episodes.start(mode="train", initial_pose=2)
        assert third.success, third.message
        final3 = episodes.final(third.episode_id, timeout=240.0)
        assert final3.state == "done", final3.message
        # Steps with the resumed learner's actor. (A step may still flag a heartbeat gap on a
        # loaded host, the first ones above all while the new learner warms up: the test's
        # learner_timeout is only 1.5 s.)
        stepped = [s for s in episodes.statuses
                   if s.episode_id == third.episode_id and s.state == "running" and s.step >= 1]
        assert stepped and not all(s.degraded for s in stepped), stack.logs()
        assert final3.actor_version >= 1, final3
        # Past the learner's grace for missing transitions: a re-checkpoint would be done now.
        cli.spin_for(max(0.0, restarted + CHECKPOINT_GRACE + 1.5 - time.monotonic()))
    learner2_log = stack.log_dir / "learner2.log"
    deadline = time.monotonic() + 30.0    # saving the checkpoint takes a while on a busy host
    while f"checkpoint after {third.episode_id}" not in learner2_log.read_text() \
            and time.monotonic() < deadline:
        time.sleep(0.2)
    log = learner2_log.read_text()
    assert "resumed from" in log and f"checkpoint after {third.episode_id}" in log, log
    assert "never arrived" not in log and f"checkpoint after {second.episode_id}" not in log, log


def test_bad_requests_are_refused_and_the_stack_stays_up(stack):
    stack.start(ROBOT, executor_spec(max_steps=400, alone=True))
    with stack.client() as cli:
        episodes = Episodes(cli)
        for fields, word in [({"mode": "play"}, "mode"), ({"mode": "train", "initial_pose": 8}, "initial_pose"),
                             ({"mode": "test", "initial_pose": -2}, "initial_pose"),
                             ({"mode": "train", "reward": "shaped"}, "reward")]:
            response = episodes.start(**fields)
            assert not response.success and word in response.message, (fields, response.message)
        episodes.wait_for_robot()
        running = episodes.start(mode="train", initial_pose=0, request_id="first")
        assert running.success, running.message
        again = episodes.start(mode="train", initial_pose=0, request_id="first")  # a retry
        assert (again.success, again.episode_id) == (True, running.episode_id), again
        busy = episodes.start(mode="test")
        assert not busy.success and "still running" in busy.message
        from qg_common.ros_client import call_service
        from qg_interfaces.srv import StopEpisode
        stopped = call_service(cli, StopEpisode, "/executor/stop_episode",
                               StopEpisode.Request(reason="test"), timeout=30.0)
        assert stopped.success and stopped.episode_id == running.episode_id
        final = episodes.final(running.episode_id, 30.0)
        assert final.state == "aborted" and "stop requested: test" in final.message, \
            final.message
        again = episodes.start(mode="test", initial_pose=1)
        assert again.success, again.message
    assert stack.launcher.poll() == [], stack.logs()


def test_executor_without_robot_refuses_with_a_clear_message(stack):
    executor = executor_spec(max_steps=10, alone=True)
    stack.start((*executor[:3], (*executor[3], "-p", "robot_grace:=0.5")))
    with stack.client() as cli:
        response = Episodes(cli).start(mode="train")
        assert not response.success and "robot side is not up" in response.message


def test_in_process_runner_repeats_the_ros_stack_episode(stack, tmp_path):
    """The experiments' fast runner must agree with the ROS stack: the same test episode (same
    start pose, the learner's initial actor, no noise) gives the same transitions in both."""
    from qg_common.params import config_file, load_ros_params
    from qg_experiments.runner import InsertionRobot, LivePolicy, StackSettings, run_episode
    from qg_learning_node.executor.episode import Episode
    from qg_learning_node.executor.residual_task import ACTION_DIM, OBSERVATION_COMPONENTS
    from qg_learning_node.learner.learner_core import LearnerCore
    from qg_learning_node.learner.learner_params import learner_config_from_params
    from qg_learning_node.learner.offline import iter_transitions

    steps, pose = 4, 3
    executor = ("executor", "qg_learning_node", "executor",
                ("--ros-args", "-p", f"task.test_max_steps:={steps}"))
    # The same code in two processes agrees to ~1e-6 where contact does not amplify rounding:
    # pybullet at the 0.25 s step. The first step's next state differed by 1.6e-4 on pybullet
    # and 1.5e-3 on MuJoCo at the default step (it ends at rest, up to 3 s of contact), and by
    # 6e-5 on MuJoCo at 0.25 s: the stiffer the contact and the longer the step, the more a
    # last-digit difference between the processes grows (its source is not found).
    engine = "sim_panda_pybullet"
    stack.start((*ROBOT[:3], (*ROBOT[3], "-p", f"robot:={engine}")),
                learner_spec(tmp_path / "checkpoints"), executor)
    with stack.client() as cli:
        episodes = Episodes(cli)
        episodes.wait_for_learner()
        response = episodes.start(mode="test", initial_pose=pose, reward="dense")
        assert response.success, response.message + stack.logs()
        final = episodes.final(response.episode_id, timeout=240.0)
        assert final.state == "done" and not final.degraded, final.message + stack.logs()
    bag = wait_for_bag(Path(stack.env["QG_RUNS_DIR"]) / "episodes", response.episode_id)
    ros = sorted(iter_transitions([bag]), key=lambda t: t.step)

    settings = StackSettings.load()
    settings = dataclasses.replace(
        settings, robot_name=engine,
        bridge={**settings.bridge, "rest": {**settings.bridge.get("rest", {}), "max_time": 0.25}},
        task=dataclasses.replace(settings.task, test_max_steps=steps))
    params = load_ros_params(config_file("learner.yaml"), "learner")["learner"]
    env = InsertionRobot(settings, "ekf")     # holds the arm where it starts, as the process does
    learner = LearnerCore(learner_config_from_params(params), env.residual.state_dim, ACTION_DIM)
    local: list = []
    episode = Episode("local", "test", pose, "dense", env.residual)
    result = run_episode(env, episode, LivePolicy(learner.agent), local.append)

    assert result["steps"] == final.step == len(ros) >= 1
    # Same code, same numbers; the two processes' physics differ only by float rounding (the
    # first states and actions are identical, later ones within ~1e-6).
    for mine, theirs in zip(local, ros):
        np.testing.assert_allclose(mine.action, theirs.action, atol=1e-5)
        np.testing.assert_allclose(mine.state, theirs.state, atol=1e-5)
        np.testing.assert_allclose(mine.next_state, theirs.next_state, atol=1e-5)
        assert mine.reward == pytest.approx(theirs.reward, abs=1e-5)
        assert mine.terminal == theirs.terminal
    # The first state: the wrench part (if the executor's state has one) bit-identical; the
    # tilt part crosses the message as a quaternion, which costs a few ulps.
    parts = OBSERVATION_COMPONENTS[settings.task.observation]
    wrench = [i for i, part in enumerate(parts) if part in ("fx", "fy", "tx", "ty")]
    np.testing.assert_array_equal(np.asarray(local[0].state)[wrench],
                                  np.asarray(ros[0].state)[wrench])
    np.testing.assert_allclose(local[0].state, ros[0].state, rtol=0, atol=1e-12)
