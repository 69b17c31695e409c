"""The person model on the real UR5 recordings: each trial predicted by a model fitted to the same person's other
trials on the same plan (leave one out), against the sources that need no calibration (issue 40).

    .venv/bin/python benchmarks/person_real.py [--data DIR] [--horizons 10,25,50]

The recordings (``../shared/data/ur5-thesis``, or ``$COASSIST_REAL_DATA``) are grouped by person and plan (the
planner's reference: user-a followed three, user-b one). For each trial, a person model is fitted
(:func:`coassist.scenario.person_model.fit_person`, the calibration's own fit) to the person's other trials on that
plan — what a lab has: positions, velocities, wrenches and the plan; no probe was in those loops, so the arm is the
assumed one (K̂ = 800 N/m, Ĉ = 10 N·s/m) — and the held-out trial's feature rows (x, y, ẋ, ẏ, f_x, f_y, x_ref, y_ref:
the control tick's, :mod:`coassist.runtime.tick`) are replayed through it with the filter of the calibration
(:data:`~coassist.scenario.person_model.PERSON_FILTER`) and through the registered sources that need none
(``present``, ``present-held``, ``constant-velocity``, ``nominal``). Each row h ticks ahead is scored against the
tool's recorded position h ticks later: the only label real recordings have (where the person was, under
whatever controller ran then; the sources predict where the person wants the tool, so a source that leads the
tool can score worse here and help more in a loop). So each is scored twice: the positions, and the displacement
along the rows (row h less the first row, against the tool's motion over the same ticks), which leaves out the
offset between the hand's wanted position and the tool and scores the path's shape. e_RMS [mm] over every tick with
h ticks recorded after it, per person and plan, and all trials together; the per-trial spread in brackets (min–max
of the trials' e_RMS). A plan the person followed once is left out (nothing to fit from).

Nothing here is told the scene (the recordings carry none): the person model learns the ways round from the other
trials. What it is scored on: the person's own trials, other than the ones it was fitted to.

``--simulated``: the same scoring on simulated thesis operators 0–2 instead (the control: where the person model is
known to help in the loop): each fitted to eight probe trials (curved task, the large obstacle, seeds 951000 + k),
scored on four MG trials (seeds 950000 + k), 50 ticks ahead.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from coassist.data import default_real_data, load_ros_user  # noqa: E402
from coassist.interfaces import TrialContext  # noqa: E402
from coassist.scenario.intent_registry import load_intent_source  # noqa: E402
from coassist.scenario.person_intent import PersonPathsIntent  # noqa: E402
from coassist.scenario.person_model import PERSON_FILTER, fit_person  # noqa: E402

#: The registered sources that need no calibration, scored beside the person model.
BASELINES = ("present", "present-held", "constant-velocity", "nominal")
HORIZON = 50  # rows a source gives (0.4 s at 125 Hz)


def plan_key(trial) -> tuple:
    """A plan's identity: its reference's start, end and lateral extent, to the millimetre."""
    r = np.asarray(trial.reference[:, :2], dtype=float)
    return tuple(np.round(np.concatenate([r[0], r[-1], r.min(axis=0), r.max(axis=0)]), 3))


def context_of(trial, user: str) -> TrialContext:
    """What a source is told at the start of a recorded trial: the plan (its reference, velocities by difference)."""
    dt = float(trial.meta.dt)
    ref = np.asarray(trial.reference[:, :2], dtype=float)
    vel = np.gradient(ref, dt, axis=0)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(ref, axis=0), axis=1) > 1e-9])
    return TrialContext(
        dt=dt,
        horizon=HORIZON,
        start=ref[0].copy(),
        target=ref[-1].copy(),
        reference=np.hstack([ref, vel]),
        task=str(trial.meta.task),
        user=user,
        object="handle",
        path=ref[keep],
    )


def feature_rows(trial) -> np.ndarray:
    """(T, 8) the control tick's feature rows of a recorded trial."""
    return np.hstack(
        [trial.pose[:, :2], trial.velocity[:, :2], trial.wrench[:, :2], np.asarray(trial.reference[:, :2])]
    ).astype(float)


def replay(source, context: TrialContext, rows: np.ndarray) -> np.ndarray:
    """(T, H, 2) the rows ``source`` gives for each tick's window (history 1, as the person model reads it);
    NaN where it gives none (the nominal source answers None: the plan's own rows are its answer)."""
    source.reset(context)
    out = np.full((len(rows), HORIZON, 2), np.nan)
    ref = np.asarray(context.reference[:, :2])
    hist = int(getattr(source, "history", 1))
    for k in range(len(rows)):
        window = rows[max(0, k - hist + 1) : k + 1]
        if len(window) < hist:  # the first ticks: the first row repeated, as the loop's window starts
            window = np.vstack([np.repeat(window[:1], hist - len(window), axis=0), window])
        got = source.predict(window)
        if got is None:
            got = ref[np.minimum(np.arange(k + 1, k + 1 + HORIZON), len(ref) - 1)]
        got = np.asarray(got, dtype=float)[:HORIZON]
        out[k, : len(got)] = got
    return out


