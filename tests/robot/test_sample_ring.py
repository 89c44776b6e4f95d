"""The loop's sample ring: every record written is taken once, in order, or counted as lost."""
from __future__ import annotations

import numpy as np
import pytest
from qg_common.types import GroundTruth
from robot_bridge_node.core.sample_ring import (
    TRUTH_SIZE,
    SampleRing,
    truth_from_array,
    truth_to_array,
)


def write(ring: SampleRing, first: int, n: int) -> None:
    for tick in range(first, first + n):
        q = np.full(ring.n_joints, float(tick))
        truth = ring.write(1000 * tick, tick, 5, q, -q, 2 * q, 3 * q, np.arange(6.0),
                           -np.arange(6.0), np.ones(3), np.eye(3), np.full(6, 0.5))
        truth[:] = tick
        ring.commit()


def test_records_come_out_once_in_order_across_the_wrap() -> None:
    ring = SampleRing.create(n_joints=3, capacity=8)
    taken = []
    for first, n in ((0, 5), (5, 3), (8, 6), (14, 0), (14, 8)):
        write(ring, first, n)
        records = ring.take()
        assert len(records) == n
        taken.extend(records["tick"].tolist())
        assert np.array_equal(records["q"][:, 0], records["tick"].astype(float))
        assert np.array_equal(records["tau"][:, -1], 2.0 * records["tick"])
        assert np.array_equal(records["tau_cmd"][:, -1], 3.0 * records["tick"])
        assert np.array_equal(records["own_wrench"][:, 5], np.full(n, -5.0))
        assert np.all(records["flags"] == 5) and np.all(records["tool_rotation"] == np.eye(3))
        assert np.array_equal(records["wrench"][:, 5], np.full(n, 5.0))
        assert np.array_equal(records["truth"][:, 13], records["tick"].astype(float))
    assert taken == list(range(22)) and ring.lost == 0
    assert ring.written == 22 and ring.latest_t_ns() == 21_000
    ring.close()


def test_a_reader_that_falls_behind_counts_what_was_overwritten() -> None:
    ring = SampleRing.create(n_joints=2, capacity=8)
    write(ring, 0, 20)
    records = ring.take()
    assert records["tick"].tolist() == list(range(12, 20))   # the newest capacity's worth
    assert ring.lost == 12
    write(ring, 20, 1)
    assert ring.take()["tick"].tolist() == [20] and ring.lost == 12
    ring.close()


def test_another_mapping_of_the_same_file_reads_what_one_writes() -> None:
    """The loop process attaches to the ring by its file descriptor (here in one process)."""
    import os
    writer = SampleRing.create(n_joints=7, capacity=16)
    reader = SampleRing.attach(os.dup(writer.fd))
    assert (reader.n_joints, reader.capacity) == (7, 16)
    write(writer, 0, 3)
    assert reader.take()["tick"].tolist() == [0, 1, 2]
    writer.close()
    reader.close()
    with pytest.raises(ValueError, match="no sample ring"):
        empty = os.memfd_create("empty")
        os.ftruncate(empty, 64)
        SampleRing.attach(empty)


def test_ground_truth_goes_through_a_record_unchanged() -> None:
    truth = GroundTruth(wrench=np.arange(6.0), insertion_depth=0.011, plunger_travel=0.003,
                        success=True, position_error=0.002, orientation_error=np.array([0.1, -0.2]),
                        lateral_offset=0.004, tilt=0.26)
    values = np.zeros(TRUTH_SIZE)
    truth_to_array(truth, values)
    back = truth_from_array(values)
    assert np.array_equal(back.wrench, truth.wrench) and back.success is True
    assert (back.insertion_depth, back.plunger_travel, back.position_error, back.lateral_offset,
            back.tilt) == (0.011, 0.003, 0.002, 0.004, 0.26)
    assert np.array_equal(back.orientation_error, truth.orientation_error)
