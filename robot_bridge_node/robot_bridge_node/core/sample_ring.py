"""The loop's every tick, handed to another process through shared memory without a lock.

The 1 kHz loop runs in a process of its own (``loop_process``) and writes one record per tick
(joint state, wrench estimate, tool pose and twist, ground truth when computed) into a ring of
records in an anonymous shared-memory file (``memfd``) that the ROS side of the robot process
maps too. One writer, one reader: the writer fills the record at ``count % capacity``
(``write``) and then advances ``count`` (``commit``); the reader copies the records it has not
seen and checks ``count`` again, so a record the writer overwrote while it was being copied is
counted as lost, never read torn. Writing a record costs the loop two copies and no lock or
system call (with the reads of the state it holds, ``RingOutlet.sample``: 2.9 us, 1.9 % of a
tick, ``benchmarks/loop_process_bench.py``). Stores become visible in program order on x86-64,
which this relies on; the file has no name, so nothing is left behind when both processes are
gone.
"""
from __future__ import annotations

import mmap
import os
from dataclasses import dataclass

import numpy as np
from qg_common.types import GroundTruth

__all__ = ["SampleRing", "record_dtype", "truth_to_array", "truth_from_array", "TRUTH_SIZE",
           "PUBLISH", "HAS_WRENCH", "HAS_TRUTH", "HAS_TOOL", "HAS_OWN_WRENCH", "DEFAULT_CAPACITY"]

#: Record flags.
PUBLISH, HAS_WRENCH, HAS_TRUTH, HAS_TOOL, HAS_OWN_WRENCH = 1, 2, 4, 8, 16
#: [records] 16 s at 1 kHz: the reader may stall this long (a loaded machine) without loss.
DEFAULT_CAPACITY = 16384
_HEADER = 8                     # int64 words before the records: count, capacity, joints
#: ``GroundTruth`` as numbers: wrench 6, depth, travel, success, position error, orientation
#: error 2, lateral offset, tilt.
TRUTH_SIZE = 14


def record_dtype(n_joints: int) -> np.dtype:
    """One tick's record for an arm of ``n_joints`` joints: ``tau`` the measured joint torques,
    ``tau_cmd`` the torques the loop commanded (on a simulated arm the first is the second as
    its sensors read it; a real arm's sensors read what the links got); ``wrench`` the loop's
    estimate of the contact wrench, ``own_wrench`` the robot's own where it has one
    (``Robot.own_wrench``)."""
    return np.dtype([("t_ns", np.int64), ("tick", np.int64), ("flags", np.int64),
                     ("q", np.float64, n_joints), ("dq", np.float64, n_joints),
                     ("tau", np.float64, n_joints), ("tau_cmd", np.float64, n_joints),
                     ("wrench", np.float64, 6), ("own_wrench", np.float64, 6),
                     ("tool_position", np.float64, 3), ("tool_rotation", np.float64, (3, 3)),
                     ("tool_twist", np.float64, 6), ("truth", np.float64, TRUTH_SIZE)])


def truth_to_array(truth: GroundTruth, out: np.ndarray) -> None:
    """Write ``truth`` into ``out`` (``TRUTH_SIZE`` numbers)."""
    out[:6] = truth.wrench
    out[6:10] = (truth.insertion_depth, truth.plunger_travel, float(truth.success),
                 truth.position_error)
    out[10:12] = truth.orientation_error
    out[12:14] = (truth.lateral_offset, truth.tilt)


def truth_from_array(values: np.ndarray) -> GroundTruth:
    """The ``GroundTruth`` that ``truth_to_array`` wrote."""
    return GroundTruth(wrench=values[:6].copy(), insertion_depth=float(values[6]),
                       plunger_travel=float(values[7]), success=bool(values[8] > 0.5),
                       position_error=float(values[9]), orientation_error=values[10:12].copy(),
                       lateral_offset=float(values[12]), tilt=float(values[13]))


