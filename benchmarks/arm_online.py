"""Would tracking the person's arm online pay? The present estimate with the fitted K̂ against the simulator's own K(t).

    .venv/bin/python benchmarks/arm_online.py RUN CELL:DRAWS [CELL:DRAWS ...]

RUN is a finished ``coassist reproduce --out`` folder; each CELL is one of its person-model datasets
(``RUN/datasets/CELL``, e.g. ``held-out-board-person``) and DRAWS the calibration-draws folder its trials ran
(``RUN/models/DRAWS``, e.g. ``person-held-out-draws``; the trial of seed s ran draw s mod n).

Issue 40 item 3 asks for the arm "tracked online if that pays". The simulated arm stiffens as its tracking
error grows (:class:`coassist.scenario.operator.OperatorArm`: K(t) = K_min + κ ē(t), ē the error low-passed
over the adaptation time, up to K_max), while the present estimate divides the hand force by one K̂, fitted
from the calibration's probe trials::

    q(k) = p(k) + (u_h(k) + Ĉ v(k)) / K + τ_lead v(k)          (the person model's present estimate)

Per trial this replays the recorded feature rows exactly as :class:`~coassist.scenario.person_intent.
PersonPathsIntent` does (the hand force with the object's inertia put back, the board's hand point), and forms
q twice: with the person's K̂ (what runs) and with the simulator's K(t) recomputed from the recorded intent and
hand point (an upper bound on what any online tracker of K could give; Ĉ and τ_lead as fitted). It prints, per
operator, K̂, the percentiles of K(t), and the RMS of each estimate's error across the plan (its offset from the
plan less the true intent's) with the share of ticks beyond 2 mm (the dead zone's floor).

This reads the simulator's truth (the operator's profile in the trial's metadata, the intent): a measure of the
model class in simulation, nothing an arm can compute.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from coassist.data.datasets import read_dataset  # noqa: E402
from coassist.scenario.hand_force import HandForce, HandPoint  # noqa: E402
from coassist.scenario.path_model import PathFrame  # noqa: E402
from coassist.scenario.person_model import read_person_model  # noqa: E402

#: The dead zone's floor [m] (PersonFilterSettings.dead_zone): errors beyond it count as evidence for a way.
BEYOND = 0.002


def replay(trial, source) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """K̂, K(t) (T,), and the errors across the plan [m] (T,) of q with K̂ and with K(t)."""
    st = source.settings
    arm = source.arms.get(trial.meta.user, source.default_arm)
    K_hat, C_hat, lead = arm.stiffness, arm.damping, st.reaction_lead
    op = trial.meta.extra["operator"]
    dt = trial.meta.dt
    hand = HandForce(dt, st.accel_time, trial.meta.object)
    point = HandPoint(dt, trial.meta.object) if st.object_yaw else None
    P, V, W = (np.asarray(a[:, :2], dtype=float) for a in (trial.pose, trial.velocity, trial.wrench))
    intent = np.asarray(trial.intent[:, :2], dtype=float)
    ref = np.asarray(trial.reference[:, :2], dtype=float)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(ref, axis=0), axis=1) > 1e-9])
    frame = PathFrame(ref[keep])
    n = len(P)
    q_fit, q_true, K_t = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros(n)
    ebar, alpha = 0.0, dt / op["adaptation_time"]
    for k in range(n):
        (px, py), (vx, vy), (wx, wy) = P[k].tolist(), V[k].tolist(), W[k].tolist()
        ux, uy = hand.step(vx, vy, wx, wy)
        if point is not None:
            ax, ay = hand.acceleration
            dpx, dpy, dvx, dvy = point.step(ux, uy, ax, ay)
            px, py, vx, vy = px + dpx, py + dpy, vx + dvx, vy + dvy
        # the operator's own rule (OperatorArm.force), on the hand point the filter reads
        ebar += alpha * (math.hypot(intent[k, 0] - px, intent[k, 1] - py) - ebar)
        K = min(op["stiffness_min"] + op["stiffness_gain"] * ebar, op["stiffness_max"])
        K_t[k] = K
        q_fit[k] = (px + (ux + C_hat * vx) / K_hat + lead * vx, py + (uy + C_hat * vy) / K_hat + lead * vy)
        q_true[k] = (px + (ux + C_hat * vx) / K + lead * vx, py + (uy + C_hat * vy) / K + lead * vy)
    _, across_intent = frame.project(intent)
    _, across_fit = frame.project(q_fit)
    _, across_true = frame.project(q_true)
    across_intent = np.asarray(across_intent)
    return K_hat, K_t, np.asarray(across_fit) - across_intent, np.asarray(across_true) - across_intent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("cells", nargs="+", help="CELL:DRAWS, e.g. held-out-board-person:person-held-out-draws")
    args = parser.parse_args()
    for item in args.cells:
        cell, sep, draws_name = item.partition(":")
        if not sep:
            raise SystemExit(f"{item!r}: expected CELL:DRAWS")
        draws = sorted((args.run / "models" / draws_name).glob("draw-*"))
        if not draws:
            raise SystemExit(f"no calibration draws at {args.run / 'models' / draws_name}")
        sources = [read_person_model(d) for d in draws]
        people: dict[str, list] = {}
        for trial in read_dataset(args.run / "datasets" / cell).trials:
            people.setdefault(trial.meta.user, []).append(replay(trial, sources[trial.meta.seed % len(sources)]))
        print(cell)
        for user, rows in sorted(people.items()):
            K_hat = [r[0] for r in rows]
            K_t = np.concatenate([r[1] for r in rows])
            fit, true = (np.concatenate([r[i] for r in rows]) for i in (2, 3))

            def said(e: np.ndarray) -> str:
                return f"{1e3 * np.sqrt(np.mean(e * e)):.2f} mm RMS ({100 * np.mean(np.abs(e) > BEYOND):.0f} % > 2 mm)"

            p10, p50, p90 = np.percentile(K_t, [10, 50, 90])
            print(
                f"  {user} ({len(rows)} trials): K^ {min(K_hat):.0f}-{max(K_hat):.0f} N/m, K(t) p10/50/90 "
                f"{p10:.0f}/{p50:.0f}/{p90:.0f}; error across the plan: K^ {said(fit)}, K(t) {said(true)}"
            )


if __name__ == "__main__":
    main()
