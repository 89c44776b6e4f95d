"""MuJoCo's contact filter for the shaft cell, in compiled code (``contact_filter.c``).

A cylinder against a box or convex mesh is MuJoCo's costliest common pair (its general convex
collider, ~1 us a pair), and a shaft in a ring of 48 bore boxes sends 22 such pairs a tick to it.
The filter drops the pairs a separating axis proves apart before they get there; the contacts
are the same, bit for bit. ``scripts/setup.sh`` compiles it against the MuJoCo wheel's headers.
"""
from __future__ import annotations

import ctypes
from importlib.resources import files

import mujoco

__all__ = ["CONTACT_FILTER_LIBRARY", "contact_filter", "install_contact_filter"]

#: The compiled filter (``scripts/setup.sh``, the step "the shaft cell's contact filter").
CONTACT_FILTER_LIBRARY = files(__name__) / "_contact_filter.so"

_filter: ctypes._CFuncPtr | None = None


def contact_filter() -> ctypes._CFuncPtr:
    """The filter as a C function pointer: ``int f(const mjModel*, mjData*, int, int)``, 1 drops
    the pair (loaded once per process).

    :raises ImportError: if the library was not built (``scripts/setup.sh`` builds it).
    """
    global _filter
    if _filter is None:
        try:
            library = ctypes.CDLL(str(CONTACT_FILTER_LIBRARY))
        except OSError as error:
            raise ImportError(f"the shaft cell's contact filter {CONTACT_FILTER_LIBRARY} is "
                              "missing or stale: run scripts/setup.sh") from error
        _filter = library.shaft_contact_filter
    return _filter


def install_contact_filter() -> None:
    """Make :func:`contact_filter` MuJoCo's contact filter (``mjcb_contactfilter``).

    MuJoCo has one filter per process; this installs ours unless another is there already (a
    caller's own filter is left alone, and the simulation is then only slower, never different).
    """
    current = mujoco.get_mjcb_contactfilter()
    if current is None:
        mujoco.set_mjcb_contactfilter(contact_filter())
