"""Constant-acceleration Kalman predictor: the physically grounded baseline.

Per axis the tool is a point with state s = [p, v, a] (m, m/s, m/s²) driven by white
jerk of power spectral density q (m²/s⁵)::

    s(k+1) = F s(k) + w(k),   F = [[1, dt, dt²/2], [0, 1, dt], [0, 0, 1]],
    w ~ N(0, Q),              Q = q [[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2, dt]],
    z(k) = [p, v] + n(k),     n ~ N(0, diag(r_p², r_v²)),

both the measured position and the measured velocity being observed. The filter is
the textbook one (predict, then update with the Joseph form); the axes are filtered
independently with the same model, so they share one covariance. The prediction for
tick k+i is the constant-acceleration extrapolation of the filtered state::

    x̂(k+i) = p̂(k) + τ v̂(k) + τ²/2 â(k),   τ = i·dt.

Its noise (q, r_v) is chosen on validation trials, from a grid, by the mean squared
position error over the whole horizon (:func:`tune_kalman`): the same protocol that
chooses the ridge's α (``baselines.fit_tuned_baselines``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from coassist._checks import check_int_at_least, check_positive_scalar

__all__ = [
    "JERK_PSD_GRID",
    "VELOCITY_NOISE_GRID",
    "KalmanCA",
    "constant_acceleration",
    "kalman_ca_filter",
    "tune_kalman",
]

#: Grid of the jerk spectral density q searched on validation trials [m²/s⁵].
JERK_PSD_GRID = tuple(float(10.0**e) for e in np.arange(-2.0, 5.01, 0.5))
#: Grid of the velocity measurement noise r_v searched on validation trials [m/s].
VELOCITY_NOISE_GRID = (1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2)


@dataclass(frozen=True)
class KalmanCA:
    """Noise of the constant-acceleration model (module docstring).

    jerk_psd : q [m²/s⁵].  velocity_noise : r_v, std of the measured velocity [m/s].
    position_noise : r_p, std of the measured position [m].
    initial_acceleration : std of the acceleration at the first tick [m/s²] (the first
        state is [p(0), v(0), 0]; position and velocity start with their measurement noise).
    tuned : whether (q, r_v) were chosen on validation trials (False: defaults).
    """

    jerk_psd: float = 10.0
    velocity_noise: float = 1e-3
    position_noise: float = 1e-4
    initial_acceleration: float = 1.0
    tuned: bool = False

    def __post_init__(self) -> None:
        for name in (
            "jerk_psd",
            "velocity_noise",
            "position_noise",
            "initial_acceleration",
        ):
            object.__setattr__(self, name, check_positive_scalar(getattr(self, name), f"kalman.{name}"))
        if not isinstance(self.tuned, bool):
            raise ValueError(f"kalman.tuned must be a bool, got {self.tuned!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> KalmanCA:
        fields = (
            "jerk_psd",
            "velocity_noise",
            "position_noise",
            "initial_acceleration",
            "tuned",
        )
        if not isinstance(data, dict) or any(k not in fields for k in data):
            raise ValueError(f"malformed Kalman parameters {data!r}: expected keys among {fields}")
        return cls(**data)

    def predict(self, pose: np.ndarray, velocity: np.ndarray, horizon: int, dt: float) -> np.ndarray:
        """(T, H, d) predictions of positions [m] from measured pose and velocity (T, d)."""
        states = kalman_ca_filter(pose, velocity, dt, [self])[0]
        return constant_acceleration(states, horizon, dt)


def _model(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """F and the unit-q process covariance Q/q for period dt (module docstring)."""
    F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q1 = np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    return F, Q1


def kalman_ca_filter(pose: np.ndarray, velocity: np.ndarray, dt: float, params: Sequence[KalmanCA]) -> np.ndarray:
    """Filtered states for several parameter sets at once.

    Parameters
    ----------
    pose, velocity : (T, d) measured position [m] and velocity [m/s].
    dt : period [s].
    params : G parameter sets.

    Returns
    -------
    (G, T, 3, d): [p̂, v̂, â] after the update with tick k's measurement, per axis.
    """
    pose, velocity = np.asarray(pose, np.float64), np.asarray(velocity, np.float64)
    if pose.ndim != 2 or pose.shape != velocity.shape or pose.shape[0] == 0:
        raise ValueError(f"pose and velocity must be equal (T, d) arrays, got {pose.shape} and {velocity.shape}")
    dt = check_positive_scalar(dt, "dt")
    t, d = pose.shape
    g = len(params)
    F, _ = _model(dt)
    # The gains do not depend on the measurements (P's recursion is data-free): computed once
    # per (dt, parameter sets) and reused by every trial; the state update is the only per-trial loop.
    gains = _gains(dt, tuple(params), t)  # (T, G, 3, 2)
    s = np.zeros((g, 3, d))
    s[:, 0], s[:, 1] = pose[0], velocity[0]
    out = np.empty((g, t, 3, d))
    out[:, 0] = s
    z = np.stack([pose, velocity], axis=1)  # (T, 2, d)
    for k in range(1, t):
        s = F @ s
        s = s + gains[k] @ (z[k] - s[:, :2])
        out[:, k] = s
    return out


#: (dt, parameter sets) → the longest gain sequence computed so far (T, G, 3, 2); a memo of
#: the pure function :func:`_gain_sequence`, bounded (a run uses a handful of keys).
_GAIN_MEMO: dict[tuple[float, tuple[KalmanCA, ...]], np.ndarray] = {}
_GAIN_MEMO_SIZE = 16


def _gains(dt: float, params: tuple[KalmanCA, ...], t: int) -> np.ndarray:
    """The first ``t`` Kalman gains of :func:`_gain_sequence`, from the memo where it holds them."""
    key = (float(dt), params)
    known = _GAIN_MEMO.get(key)
    if known is None or known.shape[0] < t:
        known = _gain_sequence(dt, params, max(t, 0 if known is None else 2 * known.shape[0]))
        if len(_GAIN_MEMO) >= _GAIN_MEMO_SIZE:
            _GAIN_MEMO.pop(next(iter(_GAIN_MEMO)))
        _GAIN_MEMO[key] = known
    return known[:t]


def _gain_sequence(dt: float, params: Sequence[KalmanCA], t: int) -> np.ndarray:
    """(T, G, 3, 2) the gains K_k = P_k⁻ H' (H P_k⁻ H' + R)⁻¹ of ticks k = 1 … T−1 (row 0 unused),
    from P_0 = diag(r_p², r_v², a_0²) and the Joseph-form covariance update."""
    g = len(params)
    F, Q1 = _model(dt)
    Q = np.array([p.jerk_psd for p in params])[:, None, None] * Q1
    R = np.zeros((g, 2, 2))
    R[:, 0, 0] = [p.position_noise**2 for p in params]
    R[:, 1, 1] = [p.velocity_noise**2 for p in params]
    Hm = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    eye = np.eye(3)
    P = np.zeros((g, 3, 3))
    P[:, :2, :2] = R
    P[:, 2, 2] = [p.initial_acceleration**2 for p in params]
    gains = np.zeros((t, g, 3, 2))
    for k in range(1, t):
        P = F @ P @ F.T + Q
        S = P[:, :2, :2] + R  # H P H' + R, H selecting p and v
        K = np.linalg.solve(S, P[:, :2, :]).transpose(0, 2, 1)  # P H' S⁻¹, (G, 3, 2); S symmetric
        IKH = eye - K @ Hm
        P = IKH @ P @ IKH.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)  # Joseph form: stays symmetric PSD
        gains[k] = K
    gains.setflags(write=False)
    return gains


def constant_acceleration(states: np.ndarray, horizon: int, dt: float) -> np.ndarray:
    """x̂(k+i) = p + τ v + τ²/2 a, τ = i·dt, i = 1 … H: states (..., 3, d) -> (..., H, d)."""
    check_int_at_least(horizon, "horizon", 1)
    tau = dt * np.arange(1, horizon + 1)[:, None]
    p, v, a = states[..., 0:1, :], states[..., 1:2, :], states[..., 2:3, :]
    return p + tau * v + 0.5 * tau**2 * a


def tune_kalman(
    trials: Sequence[Any],
    horizon: int,
    dt: float,
    *,
    first_tick: int = 0,
    jerk_psd_grid: Sequence[float] = JERK_PSD_GRID,
    velocity_noise_grid: Sequence[float] = VELOCITY_NOISE_GRID,
    position_noise: float = 1e-4,
) -> tuple[KalmanCA, dict[str, Any]]:
    """Choose (q, r_v) on validation trials: the grid point with the least mean squared error.

    The error is Σ_i ||x̂(k+i) − x(k+i)||² / H [m²], averaged over every tick k ≥
    ``first_tick`` with a full measured horizon, pooled over the trials (objects with
    ``pose`` and ``velocity``, e.g. :class:`coassist.data.Trial`).

    Returns the tuned parameters and ``{"jerk_psd_grid", "velocity_noise_grid",
    "validation_mse": (Q × R nested list, m²)}``.
    """
    check_int_at_least(horizon, "horizon", 1)
    grid = [KalmanCA(q, rv, position_noise, tuned=True) for q in jerk_psd_grid for rv in velocity_noise_grid]
    if not grid:
        raise ValueError("the Kalman tuning grid is empty")
    sse, n = _validation_sse(trials, horizon, dt, grid, first_tick)
    if n == 0:
        raise ValueError(f"no validation trial is longer than first_tick + horizon = {first_tick + horizon} samples")
    mse = sse / n
    best = grid[int(np.argmin(mse))]
    table = mse.reshape(len(jerk_psd_grid), len(velocity_noise_grid))
    record = {
        "jerk_psd_grid": [float(q) for q in jerk_psd_grid],
        "velocity_noise_grid": [float(r) for r in velocity_noise_grid],
        "validation_mse": table.tolist(),
        "validation_ticks": int(n),
    }
    if not math.isfinite(float(mse.min())):
        raise ValueError("Kalman tuning produced no finite validation error")
    return best, record


def _validation_sse(
    trials: Sequence[Any], horizon: int, dt: float, grid: Sequence[KalmanCA], first_tick: int
) -> tuple[np.ndarray, int]:
    """(G,) Σ over the trials' ticks k ≥ ``first_tick`` (with a full measured horizon) of
    Σ_i ||x̂(k+i) − x(k+i)||² / H per grid point, and the number of ticks summed.

    Σ_i ||x̂(k+i) − x(k+i)||² is a quadratic form in the filtered state, per axis: with
    φ_i = [1, τ_i, τ_i²/2], e_i = φ_i·δ − g_i, δ = [p̂ − x(k), v̂, â] and g_i = x(k+i) − x(k),
    Σ_i e_i² = δ'Aδ − 2 δ'b + c with A = Σ φ_i φ_i', b = Σ φ_i g_i, c = Σ g_i². A, b, c come
    from the data once per trial; a grid point then costs O(K) instead of O(K·H). Both sides
    are taken relative to x(k) so the three terms stay the size of the motion over a horizon,
    not of the workspace (the sum loses ~3 digits of 16 to cancellation, against the direct
    sum: tests/intent/test_baselines.py).

    Every grid point and every trial is filtered at once, tick by tick, as (G, N, d) arrays
    of p̂, v̂ and â, and δ'(Aδ − 2b) is summed as it comes: the filter's recursion written out
    per element (predict with F, update with the gain of :func:`_gains`; the same arithmetic
    whatever the number of trials), so one tick costs a few dozen array operations for all
    of them, where :func:`kalman_ca_filter` per trial cost two stacked matrix products of G
    small matrices each. Its states equal :func:`kalman_ca_filter`'s to rounding (~1e-14
    relative: ``F @ s`` sums in another order); trials still running are a prefix once they
    are sorted by length, so a trial's last tick ends its share of the work.
    """
    tau = dt * np.arange(1, horizon + 1)
    phi = np.stack([np.ones_like(tau), tau, 0.5 * tau**2], axis=1)  # (H, 3)
    A = phi.T @ phi
    steps = np.arange(1, horizon + 1)
    kept = []
    for tr in trials:
        pose, vel = np.asarray(tr.pose, np.float64), np.asarray(tr.velocity, np.float64)
        if pose.shape[0] - horizon > first_tick:
            kept.append((pose, vel))
    if not kept:
        return np.zeros(len(grid)), 0
    kept.sort(key=lambda pv: -pv[0].shape[0])  # longest first: the trials still running are a prefix
    n_trials, d, g = len(kept), kept[0][0].shape[1], len(grid)
    last = np.array([pose.shape[0] - horizon - 1 for pose, _ in kept])  # each trial's last scored tick
    t_max = int(last[0]) + 1
    zp, zv = np.zeros((t_max, n_trials, d)), np.zeros((t_max, n_trials, d))
    b = np.zeros((t_max, 3, n_trials, d))  # Σ_i φ_i g_i(k) per tick, trial and axis (0 where not scored)
    c = 0.0
    for j, (pose, vel) in enumerate(kept):
        zp[: last[j] + 1, j], zv[: last[j] + 1, j] = pose[: last[j] + 1], vel[: last[j] + 1]
        ks = np.arange(first_tick, last[j] + 1)
        ahead = pose[ks[:, None] + steps[None, :]] - pose[ks][:, None]  # g: (K, H, d)
        b[ks, :, j] = np.einsum("hi,khd->kid", phi, ahead)
        c += float(np.sum(ahead * ahead))
    gains = _gains(dt, tuple(grid), t_max).transpose(0, 2, 3, 1)[..., None, None]  # (T, 3, 2, G, 1, 1)
    p = np.broadcast_to(zp[0], (g, n_trials, d)).copy()
    v = np.broadcast_to(zv[0], (g, n_trials, d)).copy()
    a = np.zeros((g, n_trials, d))
    c1, c2 = dt, 0.5 * dt * dt  # F's entries: p += dt v + dt²/2 a, v += dt a
    (a00, a01, a02), (_, a11, a12), (_, _, a22) = A.tolist()
    sse = np.zeros(g)
    m = n_trials
    for k in range(1, t_max):
        while last[m - 1] < k:
            m -= 1
        P, V, Acc = p[:, :m], v[:, :m], a[:, :m]
        x, K = zp[k, :m], gains[k]
        pp = P + c1 * V + c2 * Acc
        vv = V + c1 * Acc
        ep, ev = x - pp, zv[k, :m] - vv
        P[...] = pp + K[0, 0] * ep + K[0, 1] * ev
        V[...] = vv + K[1, 0] * ep + K[1, 1] * ev
        Acc += K[2, 0] * ep + K[2, 1] * ev
        if k >= first_tick:
            bk = b[k, :, :m]
            d0 = P - x
            t0 = a00 * d0 + a01 * V + a02 * Acc - 2.0 * bk[0]
            t1 = a01 * d0 + a11 * V + a12 * Acc - 2.0 * bk[1]
            t2 = a02 * d0 + a12 * V + a22 * Acc - 2.0 * bk[2]
            sse += np.sum(d0 * t0 + V * t1 + Acc * t2, axis=(1, 2))
    if first_tick == 0:  # tick 0's state is the first measurement: δ = [0, v(0), 0]
        v0 = zv[0]
        sse += float(np.sum(v0 * (a11 * v0 - 2.0 * b[0, 1])))
    n = int(np.sum(last - first_tick + 1))
    return (sse + c) / horizon, n
