"""MuJoCo's contact filter for the shaft cell (``sim_robot_node/core/native``): it drops only
pairs that have no contact, so the simulation is the same with it, and it drops most of the
bore's boxes that used to reach the narrow phase."""
from __future__ import annotations

import ctypes

import mujoco
import numpy as np
import pytest
from qg_common.types import WrenchSetpoint
from robot_bridge_node.core.hardware_interface import load_robot
from robot_bridge_node.core.robot_loop import build_loop
from sim_robot_node.core.native import contact_filter

_SIGNATURE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int,
                              ctypes.c_int)

_PAIR = """
<mujoco>
  <worldbody>
    <body name="cylinder" mocap="true"><geom name="cylinder" type="cylinder" size="{r} {h}"/></body>
    <body name="other" mocap="true">
      <geom name="box" type="box" size="0.004 0.0006 0.006"/>
    </body>
  </worldbody>
</mujoco>
"""


def _drops(m: mujoco.MjModel, d: mujoco.MjData, g1: int, g2: int) -> bool:
    """The compiled filter's answer for one pair (called through ctypes, as MuJoCo calls it)."""
    function = ctypes.cast(contact_filter(), ctypes.c_void_p).value
    return bool(_SIGNATURE(function)(m._address, d._address, g1, g2))


def _random_quat(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def test_a_dropped_cylinder_box_pair_is_always_apart() -> None:
    """Random poses of a shaft-sized cylinder and a bore-sized box, most within 3 mm of each
    other: wherever the filter drops the pair, MuJoCo's own distance is positive; and it does
    drop most of the pairs that are apart, so the test cannot pass by dropping nothing."""
    m = mujoco.MjModel.from_xml_string(_PAIR.format(r=0.0059, h=0.05))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(4)
    cylinder, box = m.geom("cylinder").id, m.geom("box").id
    fromto = np.zeros(6)
    apart = dropped = wrongly = 0
    for _ in range(3000):
        d.mocap_pos[0] = rng.uniform(-0.002, 0.002, 3)
        d.mocap_quat[0] = _random_quat(rng) if rng.random() < 0.5 else [1.0, 0.0, 0.0, 0.0]
        d.mocap_pos[1] = rng.uniform(-0.012, 0.012, 3)
        d.mocap_quat[1] = _random_quat(rng)
        mujoco.mj_kinematics(m, d)
        distance = mujoco.mj_geomDistance(m, d, cylinder, box, 0.1, fromto)
        drop = _drops(m, d, cylinder, box)
        assert drop == _drops(m, d, box, cylinder)        # either order
        apart += distance > 0.0
        dropped += drop
        wrongly += drop and distance <= 0.0
    assert wrongly == 0
    assert apart > 500 and dropped > 0.5 * apart


def test_the_filter_keeps_mujocos_contype_and_conaffinity_test() -> None:
    """It replaces MuJoCo's bitmask test, so it does that test itself: geoms whose bits do not
    meet are dropped even when they overlap."""
    m = mujoco.MjModel.from_xml_string(_PAIR.format(r=0.0059, h=0.05))
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)                            # both at the origin: overlapping
    cylinder, box = m.geom("cylinder").id, m.geom("box").id
    assert not _drops(m, d, cylinder, box)
    m.geom_conaffinity[box] = 0
    m.geom_contype[box] = 2
    assert _drops(m, d, cylinder, box)


@pytest.fixture(scope="module")
def contact_states() -> tuple[mujoco.MjModel, mujoco.MjData, list[np.ndarray]]:
    """States of the realistic MuJoCo cell every 5 ticks of random-residual steps from two
    starts: the shaft above the bore, at its mouth, jammed and sliding in."""
    loop = build_loop(load_robot("sim_panda_mujoco"), None)
    world = loop.simulation.scene.world
    states: list[np.ndarray] = []
    step = world.step

    def recording_step() -> None:
        step()
        if world.data.time * 1000 % 5 < 1:
            d = world.data
            states.append(np.concatenate([d.qpos, d.qvel, d.mocap_pos.ravel(),
                                          d.mocap_quat.ravel()]))

    world.step = recording_step
    rng = np.random.default_rng(2)
    loop.begin()
    for start in (0, 5):
        loop.reset(loop.simulation.scene.geometry.start_pose(start))
        for _ in range(4):
            loop.execute(WrenchSetpoint.residual(-15.0, *(3.0 * rng.uniform(-1.0, 1.0, 2))))
    yield world.model, world.data, states
    loop.simulation.close()


def _contacts(m: mujoco.MjModel, d: mujoco.MjData, state: np.ndarray) -> list[tuple]:
    nq, nv = m.nq, m.nv
    d.qpos[:], d.qvel[:] = state[:nq], state[nq:nq + nv]
    d.mocap_pos[:] = state[nq + nv:nq + nv + 3 * m.nmocap].reshape(-1, 3)
    d.mocap_quat[:] = state[nq + nv + 3 * m.nmocap:].reshape(-1, 4)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_collision(m, d)
    return [(c.geom1, c.geom2, c.dist, *c.pos, *c.frame) for c in d.contact[:d.ncon]]


@pytest.mark.slow
def test_the_cells_contacts_are_the_same_with_the_filter(contact_states) -> None:
    """On every recorded state, MuJoCo finds the very same contacts (geoms, depth, point, frame,
    bit for bit) with the filter as with its own bitmask test alone; and most recorded states
    are in contact, so the comparison has something to compare."""
    m, d, states = contact_states
    assert len(states) > 300
    previous = mujoco.get_mjcb_contactfilter()
    try:
        mujoco.set_mjcb_contactfilter(None)
        without = [_contacts(m, d, s) for s in states]
        mujoco.set_mjcb_contactfilter(contact_filter())
        with_filter = [_contacts(m, d, s) for s in states]
    finally:
        mujoco.set_mjcb_contactfilter(previous)
    assert with_filter == without
    assert sum(bool(c) for c in without) > 0.5 * len(states)


def test_the_filter_keeps_fewer_than_two_thirds_of_the_bores_pairs(contact_states) -> None:
    """Of the cylinder-box pairs MuJoCo's mid-phase and bounding spheres let through, the filter
    drops more than a third (measured: 22 a tick kept 11.7 on a 40-step run)."""
    m, d, states = contact_states
    function = ctypes.cast(contact_filter(), ctypes.c_void_p).value
    compiled = _SIGNATURE(function)
    counts = np.zeros(2)

    def counting(m_: mujoco.MjModel, d_: mujoco.MjData, g1: int, g2: int) -> int:
        drop = compiled(m_._address, d_._address, g1, g2)
        passes_bits = (m_.geom_contype[g1] & m_.geom_conaffinity[g2]
                       or m_.geom_contype[g2] & m_.geom_conaffinity[g1])
        near = (np.linalg.norm(d_.geom_xpos[g1] - d_.geom_xpos[g2])
                <= m_.geom_rbound[g1] + m_.geom_rbound[g2])
        if passes_bits and near:                     # what reached the narrow phase before
            counts[0] += 1
            counts[1] += not drop
        return drop

    previous = mujoco.get_mjcb_contactfilter()
    try:
        mujoco.set_mjcb_contactfilter(counting)
        for state in states[::4]:
            _contacts(m, d, state)
    finally:
        mujoco.set_mjcb_contactfilter(previous)
    assert counts[0] > 10 * len(states[::4])          # the bore's many pairs a state
    assert counts[1] < 2 / 3 * counts[0]
