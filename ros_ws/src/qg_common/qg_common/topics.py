"""Topic and service names of the stack and the QoS each one needs, decided once.

Names are relative, so ``--ros-args -r __ns:=/robot1`` moves a whole stack (robot process,
executor, learner) into a namespace and two robots can run side by side without crosstalk.
In the default namespace they resolve to ``/joint_states``, ``/move_to_start`` and so on.
"""
from __future__ import annotations

import re

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

__all__ = [
    "JOINT_STATES", "JOINT_COMMANDS", "GROUND_TRUTH", "GROUND_TRUTH_WRENCH", "CLOCK",
    "SIM_RESTARTED", "MOVE_TO_START", "WRENCH_ESTIMATE", "WRENCH_SETPOINT", "EE_POSE", "EE_TWIST",
    "EE_AT_REST", "DIAGNOSTICS", "ROBOT_DESCRIPTION", "TF", "TF_STATIC", "SCENE_MARKERS", "TF_QOS",
    "EPISODE_STATUS", "TRANSITIONS", "ACTOR_PARAMETERS", "LEARNER_DIAGNOSTICS",
    "START_EPISODE", "STOP_EPISODE", "TASK_SPEC", "LEARNER_NODE", "SENSOR_QOS", "COMMAND_QOS", "RESTARTED_QOS",
    "RELIABLE_DEEP", "LATCHED", "robot_topic"]

# --- the robot process (1 kHz unless said otherwise) -------------------------------------------
JOINT_STATES = "joint_states"
JOINT_COMMANDS = "joint_commands"              # the loop's commands (separate sim's input)
GROUND_TRUTH = "sim/ground_truth"
GROUND_TRUTH_WRENCH = "sim/ground_truth_wrench"
CLOCK = "clock"                                # lockstep
SIM_RESTARTED = "sim/restarted"                # separate processes only: the sim teleported
#: Service, per episode: served by what moves the robot (the bridge of the composed robot
#: process; in separate-process mode the sim, which teleports).
MOVE_TO_START = "move_to_start"
WRENCH_ESTIMATE = "wrench_estimate"
WRENCH_SETPOINT = "wrench_setpoint"            # RL step
EE_POSE = "ee_pose"
EE_TWIST = "ee_twist"
EE_AT_REST = "ee_at_rest"                      # RL step
DIAGNOSTICS = "diagnostics"                    # 1 Hz: the realtime loop's timing
ROBOT_DESCRIPTION = "robot_description"        # latched: the robot's URDF
TF = "tf"                                      # 100 Hz: the driven joints' transforms
TF_STATIC = "tf_static"                        # latched: fixed joints, the tool, the task's frames
SCENE_MARKERS = "scene_markers"                # latched: the task's parts (visualization_msgs)

# --- learning ------------------------------------------------------------------------------
EPISODE_STATUS = "episode_status"
TRANSITIONS = "transitions"
ACTOR_PARAMETERS = "actor_parameters"
LEARNER_DIAGNOSTICS = "learner/diagnostics"
START_EPISODE = "executor/start_episode"       # service
STOP_EPISODE = "executor/stop_episode"         # service
TASK_SPEC = "executor/task_spec"               # latched: state and action sizes for the learner
#: The learner's node name.
LEARNER_NODE = "learner"


_NAMESPACE = re.compile(r"[A-Za-z_]\w*(/[A-Za-z_]\w*)*", re.ASCII)


def robot_topic(namespace: str, name: str) -> str:
    """The topic or service ``name`` of the robot in ``namespace`` (``robot1`` or ``/robot1``):
    absolute, or ``name`` itself, still relative, for "" (one robot in the caller's namespace).
    A node outside the robots' namespaces (the learner of many robots, a command line client)
    names their topics this way."""
    namespace = namespace.strip("/")
    if namespace and not _NAMESPACE.fullmatch(namespace):
        raise ValueError(f"{namespace!r} is not a ROS namespace (letters, digits, '_' and '/', "
                         "no part starting with a digit)")
    return f"/{namespace}/{name}" if namespace else name


# --- QoS -----------------------------------------------------------------------------------
#: 1 kHz state: only the newest sample matters.
SENSOR_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
#: Commands and RL-step events: reliable, a few deep.
COMMAND_QOS = 10
#: Transitions: none may be lost, even while the learner is busy training.
RELIABLE_DEEP = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
#: ``tf``: reliable and 100 deep, as tf2's ``TransformBroadcaster`` offers it.
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: The latest value is what a late joiner needs (episode status, actor parameters; the robot's
#: description, static transforms and markers, as robot_state_publisher and tf2 offer them).
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: The separate sim's last restart, latched: a bridge or estimator that discovers the sim after
#: a reset still learns of it (once, on a loaded machine, the bridge missed one and drove the
#: arm with commands the sim then ignored as belonging to an earlier restart).
RESTARTED_QOS = LATCHED