@dataclass
class SampleRing:
    """A ring of tick records in a shared-memory file; ``create`` it on one side, ``attach`` to
    its file descriptor on the other (passed to the child process).

    :param fd: the shared-memory file.
    :param n_joints: the arm's joint count (the records' size).
    :param capacity: records in the ring.
    """
    fd: int
    n_joints: int
    capacity: int

    def __post_init__(self) -> None:
        self.dtype = record_dtype(self.n_joints)
        size = _HEADER * 8 + self.capacity * self.dtype.itemsize
        # Mapped with its pages in place: a page first touched by a tick would cost it a fault
        # (about +5 % on a tick, measured, until the ring had wrapped once).
        self._map = mmap.mmap(self.fd, size, flags=mmap.MAP_SHARED | mmap.MAP_POPULATE)
        self._header = np.frombuffer(self._map, dtype=np.int64, count=_HEADER)
        self.records = np.frombuffer(self._map, dtype=self.dtype, count=self.capacity,
                                     offset=_HEADER * 8)
        self._read = int(self._header[0])   # the reader's position (records already taken)
        self.lost = 0                       # records overwritten before the reader took them
        # The writer's views: a record as int64 words (stamp, tick, flags first) and as float64
        # words (the rest, in the dtype's order, the ground truth last).
        words = self.dtype.itemsize // 8
        self._ints = self.records.view(np.int64).reshape(self.capacity, words)
        self._floats = self.records.view(np.float64).reshape(self.capacity, words)
        self._truth_at = words - TRUTH_SIZE

    @classmethod
    def create(cls, n_joints: int, capacity: int = DEFAULT_CAPACITY) -> SampleRing:
        """A new, empty ring in an anonymous shared-memory file (``fd`` to pass on)."""
        if capacity < 2:
            raise ValueError(f"capacity must be >= 2 records, got {capacity}")
        fd = os.memfd_create("qg_loop_samples", 0)
        os.ftruncate(fd, _HEADER * 8 + capacity * record_dtype(n_joints).itemsize)
        ring = cls(fd, n_joints, capacity)
        ring._header[1:3] = (capacity, n_joints)
        return ring

    @classmethod
    def attach(cls, fd: int) -> SampleRing:
        """The ring another process created, from its file descriptor.

        :raises ValueError: if the file holds no ring.
        """
        header = np.frombuffer(mmap.mmap(fd, _HEADER * 8), dtype=np.int64, count=_HEADER)
        capacity, n_joints = int(header[1]), int(header[2])
        if capacity < 2 or n_joints < 1:
            raise ValueError(f"file descriptor {fd} holds no sample ring")
        return cls(fd, n_joints, capacity)

    # --- the writer (the loop) ---------------------------------------------------------------
    def write(self, t_ns: int, tick: int, flags: int, q: np.ndarray, dq: np.ndarray,
              tau: np.ndarray, tau_cmd: np.ndarray, wrench: np.ndarray, own_wrench: np.ndarray,
              position: np.ndarray, rotation: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """Fill the next record in two copies (the loop's per-tick write: ~1.5 us, where a
        field-by-field fill took 3.7 us); returns its ``truth`` numbers, to fill before
        ``commit`` on a tick that has them."""
        i = int(self._header[0]) % self.capacity
        np.concatenate((q, dq, tau, tau_cmd, wrench, own_wrench, position, rotation.ravel(),
                        twist),
                       out=self._floats[i, 3:self._truth_at])
        words = self._ints[i]
        words[0], words[1], words[2] = t_ns, tick, flags
        return self._floats[i, self._truth_at:]

    def commit(self) -> None:
        """The record just filled is complete: the reader may take it."""
        self._header[0] += 1

    @property
    def written(self) -> int:
        """Records written since the ring was created."""
        return int(self._header[0])

    def latest_t_ns(self) -> int | None:
        """The stamp of the newest record (None before the first)."""
        count = int(self._header[0])
        return None if count == 0 else int(self.records[(count - 1) % self.capacity]["t_ns"])

    # --- the reader --------------------------------------------------------------------------
    def take(self) -> np.ndarray:
        """Copies of the records written since the last ``take``, oldest first; records the
        writer overwrote before they were taken are counted in ``lost``."""
        count = int(self._header[0])
        start = max(self._read, count - self.capacity)
        self.lost += start - self._read
        if count == start:
            return self.records[:0].copy()
        first, last = start % self.capacity, count % self.capacity
        if first < last:
            taken = self.records[first:last].copy()
        else:
            taken = np.concatenate([self.records[first:], self.records[:last]])
        # Records the writer reached again while they were being copied are not trusted.
        overwritten = max(0, int(self._header[0]) - self.capacity - start)
        self.lost += min(overwritten, len(taken))
        self._read = count
        return taken[overwritten:]

    def close(self) -> None:
        """Unmap the ring and close this process's file descriptor."""
        self.records = self._header = self._ints = self._floats = None  # type: ignore[assignment]
        self._map.close()
        os.close(self.fd)
