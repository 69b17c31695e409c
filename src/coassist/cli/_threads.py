"""The cores a command's torch threads may use: checked, and said where other work shares them."""

from __future__ import annotations

import os

from coassist.cli._common import console, fail

__all__ = ["busy_cores_hint", "check_threads", "idle_cores", "set_torch_threads", "usable_cores"]


def usable_cores() -> int:
    """The cores this process may run on (its affinity, else the machine's)."""
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def check_threads(threads: int | None, option: str = "--threads") -> None:
    """Refuse a thread count given on the command line above :func:`usable_cores` (``--threads 100000`` once ran
    out of memory in a traceback)."""
    if threads is not None and threads > (cores := usable_cores()):
        fail(f"{option} must be at most the {cores} cores this process may use, got {threads}", 2)


def idle_cores(seconds: float = 0.2) -> float | None:
    """How many of the machine's cores were idle over the next ``seconds`` (Linux ``/proc/stat``: idle and iowait
    time over all time, times the cores), this process asleep meanwhile; None where it cannot be read."""
    import time

    def sample() -> tuple[int, int] | None:
        try:
            with open("/proc/stat", encoding="ascii") as f:
                fields = [int(v) for v in f.readline().split()[1:]]
        except (OSError, ValueError):
            return None
        return (fields[3] + (fields[4] if len(fields) > 4 else 0), sum(fields)) if len(fields) >= 4 else None

    first = sample()
    time.sleep(seconds)
    last = sample()
    if first is None or last is None or last[1] <= first[1]:
        return None
    return (last[0] - first[0]) / (last[1] - first[1]) * (os.cpu_count() or 1)


def busy_cores_hint(threads: int, option: str = "--threads") -> None:
    """A line where ``threads`` torch threads would share cores with other work: they wait for each other at every
    step, spinning (OpenMP), and a training beside other work ran several times slower on two threads than on one
    (this 2-core VM beside other work: ``coassist train`` 80 s on two threads, 18 s on one; quiet, two were 1.8 times
    one's speed: docs/history.md). Nothing is changed: the same command trains the same model whatever the load."""
    if threads < 2:
        return
    idle = idle_cores()
    if idle is not None and idle < threads - 0.5:
        console.print(
            f"note: {idle:.1f} of this machine's {os.cpu_count()} cores are idle: {threads} torch threads that wait for "
            f"each other run several times slower beside other work; {option} 1 trains alone on one",
            highlight=False,
            markup=False,
        )


def set_torch_threads(threads: int) -> None:
    """Torch's intra-op thread count for this process: the command's choice (the library never sets it)."""
    import torch

    torch.set_num_threads(threads)
