"""Speed of ``coassist reproduce`` end to end, per stage: lockstep against the per-trial path, in one run.

Runs the whole pipeline (:func:`coassist.experiments.reproduce.run_reproduce`) on one
preset ``--repeats`` times with the reference path — every simulated trial alone, one
batch-1 network call per trial and tick (``ReproduceConfig.lockstep=False``) — and as
many times with the default lockstep path (one batched call per tick for every trial of
a worker's group, :mod:`coassist.runtime.lockstep`), alternating the two so that a
change in the machine's load falls on both. Prints, per stage and in total, the median
and p99 wall time of each path and the ratio of their medians. The training, the
dMPC study and the real-recordings stage do the same work on both paths; the ratio
is the simulation's.

The two paths give the same trials to the network's float32 rounding (with a model in
the loop; bit for bit without one), so their reports agree; the benchmark checks that
the two runs' claims have the same verdicts and says so.

Usage: ``.venv/bin/python benchmarks/bench_reproduce.py [--preset default] [--repeats 1]``
(the default preset takes tens of minutes for both paths on 2 cores; ``--preset tiny`` a
minute, but its datasets are too small for lockstep to matter).
"""

from __future__ import annotations

import argparse
import os
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from bench_common import machine_line
from coassist.experiments.pipeline import REPRODUCE_PRESETS
from coassist.experiments.reproduce import run_reproduce


def _stats(values: list[float]) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    return float(np.median(v)), float(np.percentile(v, 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="default", help=f"reproduce preset: {', '.join(REPRODUCE_PRESETS)}")
    parser.add_argument("--repeats", type=int, default=1, help="runs of each path (alternating)")
    parser.add_argument("--workers", type=int, default=None, help="simulation processes (default: the preset's)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")
    config = REPRODUCE_PRESETS.lookup(args.preset)
    if args.workers is not None:
        config = replace(config, workers=args.workers)
    print(machine_line())
    print(f"load average before: {os.getloadavg()[0]:.2f} (other processes on the machine inflate every number)")
    print(f"preset {config.name}: workers {config.workers}, torch threads {config.threads}, device {config.device}")
    times: dict[bool, list[dict[str, float]]] = {False: [], True: []}
    verdicts: dict[bool, list[bool]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for lockstep in (False, True):
                out = Path(tmp) / f"{'lockstep' if lockstep else 'per-trial'}-{r}"
                summary = run_reproduce(replace(config, lockstep=lockstep), out, progress=False)
                stages = dict(summary["stage_seconds"])
                stages["total"] = float(summary["total_seconds"])
                times[lockstep].append(stages)
                verdicts.setdefault(lockstep, [bool(c["holds"]) for c in summary["claims"]])
                cpu = summary["cpu_seconds"]
                used = "" if cpu["workers"] is None else f", {cpu['main'] + cpu['workers']:.0f} CPU-s"
                print(f"  run {r + 1}, {'lockstep' if lockstep else 'per-trial'}: {stages['total']:.0f} s{used} "
                      f"(load {os.getloadavg()[0]:.2f})", flush=True)
    print(f"\n{'stage':<24}{'per-trial median':>18}{'p99':>9}{'lockstep median':>18}{'p99':>9}{'ratio':>8}")
    for stage in times[True][0]:
        base, base99 = _stats([t[stage] for t in times[False]])
        fast, fast99 = _stats([t[stage] for t in times[True]])
        print(f"{stage:<24}{base:>16.1f} s{base99:>7.1f} s{fast:>16.1f} s{fast99:>7.1f} s{base / fast:>7.2f}×")
    same = verdicts[False] == verdicts[True]
    print(f"\nclaims' verdicts: {'the same' if same else 'DIFFERENT'} on both paths "
          f"({sum(verdicts[True])} of {len(verdicts[True])} hold with lockstep)")


if __name__ == "__main__":
    main()
