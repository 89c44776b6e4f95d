"""The torque loop's per-tick arithmetic in compiled code (``torque_kernels.cpp``,
``tick_arithmetic.cpp``).

``scripts/setup.sh`` builds it against the pinned Pinocchio, Eigen and pybind11 wheels; the
classes that own the configuration, the validation and the documentation of the maths are
``core/wrench_ekf.py``, ``core/impedance.py``, ``core/safety.py`` and, for the simulated arm's
friction and readings, ``sim_robot_node/core/arm_imperfections.py``. docs/design.md ("The 1 kHz
tick in compiled code") has the measurements that chose this over NumPy and numba.
"""
from __future__ import annotations

try:
    from ._tick_arithmetic import ArmErrors, TorqueLimiter
    from ._torque_kernels import ImpedanceKernel, WrenchEkfKernel
except ImportError as error:          # pragma: no cover - a setup that skipped the build
    raise ImportError("the torque loop's compiled kernels are missing or stale: run "
                      "scripts/setup.sh (its step 6 builds them)") from error

__all__ = ["ArmErrors", "ImpedanceKernel", "TorqueLimiter", "WrenchEkfKernel"]
