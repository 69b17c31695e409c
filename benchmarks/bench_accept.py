"""The per-run sources' answers checked together on the array path (issue 44): ``accept_together`` against each
stage's own ``accept``.

    .venv/bin/python benchmarks/bench_accept.py [--runs 8,24] [--ticks 2000] [--repeats 7]

On the point-mass array path every run whose intent source is its own (the person model, the path hypotheses: a
filter with a trial's state) is asked one at a time; its answer (50 rows of x-y) is then checked before the
controller takes it (:meth:`~coassist.runtime.intent.WindowIntent.accept`: enough rows, each near the tool and at a
hand's speed). ``together`` checks one tick's answers of every such run in one set of array operations
(:func:`~coassist.runtime.intent.accept_together`), ``alone`` (the naive baseline, the code before) each by its own
stage. Both must give the same rows and flags (the benchmark stops otherwise). Prints the CPU time a tick of the
group, median and p99 over the repeats [µs], and the ratio of the medians. One BLAS thread.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import machine_line  # noqa: E402
from coassist.interfaces import TrialContext  # noqa: E402
from coassist.runtime.intent import WindowIntent, accept_together  # noqa: E402

HORIZON = 50  # the application's rows (the arbitrated controller's horizon)


class _Rows:
    """A source like the person model's: 50 rows from the tool on, 1 mm apart (a hand's pace at 125 Hz)."""

    model_id = "bench"
    history = 1
    horizon = HORIZON

    def reset(self, context: TrialContext) -> None:
        pass

    def predict(self, window: np.ndarray) -> np.ndarray:
        return window[-1, :2] + 0.001 * np.arange(1, HORIZON + 1)[:, None]


def _stages(n: int, seed: int) -> tuple[list[WindowIntent], list]:
    context = TrialContext(
        dt=0.008, horizon=HORIZON, start=np.zeros(2), target=np.ones(2), reference=np.zeros((10, 4)), task="t",
        user="u", object="o",
    )  # fmt: skip
    stages = [WindowIntent(_Rows(), HORIZON) for _ in range(n)]
    rng = np.random.default_rng(seed)
    answers = []
    for stage in stages:
        stage.reset(context)
        answers.append(stage.answer(0, tuple(rng.normal(0.0, 0.01, 8))))
    return stages, answers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", default="8,24", help="runs of a lockstep group with a source each (comma-separated)")
    parser.add_argument("--ticks", type=int, default=2000, help="ticks a repeat")
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    runs = [int(r) for r in args.runs.split(",")]
    if any(r < 1 for r in runs) or args.ticks < 1 or args.repeats < 1:
        parser.error("--runs, --ticks and --repeats must be >= 1")
    print(machine_line())
    for n in runs:
        stages, answers = _stages(n, n)
        alone = [stage.accept(a) for stage, a in zip(stages, answers)]
        together = accept_together(stages, answers)
        if any(a[1] != t[1] or a[0].tobytes() != t[0].tobytes() for a, t in zip(alone, together)):
            raise SystemExit("accept_together differs from each stage's accept")
        times: dict[str, list[float]] = {"alone": [], "together": []}
        for _ in range(args.repeats):  # the two alternated, so a slower minute of a shared machine falls on both
            t0 = time.process_time()
            for _ in range(args.ticks):
                for stage, a in zip(stages, answers):
                    stage.accept(a)
            times["alone"].append((time.process_time() - t0) / args.ticks)
            t0 = time.process_time()
            for _ in range(args.ticks):
                accept_together(stages, answers)
            times["together"].append((time.process_time() - t0) / args.ticks)
        med = {k: float(np.median(v)) for k, v in times.items()}
        for k, v in times.items():
            print(
                f"{n:3d} runs, {k:8s}: median {1e6 * med[k]:7.1f} µs, p99 {1e6 * np.percentile(v, 99):7.1f} µs a tick"
            )
        print(f"{n:3d} runs: together {med['alone'] / med['together']:.2f} × less CPU a tick than alone")


if __name__ == "__main__":
    main()
