"""Calibration trials in lockstep: their probes stepped together against each by its own tick (issue 44).

    .venv/bin/python benchmarks/bench_probe.py [--trials 8] [--repeats 5] [--seed 880000]

Runs one calibration draw of the main job (the application's task and preset, the handle, MG with the probe, the
default's three operators × ``--trials`` trials) in one lockstep group, two ways alternated, on the point-mass array
path (:mod:`coassist.sim.array_runner`, how the main job's point-mass calibrations run) and on ``run_loops`` (how a
lockstep group of MuJoCo drives steps its controllers):

- ``together``: the calibration runs' controllers stepped in one call a tick (``probed_efforts`` on the array path,
  ``probed_steps`` in ``run_loops``: MG's guard once over the batch, then each run's push);
- ``alone`` (the naive baseline, the code before): each run's :class:`~coassist.control.probe.ProbedGuidance` stepped
  by its own tick (``probed_groups`` finds no group).

The two must give the same trials bit for bit (the benchmark stops otherwise). Prints the process's CPU time per
trial-tick, median and p99 over the repeats [µs], and the ratio of the medians. One BLAS thread.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from unittest import mock  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import machine_line  # noqa: E402
from coassist.experiments.reproduce_config import ReproduceConfig  # noqa: E402
from coassist.runtime import batched_loops  # noqa: E402
from coassist.sim import array_runner  # noqa: E402
from coassist.sim.trial_runner import TrialSpec, run_spec_lockstep  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=8, help="calibration trials an operator (the default's 8)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seed", type=int, default=880000)
    args = parser.parse_args()
    if args.trials < 1 or args.repeats < 1:
        parser.error("--trials and --repeats must be at least 1")
    print(machine_line())
    cfg = ReproduceConfig()
    specs = [
        TrialSpec(
            task=cfg.application_task,
            seed=args.seed + 100 * u + j,
            user=u,
            object="handle",
            controller="manual-probe",
            intent="nominal",
            preset=cfg.application_preset,
            obstacle="large",
        )
        for u in cfg.application_users
        for j in range(args.trials)
    ]
    for arrays in (True, False):
        times: dict[str, list[float]] = {"together": [], "alone": []}
        reference = None
        for _ in range(args.repeats):
            for way in ("together", "alone"):
                patches = (
                    [
                        mock.patch.object(array_runner, "probed_groups", _no_groups),
                        mock.patch.object(batched_loops, "probed_groups", _no_groups),
                    ]
                    if way == "alone"
                    else []
                )
                for p in patches:
                    p.start()
                try:
                    t0 = time.process_time()
                    trials = run_spec_lockstep(specs, arrays=arrays)
                    cpu = time.process_time() - t0
                finally:
                    for p in patches:
                        p.stop()
                ticks = sum(t.n_samples for t in trials)
                times[way].append(1e6 * cpu / ticks)
                if reference is None:
                    reference = trials
                elif not all(a.equals(b) for a, b in zip(reference, trials, strict=True)):
                    raise SystemExit(f"arrays={arrays}: the trials of {way} differ from the first run's")
        where = "array path" if arrays else "run_loops"
        for way, ts in times.items():
            print(
                f"{where:>10}, {way:>8}: median {np.median(ts):.1f} µs, p99 {np.percentile(ts, 99):.1f} µs CPU a "
                f"trial-tick ({len(specs)} trials, {ticks} trial-ticks, {len(ts)} runs)"
            )
        print(
            f"{where:>10}: ratio alone / together (medians): {np.median(times['alone']) / np.median(times['together']):.2f}"
        )


def _no_groups(ticks) -> list[None]:
    """``probed_groups`` finding none: every run's controller stepped by its own tick (the code before)."""
    return [None] * len(ticks)


if __name__ == "__main__":
    main()
