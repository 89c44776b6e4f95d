"""The shaft cell's per-tick MuJoCo work in compiled code: its contact filter
(``contact_filter.c``) and the sum of its contacts' wrench on the shaft (``contact_wrench.c``).

A cylinder against a box or convex mesh is MuJoCo's costliest common pair (its general convex
collider), and a shaft in a ring of 48 bore boxes sent 22 such pairs a tick to it. The filter
drops the pairs a separating axis proves apart before they get there; the contacts are the same,
bit for bit. The wrench sum is what the ground truth and the ground-truth estimator read, 1.3 us
a call where Python's loop over the contacts took 20-36. ``scripts/setup.sh`` compiles both against
the MuJoCo wheel's headers (the wrench sum calls MuJoCo's ``mj_contactForce``, so it links to
the wheel's library).
"""
from __future__ import annotations

import ctypes
from importlib.resources import files

import mujoco

__all__ = ["CONTACT_FILTER_LIBRARY", "CONTACT_WRENCH_LIBRARY", "contact_filter",
           "contact_wrench_sum", "install_contact_filter"]

#: The compiled filter (``scripts/setup.sh``, step 6b).
CONTACT_FILTER_LIBRARY = files(__name__) / "_contact_filter.so"
#: The compiled wrench sum (the same step).
CONTACT_WRENCH_LIBRARY = files(__name__) / "_contact_wrench.so"

_filter: ctypes._CFuncPtr | None = None
_wrench_sum: ctypes._CFuncPtr | None = None


def _load(library: object, what: str) -> ctypes.CDLL:
    try:
        return ctypes.CDLL(str(library))
    except OSError as error:
        raise ImportError(f"the shaft cell's {what} {library} is missing or stale: run "
                          "scripts/setup.sh") from error


def contact_filter() -> ctypes._CFuncPtr:
    """The filter as a C function pointer: ``int f(const mjModel*, mjData*, int, int)``, 1 drops
    the pair (loaded once per process).

    :raises ImportError: if the library was not built (``scripts/setup.sh`` builds it).
    """
    global _filter
    if _filter is None:
        _filter = _load(CONTACT_FILTER_LIBRARY, "contact filter").shaft_contact_filter
    return _filter


def contact_wrench_sum() -> ctypes._CFuncPtr:
    """``void f(const mjModel*, const mjData*, int geom, int body, double out[6])``: the wrench
    the last collision's contacts exert on ``geom``, about ``body``'s origin, in its frame
    (loaded once per process).

    :raises ImportError: if the library was not built (``scripts/setup.sh`` builds it).
    """
    global _wrench_sum
    if _wrench_sum is None:
        _wrench_sum = _load(CONTACT_WRENCH_LIBRARY, "contact wrench sum").shaft_contact_wrench
        _wrench_sum.restype = None
    return _wrench_sum


def install_contact_filter() -> None:
    """Make :func:`contact_filter` MuJoCo's contact filter (``mjcb_contactfilter``).

    MuJoCo has one filter per process; this installs ours unless another is there already (a
    caller's own filter is left alone, and the simulation is then only slower, never different).
    """
    current = mujoco.get_mjcb_contactfilter()
    if current is None:
        mujoco.set_mjcb_contactfilter(contact_filter())
