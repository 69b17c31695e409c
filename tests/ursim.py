"""``coassist ur-sim`` for the tests: a simulator on an address of its own, real-time priority where allowed.

The UR's ports are fixed (29999, 30001-30004), so each simulator listens on its own loopback
address (any 127.x.y.z is this machine): tests running side by side (``-n 2``, another
worktree's suite) never meet. The simulator asks for SCHED_FIFO (it sleeps most of each
2 ms period), and :func:`realtime_priority` gives the test's own control loop the same where
the system allows it, as a lab runs its controller (``chrt -f``): on this shared 2-core
machine a loop at normal priority misses deadlines that are the machine's, not the code's.

Each simulator runs in a process started ahead (:func:`~coassist.robot.ur_sim.process.spawn`:
its imports done, waiting for its config): the next test's is started as this one's simulator
stops, and imports while the test's world is destroyed (ur-rtde's destructors, ~1 s) and the
next test sets up, not while a real-time loop runs. A process that has only imported carries no
state from one test to the next; each test still gets a simulator of its own.
"""

from __future__ import annotations

import atexit
import contextlib
import itertools
import os
import subprocess
from collections.abc import Iterator

import pytest

_counter = itertools.count(1)
#: the process the next :func:`simulator` starts in (at most one)
_spare: list[subprocess.Popen[str]] = []


def _take_spare() -> subprocess.Popen[str]:
    from coassist.robot.ur_sim.process import spawn

    while _spare:
        proc = _spare.pop()
        if proc.poll() is None:
            return proc
    return spawn()


def _start_spare() -> None:
    from coassist.robot.ur_sim.process import spawn

    if not _spare:
        _spare.append(spawn())


@atexit.register
def _end_spare() -> None:
    # it would end on its own when its stdin closes with this process; ended here, none outlives pytest
    while _spare:
        proc = _spare.pop()
        proc.kill()
        proc.wait(10)


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
            sim.start(_take_spare())
        except RuntimeError as exc:  # the address was taken: the next one
            last = exc
            continue
        try:
            yield sim
        finally:
            sim.stop()
            _start_spare()  # the next test's, importing while this one's world is destroyed
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
