"""Performance indexes of thesis §5.2.4: e_RMS, e_MAX, f_RMS and σ.

Pure functions on arrays (SI units). Conventions, where the thesis is loose
(DESIGN.md §2):

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

from coassist._checks import check_positive_scalar
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike

__all__ = [
    "HORIZONS",
    "EMax",
    "PredictionErrors",
    "distance_to_target",
    "e_max",
    "e_rms",
    "f_rms",
    "precision_sigma",
    "prediction_errors",
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
        raise ValueError(f"prediction has shape {np.shape(prediction)}, expected ({t}, H, {d}) to match pose {pose.shape}")
    if np.any(np.isinf(pred)):
        raise ValueError("prediction has infinite values")
    return pred


def _check_horizon(horizon: int, available: int) -> int:
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)):
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
    pose_arr = _as_positions(pose, "pose")
    pred = _as_prediction(prediction, pose_arr)
    n = _check_horizon(horizon, pred.shape[1])
    t = pose_arr.shape[0]
    if t <= n:
        raise ValueError(f"trajectory of {t} samples is too short for a horizon of {n} samples (needs T > N)")
    # future[k, i-1] = pose[k+i] for k = 0 … T-N-1: windows of N rows starting at k+1.
    future = np.moveaxis(sliding_window_view(pose_arr[1:], n, axis=0), -1, 1)  # (T-N, N, d)
    err = pred[: t - n, :n, :] - future
    sq = np.sum(err * err, axis=2)  # (T-N, N): ||·||² per step
    ok = np.all(np.isfinite(sq), axis=1)
    if not np.any(ok):
        raise ValueError(f"no tick has a finite prediction over the first {n} steps")
    tick = np.flatnonzero(ok)
    sq = sq[ok]
    return PredictionErrors(tick=tick, rms=np.sqrt(np.mean(sq, axis=1)), max=np.sqrt(np.max(sq, axis=1)))


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
    compare trials. We report both readings that are comparable (DESIGN.md §2):

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
    despite its name it is a mean norm, not a root mean square (DESIGN.md §2). The
    thesis then averages it over three trials: do that over the returned values.

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
      which read literally (0.25 mm) is below the robot's tracking noise; DESIGN.md §2
      fixes metres.
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
