"""What Linux says of a process: its memory and its children (``/proc``), for the long-run
benchmarks and the tests that kill a stack's processes."""
from __future__ import annotations

from pathlib import Path

__all__ = ["rss_kib", "child_processes"]


def rss_kib(pid: int) -> int:
    """Resident set size of process ``pid`` [KiB] (0 once it has exited)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))
    except (OSError, StopIteration):
        return 0


def child_processes(parent: int) -> dict[int, list[str]]:
    """The children of process ``parent``: pid -> command line (``ros2 run``'s child runs
    ``lib/<package>/<executable>``)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except (OSError, IndexError, ValueError):
            continue
        if ppid == parent:
            found[int(entry.name)] = [a.decode(errors="replace") for a in argv if a]
    return found
