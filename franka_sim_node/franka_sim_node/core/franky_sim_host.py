"""franky-sim's MuJoCo FR3 served on one loopback address, its scene extended before it starts.

franky-sim (``franky_sim``) simulates the FR3 in MuJoCo and answers libfranka's protocol, so the
plugin talks to it exactly as to a real arm. Its own server (``franky_sim.run_server``) serves
the bare arm and paces itself by sleeping 1 ms minus each step's work, which on this machine is
~870-920 steps a second (and calls ``time.sleep(0)`` in every step). ``FrankySimHost`` instead:

- builds the scene with the arm at a start pose and then applies *scene extensions*, functions
  that add bodies to the MJCF tree before MuJoCo compiles it (``SceneExtension``; the demo's are
  in ``franky_sim_scene``): the shaft task's housing and shaft plug in as one more;
- steps at wall-clock 1 kHz on absolute deadlines (``qg_common.realtime_pacer``), one MuJoCo
  step of 1 ms a tick, libfranka's commands taken before and the state sent after each step;
- can push on the hand with a known wrench (MuJoCo's ``xfrc_applied``), the reference the
  bridge's wrench estimator is checked against.
"""
from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

import mujoco
import numpy as np
from franka_robot_node.core.fr3_description import FR3_READY
from franky_sim import SimulationServer
from franky_sim.mujoco_simulator import MujocoSimulator
from qg_common.realtime_pacer import RealtimePacer

__all__ = ["SceneExtension", "FrankySimHost", "ROBOT_PREFIX", "HAND_BODY", "TCP_IN_HAND"]

#: Adds bodies, geoms, sites or equality constraints to the scene's MJCF tree
#: (``sim.worldbody``, ``sim.scene``) before it is compiled.
SceneExtension = Callable[[MujocoSimulator], None]
#: franky-sim prefixes every name of its first robot's MJCF with this.
ROBOT_PREFIX = "robot0_"
#: The hand's body in franky-sim's MJCF (it carries the fingers).
HAND_BODY = ROBOT_PREFIX + "hand"
#: [m] The tool centre point in the hand's frame (franky-sim's ``ee_tcp_xyz``, the URDF's
#: ``fr3_hand_tcp``).
TCP_IN_HAND = np.array([0.0, 0.0, 0.1034])


class FrankySimHost:
    """One simulated FR3 serving libfranka's protocol on ``address`` (port 1337).

    :param address: a loopback address to bind (``127.x.y.z``: several servers can run side by
        side, one an address).
    :param extensions: applied in order to the scene before it starts.
    :param initial_q: (7,) [rad] the arm's start pose.
    :raises OSError: if ``address`` cannot be bound (taken, or not local).
    """

    def __init__(self, address: str, extensions: Sequence[SceneExtension] = (),
                 initial_q: Sequence[float] = FR3_READY) -> None:
        self.address = address
        self.sim = MujocoSimulator()
        self.sim.init()
        self.robot = self.sim.add_robot(initial_q=tuple(initial_q))
        for extend in extensions:
            extend(self.sim)
        self.server = SimulationServer(self.sim, hostname_candidates=[address])
        try:
            self.server.init()            # binds, then compiles and starts the MuJoCo scene
        except BaseException:
            self.sim.cleanup()
            raise
        model = self.sim.model
        self._hand = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, HAND_BODY)
        self._wrench = np.zeros(6)
        self._wrench_lock = threading.Lock()
        self.sim.register_pre_step_callback(self._push_hand)
        self.steps = 0
        self._pacer: RealtimePacer | None = None

    # --- a known wrench on the hand ----------------------------------------------------------
    def set_hand_wrench(self, wrench: Sequence[float]) -> None:
        """Push on the hand from the next step on with ``wrench`` (6,) ``(Fx, Fy, Fz, Tx, Ty,
        Tz)`` [N, Nm], base (world) frame, the force acting at the tool centre point; zeros
        stop it.

        :raises ValueError: unless 6 finite values.
        """
        values = np.asarray(wrench, dtype=float)
        if values.shape != (6,) or not np.all(np.isfinite(values)):
            raise ValueError(f"a hand wrench is 6 finite values [N, Nm], got {wrench}")
        with self._wrench_lock:
            self._wrench = values.copy()

    def _push_hand(self, sim: MujocoSimulator) -> None:
        """MuJoCo applies ``xfrc_applied`` at the body's centre of mass: move the force's
        moment from the tool centre point there."""
        with self._wrench_lock:
            wrench = self._wrench
        data = sim.data
        if not np.any(wrench):
            data.xfrc_applied[self._hand] = 0.0
            return
        tcp = data.xpos[self._hand] + data.xmat[self._hand].reshape(3, 3) @ TCP_IN_HAND
        force = wrench[:3]
        torque = wrench[3:] + np.cross(tcp - data.xipos[self._hand], force)
        data.xfrc_applied[self._hand] = np.concatenate([force, torque])

    # --- running ------------------------------------------------------------------------------
    def step(self) -> None:
        """One millisecond: take libfranka's commands, step the physics, send the state.

        ``SimulationServer.run_once`` without its pacing: even with ``realtime=False`` it calls
        ``time.sleep(0)``, which hands the core to any other runnable process; on the loaded
        2-core machine that cost 450 us a step (profiled), a third of the period.
        """
        for robot_server in self.server.robot_servers:
            robot_server.process_commands()
        self.sim.step()
        for robot_server in self.server.robot_servers:
            robot_server.send_state()
        self.steps += 1

    def run(self, stop: threading.Event, period: float = 0.001) -> None:
        """Step every ``period`` of wall-clock time until ``stop`` is set."""
        self._pacer = RealtimePacer(period)
        while not stop.is_set():
            self._pacer.wait()
            self.step()

    @property
    def dropped(self) -> int:
        """Steps ``run``'s pacer skipped (the host fell a whole period behind)."""
        return 0 if self._pacer is None else self._pacer.missed

    def close(self) -> None:
        """Close the server's sockets and the simulation."""
        self.server.cleanup()
        self.sim.cleanup()
