"""What Linux says of a process: its memory and its children (``/proc``), for the long-run
benchmarks and the tests that kill a stack's processes."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["rss_kib", "child_processes", "cpu_seconds"]

_CLOCK_TICKS = os.sysconf("SC_CLK_TCK")      # the unit of /proc/<pid>/stat's times


def rss_kib(pid: int) -> int:
    """Resident set size of process ``pid`` [KiB] (0 once it has exited)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))
    except (OSError, StopIteration):
        return 0


def cpu_seconds(pid: int, children: bool = True) -> float:
    """CPU time process ``pid`` has used, user and system [s] (0 once it has exited), with that
    of its live children if ``children`` (a robot process's forked 1 kHz loop)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    ticks = float(fields[11]) + float(fields[12])           # utime, stime
    seconds = ticks / _CLOCK_TICKS
    if children:
        seconds += sum(cpu_seconds(child, children=True) for child in child_processes(pid))
    return seconds


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