def errors(pred: np.ndarray, pose: np.ndarray, h: int, moved: bool) -> np.ndarray:
    """Each tick k's error [m] of the row h ticks ahead against the recorded position h ticks later, or with
    ``moved`` of the rows' displacement from their first row against the tool's from tick k + 1 (the offset
    between where a source says the hand wants the tool and where the tool is left out: the path's shape)."""
    T = len(pose)
    if not moved:
        return np.linalg.norm(pred[: T - h, h - 1] - pose[h:], axis=1)
    if h < 2:
        raise ValueError("a displacement needs h >= 2")
    got = pred[: T - h, h - 1] - pred[: T - h, 0]
    return np.linalg.norm(got - (pose[h:] - pose[1 : T - h + 1]), axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None, help="the recordings' folder (default: coassist's)")
    ap.add_argument("--horizons", default="10,25,50", help="ticks ahead to score (125 Hz)")
    ap.add_argument("--simulated", action="store_true", help="score simulated thesis operators instead (the control)")
    args = ap.parse_args()
    if args.simulated:
        simulated_control()
        return
    folder = default_real_data() if args.data is None else args.data
    horizons = [int(h) for h in args.horizons.split(",")]
    if any(not 2 <= h <= HORIZON for h in horizons):
        ap.error(f"--horizons must be in 2..{HORIZON} (a displacement along the rows needs two of them)")
    names = ("person model",) + BASELINES
    metrics = ("position", "displacement")
    total = {(m, n, h): [] for m in metrics for n in names for h in horizons}
    for user in ("user-a", "user-b"):
        trials = load_ros_user(folder / user)
        groups: dict[tuple, list] = {}
        for t in trials:
            groups.setdefault(plan_key(t), []).append(t)
        for g, members in enumerate(groups.values()):
            if len(members) < 2:
                print(f"{user}, plan {g + 1}: trial {members[0].meta.extra['recording']} alone on it: left out")
                continue
            label = f"{user}, plan {g + 1} ({len(members)} trials: " + ", ".join(
                t.meta.extra["recording"].removeprefix("trial_") for t in members
            )
            per = {(m, n, h): [] for m in metrics for n in names for h in horizons}
            per_trial = {(m, n, h): [] for m in metrics for n in names for h in horizons}
            for i, trial in enumerate(members):
                others = [t for j, t in enumerate(members) if j != i]
                fit = fit_person(others)
                sources = {
                    "person model": PersonPathsIntent(
                        HORIZON, paths={user: fit.paths}, arms={user: fit.arm}, settings=PERSON_FILTER
                    )
                }
                sources.update({n: load_intent_source(n, HORIZON) for n in BASELINES})
                rows, context = feature_rows(trial), context_of(trial, user)
                pose = trial.pose[:, :2]
                for n, src in sources.items():
                    pred = replay(src, context, rows)
                    for m in metrics:
                        for h in horizons:
                            e = errors(pred, pose, h, m == "displacement")
                            per[m, n, h].append(e)
                            total[m, n, h].append(e)
                            per_trial[m, n, h].append(math.sqrt(float(np.mean(e**2))))
            print(label + f"; the person model fitted to {len(members) - 1} of them, leave one out)")
            for m in metrics:
                print(f"  {m} (e_RMS mm at " + ", ".join(f"{h} ticks" for h in horizons) + ")")
                for n in names:
                    cells = []
                    for h in horizons:
                        e = np.concatenate(per[m, n, h])
                        lo, hi = min(per_trial[m, n, h]), max(per_trial[m, n, h])
                        cells.append(f"{1e3 * math.sqrt(float(np.mean(e**2))):6.2f} [{1e3 * lo:.2f}–{1e3 * hi:.2f}]")
                    print(f"    {n:18s} " + "  ".join(cells))
    for m in metrics:
        print(f"all trials, {m} (e_RMS mm at " + ", ".join(f"{h} ticks" for h in horizons) + ")")
        for n in names:
            cells = [f"{1e3 * math.sqrt(float(np.mean(np.concatenate(total[m, n, h]) ** 2))):6.2f}" for h in horizons]
            print(f"  {n:18s} " + "  ".join(cells))


def simulated_control() -> None:
    """The same scoring on simulated thesis operators under MG (module docstring, ``--simulated``)."""
    from bench_common import curved_trial
    from coassist.scenario.populations import population_profile

    h = HORIZON
    print(f"simulated thesis operators under MG, e_RMS mm at {h} ticks: position / displacement")
    for user in (0, 1, 2):
        profile = population_profile("thesis", user, 0)
        fit = fit_person([curved_trial(profile, 951000 + k, "manual-probe") for k in range(8)])
        tests = [curved_trial(profile, 950000 + k, "manual") for k in range(4)]
        out = {}
        for t in tests:
            name = str(t.meta.user)
            sources = {
                "person model": PersonPathsIntent(
                    HORIZON, paths={name: fit.paths}, arms={name: fit.arm}, settings=PERSON_FILTER
                )
            }
            sources.update({n: load_intent_source(n, HORIZON) for n in BASELINES})
            rows, context = feature_rows(t), context_of(t, name)
            for n, src in sources.items():
                pred = replay(src, context, rows)
                for moved in (False, True):
                    out.setdefault((n, moved), []).append(errors(pred, t.pose[:, :2], h, moved))
        cells = [
            f"{n} {1e3 * math.sqrt(float(np.mean(np.concatenate(out[n, False]) ** 2))):.1f} / "
            f"{1e3 * math.sqrt(float(np.mean(np.concatenate(out[n, True]) ** 2))):.1f}"
            for n in ("person model",) + BASELINES
        ]
        print(f"  user {user}: " + "; ".join(cells))


if __name__ == "__main__":
    main()
