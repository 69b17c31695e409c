"""Performance indexes of thesis §5.2.4 (e_RMS, e_MAX, f_RMS, σ) and of smoothness and stability.

Smoothness and stability (beyond the thesis, issue #11): :func:`jerk_rms` of the tool
path, :func:`overshoot` of the tool past the operator's intent at each of its turns,
:func:`tracking_error_rms` of the tool against that intent, and
:func:`peak_effort_ratio` of the robot's peak effort to the hand's. Around an obstacle
(issue 34): :func:`clearance` of a path from a box, and :func:`clearance_deficit`, how much
closer the tool passes than the operator meant to.

Pure functions on arrays (SI units). Conventions, where the thesis is loose
(docs/architecture.md, *Conventions for the math*):

- ``prediction[k, i - 1]`` is the position predicted at tick ``k`` for tick ``k + i``,
  ``i = 1 … H`` (the layout of :attr:`coassist.data.Trial.prediction`). The prediction
  errors compare it with the *measured* pose ``pose[k + i]``.
- A horizon of N samples uses the N steps k+1 … k+N. Eq. 5.6 sums K = T … T+N (N+1
  terms) but divides by N; we use N terms divided by N.
- Only ticks k with k + N < T are scored (their whole horizon has been measured).
  Ticks whose prediction over those N steps is not finite (NaN = "no prediction in use
  at that tick", e.g. before the predictor's history window is full) are skipped;
  :func:`prediction_errors` returns the ticks it scored.
- Horizons are reported at 0.04, 0.08, 0.16 and 0.4 s, i.e. :data:`HORIZONS` =
  (5, 10, 20, 50) samples at dt = 0.008 s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike

from coassist._checks import check_positive_scalar, is_integer

__all__ = [
    "HORIZONS",
    "EMax",
    "PredictionErrors",
    "clearance",
    "clearance_deficit",
    "distance_to_target",
    "e_max",
    "e_rms",
    "f_rms",
    "jerk_rms",
    "overshoot",
    "peak_effort_ratio",
    "precision_sigma",
    "tracking_error_rms",
    "prediction_errors",
    "prediction_errors_by_horizon",
    "time_to_target",
]

#: Prediction horizons of the thesis' evaluation, in samples (0.04, 0.08, 0.16, 0.4 s).
HORIZONS: tuple[int, ...] = (5, 10, 20, 50)


class PredictionErrors(NamedTuple):
    """Per-tick prediction errors for one horizon N.

    Attributes
    ----------
    tick : ndarray of int, shape (L,)
        The ticks k scored (k + N < T, finite prediction).
    rms : ndarray, shape (L,)
        sqrt(mean_{i=1..N} ||x̂_k(k+i) − x(k+i)||²), in m: the inner term of eq. 5.6.
    max : ndarray, shape (L,)
        max_{i=1..N} ||x̂_k(k+i) − x(k+i)||, in m: e_MAX,i of eq. 5.7.
    """

    tick: np.ndarray
    rms: np.ndarray
    max: np.ndarray


class EMax(NamedTuple):
    """e_MAX for one horizon (eq. 5.7–5.8), in m: mean and max over the trajectory."""

    mean: float
    max: float


# --------------------------------------------------------------------------- validation


def _as_positions(value: ArrayLike, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 1:
        # A 1-D array is one DOF over time.
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name} must have shape (T, d), got {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite values")
    return arr


def _as_prediction(prediction: ArrayLike, pose: np.ndarray) -> np.ndarray:
    pred = np.asarray(prediction, dtype=np.float64)
    t, d = pose.shape
    if pred.ndim == 2 and d == 1:
        pred = pred[:, :, None]
    if pred.ndim != 3 or pred.shape[0] != t or pred.shape[2] != d or pred.shape[1] < 1:
        raise ValueError(
            f"prediction has shape {np.shape(prediction)}, expected ({t}, H, {d}) to match pose {pose.shape}"
        )
    if np.any(np.isinf(pred)):
        raise ValueError("prediction has infinite values")
    return pred


def _check_horizon(horizon: int, available: int) -> int:
    if not is_integer(horizon):
        raise ValueError(f"horizon must be an integer number of samples, got {horizon!r}")
    if not 1 <= horizon <= available:
        raise ValueError(f"horizon must be between 1 and the prediction's H = {available}, got {horizon}")
    return int(horizon)


# --------------------------------------------------------------------------- prediction errors


def prediction_errors(prediction: ArrayLike, pose: ArrayLike, horizon: int) -> PredictionErrors:
    """Per-tick RMS and max prediction error over the first ``horizon`` steps.

    For each scored tick k::

        e_k,i = ||x̂_k(k+i) − x(k+i)||,  i = 1 … N
        rms_k = sqrt( (1/N) Σ_i e_k,i² )        (inner term of eq. 5.6)
        max_k = max_i e_k,i                      (eq. 5.7)

    Parameters
    ----------
    prediction : array_like, shape (T, H, d)
        ``prediction[k, i-1]`` = position predicted at tick k for tick k+i, in m.
        (T, H) is accepted when d = 1.
    pose : array_like, shape (T, d)
        Measured positions, in m. (T,) is accepted when d = 1.
    horizon : int
        N, in samples, 1 ≤ N ≤ H.

    Returns
    -------
    PredictionErrors
        ``tick``, ``rms``, ``max``, each of shape (L,), L the number of scored ticks:
        those with k + N < T and a finite prediction over steps 1 … N.

    Raises
    ------
    ValueError
        On bad shapes, non-finite poses, or when no tick can be scored (T ≤ N, or
        every prediction is NaN).
    """
    return prediction_errors_by_horizon(prediction, pose, (horizon,))[int(horizon)]


def prediction_errors_by_horizon(
    prediction: ArrayLike, pose: ArrayLike, horizons: Sequence[int]
) -> dict[int, PredictionErrors]:
    """:func:`prediction_errors` for several horizons of one trajectory: the prediction converted and checked
    once, each step's squared error computed once (for the longest horizon); each horizon's result is the one
    it gets alone, bit for bit (its rows and columns of the same squared errors).

    Returns horizon → :class:`PredictionErrors`; raises what :func:`prediction_errors` raises for the first
    horizon that cannot be scored (in the order given)."""
    pose_arr = _as_positions(pose, "pose")
    pred = _as_prediction(prediction, pose_arr)
    hs = [_check_horizon(h, pred.shape[1]) for h in horizons]
    if not hs:
        return {}
    t, d = pose_arr.shape
    for n in hs:
        if t <= n:
            raise ValueError(f"trajectory of {t} samples is too short for a horizon of {n} samples (needs T > N)")
    longest = max(hs)
    # future[k, i-1] = pose[k+i] for k = 0 … T-2, NaN past the end: each horizon N reads rows k < T-N of its
    # first N columns, which never reach the padding, so each element is prediction_errors' own.
    padded = np.concatenate((pose_arr[1:], np.full((longest - 1, d), np.nan)))
    future = np.moveaxis(sliding_window_view(padded, longest, axis=0), -1, 1)  # (T-1, longest, d)
    err = pred[: t - 1, :longest, :] - future
    sq_all = np.sum(err * err, axis=2)  # (T-1, longest)
    out: dict[int, PredictionErrors] = {}
    for n in hs:
        sq = sq_all[: t - n, :n]
        ok = np.all(np.isfinite(sq), axis=1)
        if not np.any(ok):
            raise ValueError(f"no tick has a finite prediction over the first {n} steps")
        sq = sq[ok]
        out[n] = PredictionErrors(
            tick=np.flatnonzero(ok), rms=np.sqrt(np.mean(sq, axis=1)), max=np.sqrt(np.max(sq, axis=1))
        )
    return out


def e_rms(prediction: ArrayLike, pose: ArrayLike, horizon: int) -> float:
    """e_RMS for one horizon (eq. 5.6), in m.

    ::

        e_RMS = (1/L) Σ_k sqrt( (1/N) Σ_{i=1..N} ||x̂_k(k+i) − x(k+i)||² )

    over the L scored ticks (see :func:`prediction_errors` for shapes and which ticks
    are scored).
    """
    return float(np.mean(prediction_errors(prediction, pose, horizon).rms))


def e_max(prediction: ArrayLike, pose: ArrayLike, horizon: int) -> EMax:
    """e_MAX for one horizon (eq. 5.7–5.8), in m.

    First the per-tick maximum over the horizon, e_MAX,k = max_{i=1..N}
    ||x̂_k(k+i) − x(k+i)|| (eq. 5.7). The thesis then disagrees with itself: its text
    takes "the maximum from all the values obtained before", its eq. 5.8 takes the
    *sum* over the trajectory — which grows with the trajectory's length and so cannot
    compare trials. We report both readings that are comparable (docs/architecture.md,
    *Conventions for the math*):

    - ``mean``: the mean of e_MAX,k over the scored ticks (the sum of eq. 5.8 divided
      by L);
    - ``max``: the maximum of e_MAX,k over the scored ticks (the text's reading).
    """
    per_tick = prediction_errors(prediction, pose, horizon).max
    return EMax(mean=float(np.mean(per_tick)), max=float(np.max(per_tick)))


# --------------------------------------------------------------------------- force


def f_rms(wrench: ArrayLike, *, axes: Sequence[int] | None = None) -> float:
    """f_RMS (eq. 5.9), in N: the mean over time of the interaction-force norm.

    ::

        f_RMS = (1/T) Σ_k sqrt( f_x(k)² + f_y(k)² )

    Eq. 5.9 writes only the norm sqrt(f_x² + f_y²) and says the index is a mean value;
    despite its name it is a mean norm, not a root mean square (docs/architecture.md,
    *Conventions for the math*). The thesis then averages it over three trials: do that
    over the returned values.

    Parameters
    ----------
    wrench : array_like, shape (T, d)
        Measured interaction force, in N; (T,) for one axis.
    axes : sequence of int, optional
        Columns that enter the norm; default all of them. Pass ``axes=(0, 1)`` for the
        planar force of a wrench that also holds z.
    """
    arr = _as_positions(wrench, "wrench")
    if axes is not None:
        cols = [int(a) for a in axes]
        if not cols or any(not 0 <= a < arr.shape[1] for a in cols) or len(set(cols)) != len(cols):
            raise ValueError(f"axes must be distinct column indexes in [0, {arr.shape[1]}), got {tuple(axes)}")
        arr = arr[:, cols]
    return float(np.mean(np.linalg.norm(arr, axis=1)))


# --------------------------------------------------------------------------- target precision


def distance_to_target(pose: ArrayLike, target: ArrayLike) -> np.ndarray:
    """σ_i = ||x_current − x_final|| for every tick (eq. 5.10), in m.

    Parameters
    ----------
    pose : array_like, shape (T, d)
    target : array_like, shape (d,)

    Returns
    -------
    ndarray, shape (T,)
    """
    pose_arr = _as_positions(pose, "pose")
    tgt = np.asarray(target, dtype=np.float64).reshape(-1)
    if tgt.shape != (pose_arr.shape[1],):
        raise ValueError(f"target has shape {np.shape(target)}, expected ({pose_arr.shape[1]},) to match pose")
    if not np.all(np.isfinite(tgt)):
        raise ValueError("target has non-finite values")
    return np.linalg.norm(pose_arr - tgt, axis=1)


def _first_entry(dist: np.ndarray, epsilon: float) -> int | None:
    inside = np.flatnonzero(dist <= epsilon)
    return int(inside[0]) if inside.size else None


def time_to_target(pose: ArrayLike, target: ArrayLike, dt: float, *, epsilon: float = 0.025) -> float:
    """Time in s at which the pose first enters the closed ball of radius ``epsilon``
    metres around ``target`` (tick index × dt); NaN if it never does."""
    dt = check_positive_scalar(dt, "dt")
    epsilon = check_positive_scalar(epsilon, "epsilon")
    k0 = _first_entry(distance_to_target(pose, target), epsilon)
    return math.nan if k0 is None else k0 * dt


def precision_sigma(
    pose: ArrayLike,
    target: ArrayLike,
    dt: float,
    *,
    epsilon: float = 0.025,
    tau: float = 3.0,
) -> float:
    """Target precision σ (eq. 5.10–5.11), in m.

    ::

        σ_i = ||x(i) − x_final||                          (eq. 5.10)
        σ   = (1/n) Σ_{i=k0}^{k0+n−1} σ_i,  n = round(τ/dt) (eq. 5.11)

    where k0 is the first tick with σ_i ≤ ε, i.e. the pose first enters the closed
    ball of radius ε around the target, and the n ticks cover [t_k0, t_k0 + τ).

    - ε is in **metres** (default 0.025 m = 2.5 cm). The thesis writes "0.025cm",
      which read literally (0.25 mm) is below the robot's tracking noise;
      docs/architecture.md (*Conventions for the math*) fixes metres.
    - If the pose never enters the ball, σ is undefined: returns NaN (count such
      trials separately, e.g. with :func:`time_to_target`).
    - If fewer than n ticks remain after k0 (the trial ends less than τ after
      reaching the target), σ is the mean over the ticks that remain.

    Parameters
    ----------
    pose : array_like, shape (T, d)
        Positions in m.
    target : array_like, shape (d,)
        Target point x_final in m.
    dt : float
        Sampling period in s.
    epsilon : float
        Radius of the ball, in m.
    tau : float
        Averaging window, in s (thesis: 3 s).
    """
    dt = check_positive_scalar(dt, "dt")
    epsilon = check_positive_scalar(epsilon, "epsilon")
    tau = check_positive_scalar(tau, "tau")
    dist = distance_to_target(pose, target)
    k0 = _first_entry(dist, epsilon)
    if k0 is None:
        return math.nan
    n = max(1, int(round(tau / dt)))
    return float(np.mean(dist[k0 : k0 + n]))


# --------------------------------------------------------------------------- smoothness and stability


def jerk_rms(pose: ArrayLike, dt: float) -> float:
    """RMS of the tool's jerk, in m/s³, from third differences of the positions::

        j(k) = (x(k+3) − 3 x(k+2) + 3 x(k+1) − x(k)) / dt³,   k = 0 … T−4
        jerk_RMS = sqrt( (1/(T−3)) Σ_k ||j(k)||² )

    Exact for a cubic path (x = c t³ gives j = 6c). A wiggling tool has a larger jerk
    than a smooth one along the same path.

    Parameters
    ----------
    pose : array_like, shape (T, d), T ≥ 4; positions in m.
    dt : sampling period in s.
    """
    dt = check_positive_scalar(dt, "dt")
    x = _as_positions(pose, "pose")
    if x.shape[0] < 4:
        raise ValueError(f"pose needs at least 4 samples for a third difference, got {x.shape[0]}")
    j = np.diff(x, n=3, axis=0) / dt**3
    return float(np.sqrt(np.mean(np.sum(j * j, axis=1))))


def tracking_error_rms(pose: ArrayLike, intent: ArrayLike) -> float:
    """sqrt( (1/T) Σ_k ||x(k) − x_ref,h(k)||² ), in m: how far the tool is from where the operator wants it."""
    x = _as_positions(pose, "pose")
    ref = _as_positions(intent, "intent")
    if ref.shape != x.shape:
        raise ValueError(f"intent has shape {ref.shape}, expected {x.shape} to match pose")
    return float(np.sqrt(np.mean(np.sum((x - ref) ** 2, axis=1))))


def _turning_points(x: np.ndarray, tol: float) -> list[tuple[int, int]]:
    """(index, direction) of the extrema of a 1-D signal that it leaves by more than ``tol``.

    A "zigzag" with hysteresis: an extremum counts once the signal has retreated from it
    by more than tol; the last extremum (where the signal ends up) counts too. direction
    is +1 for a maximum (the signal was rising into it), −1 for a minimum.
    """
    turns: list[tuple[int, int]] = []
    direction = 0
    ext_i = 0
    for k in range(1, x.shape[0]):
        if direction == 0:
            if abs(x[k] - x[0]) > tol:
                direction = 1 if x[k] > x[0] else -1
                ext_i = k
            continue
        if direction * (x[k] - x[ext_i]) > 0.0:
            ext_i = k
        elif direction * (x[ext_i] - x[k]) > tol:
            turns.append((ext_i, direction))
            direction = -direction
            ext_i = k
    if direction != 0:
        turns.append((ext_i, direction))
    return turns


def overshoot(pose: ArrayLike, intent: ArrayLike, *, tol: float = 1e-3) -> float:
    """Largest overshoot of the tool past the operator's intent at the intent's turns, in m.

    Per axis, the intent's turning points are its extrema that it then leaves by more
    than ``tol`` m, plus where it comes to rest (the last extremum). At a turning point
    e with value r_e, reached while moving in direction s_e (+1 rising into a maximum,
    −1 falling into a minimum), between the previous turning point and the next (the
    end for the last one) the intent never goes beyond r_e, so the tool's excursion
    past it is overshoot::

        OS_e = max(0, max_{k ∈ [k_{e−1}, k_{e+1}]} s_e (x(k) − r_e))
        overshoot = max over axes and turning points of OS_e

    A step of the intent to r answered by a tool that peaks at r + 0.1 r gives 0.1 r
    (the classic overshoot); a tool that never passes the intent gives 0.

    Parameters
    ----------
    pose : array_like, shape (T, d), tool positions in m.
    intent : array_like, shape (T, d), the operator's desired positions in m.
    tol : hysteresis in m: turns of the intent smaller than this are ignored.
    """
    tol = check_positive_scalar(tol, "tol")
    x = _as_positions(pose, "pose")
    ref = _as_positions(intent, "intent")
    if ref.shape != x.shape:
        raise ValueError(f"intent has shape {ref.shape}, expected {x.shape} to match pose")
    worst = 0.0
    for axis in range(x.shape[1]):
        turns = _turning_points(ref[:, axis], tol)
        bounds = [0] + [i for i, _ in turns] + [x.shape[0] - 1]
        for e, (i, s) in enumerate(turns):
            lo, hi = bounds[e], bounds[e + 2]  # from the turn before to the turn after (or the ends)
            worst = max(worst, float(np.max(s * (x[lo : hi + 1, axis] - ref[i, axis]))))
    return worst


def clearance(positions: ArrayLike, center: ArrayLike, size: ArrayLike) -> float:
    """min_k d(x(k), box) [m]: the smallest signed distance of a path from an axis-aligned box.

    d is the Euclidean distance to the box's surface outside it and minus the distance to the
    surface inside it (the box of :class:`coassist.scenario.tasks.Box`: ``center`` (d,),
    ``size`` (d,) its full widths [m]). Negative: the path went into the box.

    Parameters
    ----------
    positions : array_like, shape (T, d), in m.
    center, size : array_like, shape (d,), in m; size > 0.
    """
    x = _as_positions(positions, "positions")
    c = np.asarray(center, dtype=float)
    half = 0.5 * np.asarray(size, dtype=float)
    if c.shape != (x.shape[1],) or half.shape != (x.shape[1],):
        raise ValueError(f"center and size must have shape ({x.shape[1]},), got {c.shape} and {half.shape}")
    if not (np.isfinite(c).all() and np.isfinite(half).all() and (half > 0).all()):
        raise ValueError(f"center must be finite and size finite and > 0, got {center!r}, {size!r}")
    q = np.abs(x - c) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    inside = np.minimum(np.max(q, axis=1), 0.0)
    return float(np.min(outside + inside))


def clearance_deficit(pose: ArrayLike, intent: ArrayLike, center: ArrayLike, size: ArrayLike) -> float:
    """clearance(intent) − clearance(pose) [m]: how much closer to the box the tool passed than the
    operator meant it to (> 0: closer; ≤ 0: at least as far)."""
    return clearance(intent, center, size) - clearance(pose, center, size)


def peak_effort_ratio(effort_r: ArrayLike, effort_h: ArrayLike) -> float:
    """max_k ||u_r(k)|| / max_k ||u_h(k)||: the robot's peak effort relative to the hand's.

    Above 1 the robot pushes harder than the operator at some point; a robot fighting an
    oscillation shows peaks far above the hand's. NaN if the hand never pushes.

    Parameters
    ----------
    effort_r, effort_h : array_like, shape (T, d), in N.
    """
    ur = _as_positions(effort_r, "effort_r")
    uh = _as_positions(effort_h, "effort_h")
    peak_h = float(np.max(np.linalg.norm(uh, axis=1)))
    if peak_h == 0.0:
        return math.nan
    return float(np.max(np.linalg.norm(ur, axis=1))) / peak_h
