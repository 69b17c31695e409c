"""CPU seconds of this process and its child processes: the work a run did, not its wall time.

On a shared machine wall time moves with other processes' load; CPU seconds move much
less (they still grow somewhat when cores are contended: caches, frequency), so runs are
compared by both. A run's worker processes (``sim.pool.worker_pool``) live as long as
the run, so their time is read while they run: from ``/proc/<pid>/stat`` (Linux), the
user and system time of every child process still alive, plus what the children that
have ended and been waited for used (``resource.getrusage(RUSAGE_CHILDREN)``).
Elsewhere only this process is counted, and :func:`children_seconds` says so by
returning None.
"""

from __future__ import annotations

import multiprocessing
import os
import resource
import time
from pathlib import Path
from typing import NamedTuple

__all__ = ["CpuSeconds", "children_seconds", "run_cpu_seconds"]


def _proc_seconds(pid: int, ticks: float) -> float | None:
    """utime + stime of a live process [s] from /proc/<pid>/stat, None where it cannot be read."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # The command name (field 2) is in parentheses and may hold spaces: split after its ')'.
    fields = stat[stat.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / ticks  # fields 14 and 15 of proc(5)


def children_seconds() -> float | None:
    """CPU seconds of this process's children: the live ones (``multiprocessing.active_children``,
    read from /proc) and those already waited for. None where /proc cannot be read."""
    if not Path("/proc/self/stat").exists():
        return None
    ticks = float(os.sysconf("SC_CLK_TCK"))
    reaped = resource.getrusage(resource.RUSAGE_CHILDREN)
    total = reaped.ru_utime + reaped.ru_stime
    for child in multiprocessing.active_children():
        if child.pid is None:
            continue
        seconds = _proc_seconds(child.pid, ticks)
        if seconds is not None:  # it ended between the listing and the read: counted once reaped
            total += seconds
    return total


class CpuSeconds(NamedTuple):
    """CPU seconds: ``main``, this process's (all its threads); ``workers``, its children's
    (None where they cannot be read)."""

    main: float
    workers: float | None

    @property
    def total(self) -> float | None:
        return None if self.workers is None else self.main + self.workers

    def since(self, before: CpuSeconds) -> CpuSeconds:
        """What was used from ``before`` to this reading."""
        workers = None if self.workers is None or before.workers is None else self.workers - before.workers
        return CpuSeconds(self.main - before.main, workers)

    def to_dict(self) -> dict[str, float | None]:
        return {"main": self.main, "workers": self.workers}


def run_cpu_seconds() -> CpuSeconds:
    """This process's and its children's CPU seconds so far."""
    return CpuSeconds(time.process_time(), children_seconds())
