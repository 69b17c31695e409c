"""The path-hypotheses source's work per control tick, against a naive search, and the deadline.

    .venv/bin/python benchmarks/bench_paths.py [--repeats 3] [--seed 950000]

Records the feature rows of one application trial (the board, operator 1, the arbitrated
controller with the ``paths`` source in the loop), then replays them through fresh sources and
times every ``predict`` call:

- ``present``: the present estimate alone (no obstacle);
- ``paths``, its default 5 × 5 shape grid per side (50 curves): each curve searched within
  ±2 cm (``search_window``) of the arc length where the tool was last, one curve standing for
  all where they coincide;
- the naive baseline: the same filter searching the whole of every curve, all 50 curves, on
  every tick (no search window, no shared curve);
- ``paths`` with one shape per side (2 curves).

Prints median and p99 [µs] per tick, the ratio to the naive search, and the share of the control
period it takes at 125 Hz (8 ms) and 500 Hz (2 ms). One BLAS thread.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import RecordsWindows, machine_line, replay  # noqa: E402
from coassist.control.presets import get_preset, make_controller  # noqa: E402
from coassist.runtime.episode import run_episode  # noqa: E402
from coassist.scenario.objects import get_object  # noqa: E402
from coassist.scenario.operator import operator_profile  # noqa: E402
from coassist.scenario.path_hypotheses import FilterSettings, PathHypothesesIntent, PersonShape  # noqa: E402
from coassist.scenario.tasks import task_for_seed  # noqa: E402
from coassist.sim.trial_runner import build_trial  # noqa: E402


class _Recording(RecordsWindows, PathHypothesesIntent):
    """The source in the loop, keeping the windows it was given (to replay them)."""


class _WholeCurves(PathHypothesesIntent):
    """The naive search: every sample of every curve, every tick (a search window longer than any curve;
    ``FilterSettings.search_window`` itself is bounded to what a tick can afford)."""

    shared_fast_path = False

    def _widest(self, hyp):
        return hyp.points.shape[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=950000)
    args = parser.parse_args()
    print(machine_line())
    preset = get_preset("thesis-application-damped")
    task = task_for_seed("curved", args.seed, obstacle="large")
    profile = operator_profile(1)
    shape = PersonShape(profile.clearance, profile.anticipation, profile.left_preference, 4)
    recorder = _Recording(50, default=shape)
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
    naive = _WholeCurves(50, default=shape)
    rows = [
        ("present (no obstacle)", PathHypothesesIntent(50, default=shape, use_obstacles=False)),
        ("paths, 50 curves", PathHypothesesIntent(50, default=shape)),
        ("paths, 50 curves, whole curves every tick (naive)", naive),
        (
            "paths, 2 curves (one shape per side)",
            PathHypothesesIntent(50, default=shape, settings=FilterSettings(shape_grid=(1.0,))),
        ),
    ]
    results = {}
    for label, source in rows:
        results[label] = np.concatenate(
            [replay(source, recorder.context, recorder.windows) for _ in range(args.repeats)]
        )
    naive = np.median(results[rows[2][0]])
    print(f"{'per tick':50s} {'median µs':>10s} {'p99 µs':>8s} {'vs naive':>9s} {'of 8 ms':>8s} {'of 2 ms':>8s}")
    for label, t in results.items():
        med, p99 = np.median(t), np.percentile(t, 99)
        print(
            f"{label:50s} {med:10.0f} {p99:8.0f} {med / naive:8.2f}x {100 * p99 / 8000:7.1f}% {100 * p99 / 2000:7.1f}%"
        )


if __name__ == "__main__":
    main()
