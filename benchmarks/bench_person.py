"""The person model's work per control tick, against a naive search, and the deadline (issue 40).

    .venv/bin/python benchmarks/bench_person.py [--calibration 10] [--repeats 3] [--seed 950000]

Fits one simulated operator's person model (operator 1 of the thesis population) from
``--calibration`` probe trials (manual guidance with the probe, what a lab records), records the
feature rows of one application trial with it in the loop (the board, the arbitrated controller),
then replays them through fresh sources and times every ``predict`` call:

- ``present``: the present estimate alone (the arm assumed, no paths);
- ``person``: the person model as fitted (its ways' curves searched within ``search_window`` of the
  arc length where the person was last);
- the naive baseline: the same filter searching ±20 cm of every curve on every tick (the widest
  ``search_window`` allowed, some 60 % of the application path's length) instead of ±2 cm.

Times are the thread's CPU time (``time.thread_time_ns``): on a shared machine a wall clock counts the
ticks another process preempted. Prints median and p99 [µs] per tick, the ratio to the naive search, and the share of the control
period it takes at 125 Hz (8 ms), 500 Hz (2 ms) and a Franka's 1 kHz (1 ms). One BLAS thread.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import RecordsWindows, machine_line, replay  # noqa: E402
from coassist.control.presets import get_preset, make_controller  # noqa: E402
from coassist.runtime.episode import run_episode  # noqa: E402
from coassist.scenario.objects import get_object  # noqa: E402
from coassist.scenario.operator import operator_profile  # noqa: E402
from coassist.scenario.person_intent import PersonFilterSettings, PersonPathsIntent  # noqa: E402
from coassist.scenario.person_model import (
    PERSON_FILTER,  # noqa: E402
    fit_person,  # noqa: E402
)
from coassist.scenario.tasks import task_for_seed  # noqa: E402
from coassist.sim.trial_runner import build_trial  # noqa: E402


class _Recording(RecordsWindows, PersonPathsIntent):
    """The source in the loop, keeping the windows it was given (to replay them)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--calibration", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=950000)
    parser.add_argument("--profile", action="store_true", help="also print where the person model's tick goes")
    args = parser.parse_args()
    print(machine_line())
    preset = get_preset("thesis-application-damped")
    profile = operator_profile(1)
    calibration = []
    for k in range(args.calibration):
        seed = args.seed + 1000 + k
        probe = make_controller("manual-probe", preset)
        episode = build_trial(
            task_for_seed("curved", seed, obstacle="large"),
            profile,
            get_object("handle"),
            probe,
            None,
            seed,
            preset_name=preset.name,
        )
        calibration.append(run_episode(episode))
    t0 = time.process_time()
    fit = fit_person(calibration)
    print(
        f"fitted from {len(calibration)} probe trials in {time.process_time() - t0:.1f} CPU-s: "
        f"K̂ {fit.arm.stiffness:.0f} N/m, Ĉ {fit.arm.damping:.1f} N·s/m (operator: K {profile.stiffness_min:.0f}–{profile.stiffness_max:.0f}, "
        f"C {profile.damping:.1f}), {len(fit.paths.sides)} demonstrations"
    )
    name = profile.name
    settings = PERSON_FILTER

    def person(s: PersonFilterSettings) -> PersonPathsIntent:
        return PersonPathsIntent(50, paths={name: fit.paths}, arms={name: fit.arm}, settings=s)

    recorder = _Recording(50, paths={name: fit.paths}, arms={name: fit.arm}, settings=settings)
    task = task_for_seed("curved", args.seed, obstacle="large")
    trial = run_episode(
        build_trial(
            task,
            profile,
            get_object("board"),
            make_controller("cooperative-arbitrated", preset),
            recorder,
            args.seed,
            preset_name=preset.name,
        )
    )
    print(f"one trial: {len(recorder.windows)} ticks, side {trial.meta.extra['intent_side']:+d}")
    rows = [
        ("present (arm assumed, no paths)", PersonPathsIntent(50, model_id="present")),
        ("person model", person(settings)),
        ("person model, ±20 cm of every curve (naive)", person(replace(settings, search_window=0.2))),
    ]
    results = {
        label: np.concatenate(
            [replay(src, recorder.context, recorder.windows, time.thread_time_ns) for _ in range(args.repeats)]
        )
        for label, src in rows
    }
    if args.profile:
        import cProfile
        import pstats

        profiler = cProfile.Profile()
        profiler.runcall(replay, rows[1][1], recorder.context, recorder.windows, time.thread_time_ns)
        pstats.Stats(profiler).sort_stats("tottime").print_stats(12)
    naive = np.median(results[rows[2][0]])
    print(
        f"{'per tick':48s} {'median µs':>10s} {'p99 µs':>8s} {'vs naive':>9s} {'of 8 ms':>8s} {'of 2 ms':>8s} "
        f"{'of 1 ms':>8s}"
    )
    for label, t in results.items():
        med, p99 = np.median(t), np.percentile(t, 99)
        print(
            f"{label:48s} {med:10.0f} {p99:8.0f} {med / naive:8.2f}x {100 * p99 / 8000:7.1f}% "
            f"{100 * p99 / 2000:7.1f}% {100 * p99 / 1000:7.1f}%"
        )


if __name__ == "__main__":
    main()
