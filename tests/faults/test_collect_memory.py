"""``collect`` in lockstep holds a bounded number of trials, not every trial it has made (issue 37).

The probe saw ``collect`` grow by ~3 MB per trial in lockstep (967 MB for 240 trials) and
stay flat with ``--per-trial``. Found with tracemalloc: on a pool, every job's future kept
its unpickled trials until the whole collection was gathered (2 MB a nominal trial);
in one process (``--workers 1``), all the trials ran as one lockstep group, whose inputs
and logs (B, N, ·) grow with the trial count. Now a job is let go once its trials are
delivered, and one process runs named-intent trials in groups of at most ``NAMED_GROUP``.

The measure: Python's traced memory (numpy's arrays included) each time a trial is
delivered, its maximum over the run less the memory before it: what the collection holds
beside the trial being written. With jobs of 5 trials it must not grow with the number
of trials: the growth from 10 to 40 trials is held below 15 trials' arrays, where the old
code grew by 30 (one per trial) and the new one holds at most the jobs in flight (two
workers: two jobs of 5, and their unpickling), the same for 10 trials as for 40. In one
process the simulation is measured by its lockstep groups' arrays instead (tracemalloc
would slow it tenfold).
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable

import numpy as np

from coassist.data import Trial
from coassist.sim import trial_runner
from coassist.sim.collect import dataset_specs
from coassist.sim.pool import worker_pool
from coassist.sim.trial_runner import run_spec, run_trials

FEW, MANY, JOB = 10, 40, 5
SPECS = dataset_specs(
    controller="cooperative",
    users=[0],
    tasks=["linear", "curved", "sinusoidal"],
    objects=["handle"],
    trials=MANY // 3 + 1,
    seed=0,
)[:MANY]
ARRAYS = ("time", "pose", "velocity", "wrench", "reference", "prediction", "intent", "effort_h", "effort_r", "fault")


def _nbytes(trial: Trial) -> int:
    return sum(a.nbytes for a in (getattr(trial, name) for name in ARRAYS) if a is not None)


def _held(run: Callable[[list, Callable[[int, Trial], None]], None], n: int) -> tuple[int, float]:
    """(most bytes held beside the trial being delivered, mean bytes of a trial's arrays) for the first n specs."""
    held: list[int] = []
    sizes: list[int] = []

    def on_result(i: int, trial: Trial) -> None:
        held.append(tracemalloc.get_traced_memory()[0] - base)
        sizes.append(_nbytes(trial))

    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        run(SPECS[:n], on_result)
    finally:
        tracemalloc.stop()
    assert len(sizes) == n
    return max(held), float(np.mean(sizes))


def test_collect_on_a_pool_does_not_hold_the_trials_it_delivered():
    """Old code: 10 trials held 27 MB, 40 held 90 MB (1.9 MB a trial: every delivered job's future kept
    its trials); now 17 and 25 MB (the jobs in flight)."""
    with worker_pool(2) as pool:

        def run(specs, on_result):
            run_trials(
                specs,
                workers=2,
                pool=pool,
                progress=False,
                lockstep=True,
                groups=len(specs) // JOB,
                on_result=on_result,
            )

        few, size_few = _held(run, FEW)
        many, size_many = _held(run, MANY)
    size = min(size_few, size_many)
    assert size > 1e6  # a nominal trial's arrays, 1.9 MB: the unit of the bound
    assert many - few < 15 * size, (
        f"{FEW} trials held {few / 1e6:.1f} MB, {MANY} held {many / 1e6:.1f} MB ({size / 1e6:.2f} MB a trial)"
    )


def test_collect_in_one_process_runs_bounded_groups(monkeypatch):
    """Old code: one lockstep group of every trial, its arrays twice as large for 20 trials as for 10.

    Measured on the groups' own arrays (inputs and logs, (B, N, ·)), the memory that grew."""
    from coassist.sim import array_runner

    monkeypatch.setattr(trial_runner, "NAMED_GROUP", JOB)
    batch_bytes: list[int] = []
    init = array_runner._Batch.__init__

    def spy(self, loops) -> None:
        init(self, loops)
        batch_bytes.append(sum(v.nbytes for v in vars(self).values() if isinstance(v, np.ndarray)))

    monkeypatch.setattr(array_runner._Batch, "__init__", spy)
    largest: dict[int, int] = {}
    later = JOB + 1  # a trial of the second group
    got: dict[int, Trial] = {}
    for n in (FEW, 2 * FEW):
        batch_bytes.clear()
        run_trials(
            SPECS[:n],
            workers=1,
            progress=False,
            lockstep=True,
            on_result=lambda i, trial: got.__setitem__(i, trial) if i == later else None,
        )
        largest[n] = max(batch_bytes)
    assert largest[2 * FEW] < 1.5 * largest[FEW], largest  # the old code's: 2x
    assert got[later].equals(run_spec(SPECS[later]))  # the numbers are the trial's alone, bit for bit
