"""coassist._cpu: the CPU seconds of this process and of its live and ended children."""

import multiprocessing
import os
import time
from pathlib import Path

import pytest

from coassist._cpu import children_seconds, run_cpu_seconds

BURN = 0.4  # CPU seconds a child spends for certain


def _burn(seconds: float, done) -> None:
    start = time.process_time()
    while time.process_time() - start < seconds:
        pass
    done.set()
    time.sleep(30)  # stay alive: its time must be read from /proc, not from the reaped total


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads live children's CPU time from /proc (Linux)")
def test_a_live_child_and_an_ended_one_are_counted():
    ctx = multiprocessing.get_context("spawn")
    before = children_seconds()
    done = ctx.Event()
    child = ctx.Process(target=_burn, args=(BURN, done), daemon=True)
    child.start()
    try:
        assert done.wait(60)
        alive = children_seconds()
        # at least what it burnt (less /proc's rounding down of user and system time to a clock
        # tick each); at most that plus the interpreter's start-up (seconds, not minutes)
        tick = 1.0 / os.sysconf("SC_CLK_TCK")
        assert before + BURN - 2 * tick <= alive < before + BURN + 20.0
    finally:
        child.kill()
        child.join()
    assert children_seconds() >= alive - 0.05  # once reaped, rusage holds it (its last ticks included)


def test_run_cpu_seconds_counts_this_process():
    a = run_cpu_seconds()
    start = time.process_time()
    while time.process_time() - start < 0.1:
        pass
    b = run_cpu_seconds()
    assert b.main - a.main >= 0.1 and b.since(a).main >= 0.1


def test_readings_subtract_and_an_unreadable_side_stays_unknown():
    from coassist._cpu import CpuSeconds

    assert CpuSeconds(5.0, 9.0).since(CpuSeconds(2.0, 4.0)) == CpuSeconds(3.0, 5.0)
    assert CpuSeconds(5.0, 9.0).since(CpuSeconds(2.0, 4.0)).total == 8.0
    assert CpuSeconds(5.0, None).since(CpuSeconds(2.0, 4.0)) == CpuSeconds(3.0, None)
    assert CpuSeconds(5.0, None).total is None
