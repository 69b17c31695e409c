"""Which way round the person model's rows followed, replayed from a comparison's own trials (issue 40).

    .venv/bin/python benchmarks/way_decisions.py RUN [RUN ...]

RUN is a ``coassist compare-intents --source person=person`` output folder. For every person-model trial
there (each base, object and population), the trial's recorded feature rows are replayed through the
person model of the calibration draw that ran it (``models/person*-draws/draw-k``, the trial of seed s
runs draw s mod n); the replayed rows must equal the recorded prediction (checked, or the script stops).
Per tick it reads the way the rows follow (``PersonPathsIntent.side``: +1 left, −1 right, 0 undecided) and
compares it with the way the person took (the trial's detour side, as the application's metrics read it).

Prints per RUN, and pooled over all RUNs when there are several: the trials, those whose rows ever followed the way the person did not take and the ticks
they did, and how many ticks after the intent first left the plan by 5 mm the right way was followed
(median, 10th and 90th percentile; negative: before, from the prior or an early offset). This reads the
simulated intent: a measure of the filter in simulation, not something an arm can compute.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from coassist.data.datasets import read_dataset  # noqa: E402
from coassist.experiments.application import application_metrics, pair_key  # noqa: E402
from coassist.interfaces import TrialContext  # noqa: E402
from coassist.scenario.path_model import PathFrame  # noqa: E402
from coassist.scenario.person_model import read_person_model  # noqa: E402

#: The intent's offset from the plan [m] that counts as having left it.
LEFT_PLAN = 0.005


def _context(trial) -> TrialContext:
    """What the source was told for this trial: the plan (the reference's distinct points), the person, the object."""
    ref = np.asarray(trial.reference, dtype=float)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1) > 1e-9])
    return TrialContext(
        dt=trial.meta.dt,
        horizon=trial.horizon,
        start=trial.pose[0, :2].copy(),
        target=np.asarray(trial.meta.extra["target"], dtype=float),
        reference=ref,
        task=trial.meta.task,
        user=trial.meta.user,
        object=trial.meta.object,
        path=ref[keep, :2],
        seed=trial.meta.seed,
    )


def replay_ways(source, trial) -> tuple[np.ndarray, np.ndarray]:
    """The way the rows followed and the intent's offset from the plan [m], per tick: (sides (T,), offsets (T,))."""
    context = _context(trial)
    source.reset(context)
    rows = np.hstack([trial.pose[:, :2], trial.velocity[:, :2], trial.wrench[:, :2], trial.reference[:, :2]])
    recorded = np.asarray(trial.prediction)
    sides = np.zeros(len(rows), dtype=int)
    for k in range(len(rows)):
        out = source.predict(rows[: k + 1])
        if not np.allclose(out.reshape(recorded[k].shape), recorded[k], rtol=0.0, atol=1e-9):
            raise SystemExit(f"trial {trial.meta.seed}: the replay's rows differ from the recorded ones at tick {k}")
        sides[k] = source.side
    _, offsets = PathFrame(context.path).project(np.asarray(trial.intent[:, :2], dtype=float))
    return sides, np.asarray(offsets)


class _Tally:
    """Trials, those whose rows ever followed the way not taken, those ticks, and each trial's latency [ticks]."""

    def __init__(self) -> None:
        self.trials = self.wrong = self.wrong_ticks = 0
        self.latency: list[int] = []

    def add(self, sides: np.ndarray, offsets: np.ndarray, side: int) -> None:
        self.trials += 1
        astray = (sides != 0) & (sides != side)
        self.wrong += int(astray.any())
        self.wrong_ticks += int(astray.sum())
        right, left_plan = np.flatnonzero(sides == side), np.flatnonzero(np.abs(offsets) > LEFT_PLAN)
        if len(right) and len(left_plan):
            self.latency.append(int(right[0] - left_plan[0]))

    def merge(self, other: _Tally) -> None:
        self.trials += other.trials
        self.wrong += other.wrong
        self.wrong_ticks += other.wrong_ticks
        self.latency += other.latency

    def __str__(self) -> str:
        lat = np.asarray(self.latency)
        return (
            f"{self.trials} trials; the rows followed the way not taken in {self.wrong} ({self.wrong_ticks} ticks); "
            f"the right way followed {np.median(lat):.0f} ticks after the intent left the plan by "
            f"{1e3 * LEFT_PLAN:.0f} mm (p10 {np.percentile(lat, 10):.0f}, p90 {np.percentile(lat, 90):.0f}; "
            f"{len(lat)} trials)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    args = parser.parse_args()
    pooled = _Tally()
    for run in args.runs:
        tally = _Tally()
        for folder in sorted(run.glob("base-*/datasets/*-person*")):
            if "draw" in folder.name or "probe" in folder.name:
                continue
            base = folder.parent.parent
            suffix = folder.name.split("-person", 1)[1]  # "" or "-varied"
            draws = sorted((base / "models" / f"person{suffix}-draws").glob("draw-*"))
            if not draws:
                raise SystemExit(f"{folder}: no calibration draws at {base / 'models' / f'person{suffix}-draws'}")
            sources = [read_person_model(d) for d in draws]
            recorded = sorted(read_dataset(folder).trials, key=pair_key)
            took = np.sign(np.asarray(application_metrics(recorded)["side"], dtype=float)).astype(int)
            for trial, side in zip(recorded, took, strict=True):
                tally.add(*replay_ways(sources[trial.meta.seed % len(sources)], trial), side)
        if not tally.trials:
            raise SystemExit(f"{run}: no person-model trials (a compare-intents folder with --source person=person?)")
        print(f"{run}: {tally}")
        pooled.merge(tally)
    if len(args.runs) > 1:
        print(f"all {len(args.runs)}: {pooled}")


if __name__ == "__main__":
    main()
