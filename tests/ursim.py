"""``coassist ur-sim`` for the tests: a simulator on an address of its own, real-time priority where allowed.

The UR's ports are fixed (29999, 30001-30004), so each simulator listens on its own loopback
address (any 127.x.y.z is this machine): tests running side by side (``-n 2``, another
worktree's suite) never meet. The simulator asks for SCHED_FIFO (it sleeps most of each
2 ms period), and :func:`realtime_priority` gives the test's own control loop the same where
the system allows it, as a lab runs its controller (``chrt -f``): on this shared 2-core
machine a loop at normal priority misses deadlines that are the machine's, not the code's.
"""

from __future__ import annotations

import contextlib
import itertools
import os
from collections.abc import Iterator

import pytest

_counter = itertools.count(1)


def free_host() -> str:
    """A loopback address no other test process uses: 127.<pid>.<n>."""
    pid = os.getpid()
    n = next(_counter)
    return f"127.{100 + pid % 100}.{(pid // 100) % 250 + 1}.{n % 250 + 1}"


@contextlib.contextmanager
def simulator(**config) -> Iterator:
    """A started :class:`~coassist.robot.ur_sim.process.URSimProcess` (another address when one is taken)."""
    from coassist.robot.ur_sim import URSimConfig
    from coassist.robot.ur_sim.process import URSimProcess

    config.setdefault("rt_priority", 20)
    last: Exception | None = None
    for _ in range(5):
        sim = URSimProcess(URSimConfig(host=free_host(), **config))
        try:
            sim.start()
        except RuntimeError as exc:  # the address was taken: the next one
            last = exc
            continue
        try:
            yield sim
        finally:
            sim.stop()
        return
    raise RuntimeError(f"no simulator started: {last}")


@contextlib.contextmanager
def realtime_priority(priority: int = 10) -> Iterator[bool]:
    """SCHED_FIFO for the calling thread (and the threads it starts, not the processes) while inside;
    yields whether granted."""
    try:
        # not for the processes it forks (a predictor's or a training's worker would take a core for ever)
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
        granted = True
    except (AttributeError, OSError):
        granted = False
    try:
        yield granted
    finally:
        if granted:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def needs_ur_rtde() -> None:
    """Skip the module unless the real client is installed (the robot extra)."""
    pytest.importorskip("rtde_control", reason="the real client: pip install 'coassist[robot]' (ur-rtde)")
    pytest.importorskip("rtde_receive", reason="the real client: pip install 'coassist[robot]' (ur-rtde)")
