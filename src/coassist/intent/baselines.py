"""Baselines every intent model is scored against, on the same windows.

- nominal: ŷ_ref,h(k+i) = y_ref,r(k+i), the planner's reference over the horizon — the
  assumption of dataset D0 (eq. 4.7);
- constant velocity: x(k) + i·dt·ẋ(k);
- constant acceleration: a Kalman filter on the measured pose and velocity, extrapolated
  with constant acceleration (:mod:`coassist.intent.kalman`), its noise tuned on
  validation trials;
- ridge regression: a linear map from the same scaled input window to the same scaled
  target as the network, fitted in closed form on the same training windows, its α
  chosen on validation trials.

Tuning protocol (:func:`fit_tuned_baselines`), the one the model's own hyper-parameter
search uses (``intent.tuning``): the model's training trials are split again, by trial,
into fit and validation trials (:func:`coassist.intent.features.validation_split`); α
and the Kalman noise minimise the validation error over a fixed grid; the ridge is then
refitted on all training windows with the chosen α. The test trials are never seen.

All return predictions shaped like :attr:`coassist.data.Trial.prediction`: (T, H, d),
``pred[k, i-1]`` for tick k+i, in m.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from coassist.data import Trial
from coassist.intent.features import (
    Scaler,
    WindowConfig,
    WindowSet,
    constant_velocity,
    decode_target,
    scale_targets,
    unscale_targets,
    validation_split,
)
from coassist.intent.kalman import KalmanCA, tune_kalman

__all__ = [
    "RIDGE_ALPHAS",
    "RidgeBaseline",
    "constant_acceleration_prediction",
    "constant_velocity_prediction",
    "fit_tuned_baselines",
    "nominal_prediction",
    "ridge_validation_errors",
    "tune_ridge_alpha",
]

#: The ridge α searched on validation trials (scaled inputs and targets, see RidgeBaseline).
RIDGE_ALPHAS = tuple(float(10.0**e) for e in np.arange(-7.0, 3.01, 0.5))


def nominal_prediction(trial: Trial, horizon: int) -> np.ndarray:
    """ŷ(k+i) = reference(k+i) (eq. 4.7), holding the last reference past the end. (T, H, d)."""
    t = trial.n_samples
    idx = np.minimum(np.arange(t)[:, None] + np.arange(1, horizon + 1)[None, :], t - 1)
    return trial.reference[idx]


def constant_velocity_prediction(trial: Trial, horizon: int, dt: float | None = None) -> np.ndarray:
    """ŷ(k+i) = x(k) + i·dt·ẋ(k), with the measured velocity; dt defaults to the trial's. (T, H, d)."""
    return constant_velocity(trial.pose, trial.velocity, horizon, trial.meta.dt if dt is None else dt)


def constant_acceleration_prediction(
    trial: Trial, horizon: int, params: KalmanCA, dt: float | None = None
) -> np.ndarray:
    """ŷ(k+i) = p̂ + τ v̂ + τ²/2 â (τ = i·dt) from the constant-acceleration Kalman filter. (T, H, d)."""
    return params.predict(trial.pose, trial.velocity, horizon, trial.meta.dt if dt is None else dt)


def _normal_equations(
    windows: WindowSet, input_scaler: Scaler, target_scaler: Scaler, chunk: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Centred Xc'Xc, Xc'Yc and the means of X and Y over the scaled windows, in chunks."""
    n = len(windows)
    sxx = sxy = sx = sy = None
    for sel in np.array_split(np.arange(n), max(1, math.ceil(n / chunk))):
        x = input_scaler.transform(windows.raw_inputs(sel)).reshape(sel.size, -1)
        y = scale_targets(target_scaler, windows.raw_targets(sel))
        if sxx is None:
            sxx, sxy = np.zeros((x.shape[1],) * 2), np.zeros((x.shape[1], y.shape[1]))
            sx, sy = np.zeros(x.shape[1]), np.zeros(y.shape[1])
        sxx += x.T @ x
        sxy += x.T @ y
        sx += x.sum(0)
        sy += y.sum(0)
    mx, my = sx / n, sy / n
    return sxx - n * np.outer(mx, mx), sxy - n * np.outer(mx, my), mx, my


def ridge_validation_errors(
    fit: WindowSet,
    validation: WindowSet,
    input_scaler: Scaler,
    target_scaler: Scaler,
    alphas: Sequence[float] = RIDGE_ALPHAS,
    chunk: int = 4096,
) -> np.ndarray:
    """Validation error of the ridge fitted on ``fit`` for each α: (len(alphas),) in m².

    The error is the mean over validation windows of Σ_i ||x̂(k+i) − x(k+i)||² / H, the
    positions decoded from the scaled outputs. One eigendecomposition Xc'Xc = V Λ V'
    serves every α: W(α) = V (Λ + α I)⁻¹ V' Xc'Yc.
    """
    alphas = [float(a) for a in alphas]
    if not alphas or any(not (math.isfinite(a) and a >= 0) for a in alphas):
        raise ValueError(f"ridge alphas must be finite numbers >= 0, got {alphas!r}")
    cxx, cxy, mx, my = _normal_equations(fit, input_scaler, target_scaler, chunk)
    lam, V = np.linalg.eigh(cxx)
    vxy = V.T @ cxy
    h, d = validation.window.horizon, validation.n_dof
    sse, n = np.zeros(len(alphas)), len(validation)
    floor = 1e-12 * max(float(lam.max()), 1e-300)  # α = 0 on a singular Xc'Xc: the minimum-norm solution
    weights = [V @ (np.where(lam + a > floor, 1.0 / np.maximum(lam + a, floor), 0.0)[:, None] * vxy) for a in alphas]
    for sel in np.array_split(np.arange(n), max(1, math.ceil(n / chunk))):
        x = input_scaler.transform(validation.raw_inputs(sel)).reshape(sel.size, -1) - mx
        truth = validation.raw_targets(sel)  # the positions' error equals the target's (same base)
        for i, w in enumerate(weights):
            e = unscale_targets(target_scaler, x @ w + my, h, d) - truth
            sse[i] += float(np.sum(e * e)) / h
    return sse / n


class RidgeBaseline:
    """Ridge regression on the network's scaled, flattened input windows.

    Minimises Σ ||y − (W'x + b)||² + alpha ||W||² over the training windows (b not
    penalised), where x is the scaled window (steps·4·d) and y the scaled target
    (H·d), in closed form: W = (Xc'Xc + alpha I)⁻¹ Xc'Yc with Xc, Yc centred.
    The normal equations are accumulated in chunks, so any number of windows fits.
    """

    def __init__(
        self,
        W: np.ndarray,
        b: np.ndarray,
        alpha: float,
        window: WindowConfig,
        input_scaler: Scaler,
        target_scaler: Scaler,
        dt: float,
    ) -> None:
        self.W, self.b, self.alpha = np.asarray(W, np.float64), np.asarray(b, np.float64), float(alpha)
        self.window, self.input_scaler, self.target_scaler, self.dt = window, input_scaler, target_scaler, float(dt)

    @classmethod
    def fit(
        cls, windows: WindowSet, input_scaler: Scaler, target_scaler: Scaler, alpha: float = 1.0, chunk: int = 4096
    ) -> RidgeBaseline:
        if not (math.isfinite(alpha) and alpha >= 0):
            raise ValueError(f"alpha must be a finite number >= 0, got {alpha!r}")
        cxx, cxy, mx, my = _normal_equations(windows, input_scaler, target_scaler, chunk)
        W = np.linalg.solve(cxx + alpha * np.eye(cxx.shape[0]), cxy)
        return cls(W, my - mx @ W, alpha, windows.window, input_scaler, target_scaler, windows.dt)

    def predict_scaled(self, x: np.ndarray) -> np.ndarray:
        """Scaled windows (B, steps, 4·d) -> scaled targets (B, H·d)."""
        return x.reshape(x.shape[0], -1) @ self.W + self.b

    def predict_trial(self, trial: Trial) -> np.ndarray:
        """(T, H, d) predictions; NaN before the history window is full."""
        ws = WindowSet([trial], self.window, self.dt, need_future=False)
        sel = np.arange(len(ws))
        out = self.predict_scaled(self.input_scaler.transform(ws.raw_inputs(sel)))
        d, h = trial.n_dof, self.window.horizon
        pose, vel = ws.anchors(sel)
        pred = np.full((trial.n_samples, h, d), np.nan)
        pred[ws.ends] = decode_target(unscale_targets(self.target_scaler, out, h, d), pose, vel, self.window, self.dt)
        return pred

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {
            "W": torch.from_numpy(self.W.copy()),
            "b": torch.from_numpy(self.b.copy()),
            "alpha": torch.tensor([self.alpha], dtype=torch.float64),
        }

    @classmethod
    def from_state_dict(
        cls,
        state: dict[str, torch.Tensor],
        window: WindowConfig,
        input_scaler: Scaler,
        target_scaler: Scaler,
        dt: float,
    ) -> RidgeBaseline:
        try:
            return cls(
                state["W"].numpy(),
                state["b"].numpy(),
                float(state["alpha"][0]),
                window,
                input_scaler,
                target_scaler,
                dt,
            )
        except KeyError as exc:
            raise ValueError(f"ridge weights miss tensor {exc}") from None


#: The ridge's α where there is nothing to validate on (fewer than two training trials).
UNTUNED_RIDGE_ALPHA = 1.0


def tune_ridge_alpha(
    trials: Sequence[Trial],
    ids: Sequence[str],
    window: WindowConfig,
    dt: float,
    input_scaler: Scaler,
    target_scaler: Scaler,
    *,
    seed: int,
    stride: int = 1,
    alphas: Sequence[float] = RIDGE_ALPHAS,
) -> tuple[float, dict[str, Any]]:
    """α minimising :func:`ridge_validation_errors` on validation trials split from the training trials.

    ``trials``/``ids``: the model's training trials (at least two), split by
    :func:`validation_split` with ``seed``; windows every ``stride``-th, as in training.
    Returns (α, record with the fit and validation trial ids, the grid and its errors in m²).
    """
    if len(trials) != len(ids):
        raise ValueError(f"need one id per training trial, got {len(trials)} trials and {len(ids)} ids")
    fit_idx, val_idx = validation_split(ids, seed)
    try:
        fit_ws = WindowSet([trials[i] for i in fit_idx], window, dt, stride=stride)
        val_ws = WindowSet([trials[i] for i in val_idx], window, dt, stride=stride)
    except ValueError as exc:  # said of the split (it read as if of every trial given: a review, 2026-12-07)
        raise ValueError(
            f"the ridge's α is tuned on a split of the {len(trials)} training trials ({len(fit_idx)} to fit, "
            f"{len(val_idx)} to validate on) and one part has no window: {exc}; give more trials long enough"
        ) from None
    alphas = [float(a) for a in alphas]
    errors = ridge_validation_errors(fit_ws, val_ws, input_scaler, target_scaler, alphas)
    record = {
        "fit_trials": [ids[i] for i in fit_idx],
        "validation_trials": [ids[i] for i in val_idx],
        "alphas": alphas,
        "validation_mse": [float(e) for e in errors],
    }
    return alphas[int(np.argmin(errors))], record


def fit_tuned_baselines(
    trials: Sequence[Trial],
    ids: Sequence[str],
    window: WindowConfig,
    dt: float,
    input_scaler: Scaler,
    target_scaler: Scaler,
    *,
    seed: int,
    stride: int = 1,
    alpha: float | None = None,
    fallback_alpha: float = UNTUNED_RIDGE_ALPHA,
    tuned: tuple[float, dict[str, Any]] | None = None,
) -> tuple[RidgeBaseline, KalmanCA, dict[str, Any]]:
    """The ridge and the Kalman predictor, tuned on validation trials from the training trials.

    ``trials`` and ``ids`` are the model's training trials (never its test trials). α
    comes from :func:`tune_ridge_alpha` unless ``alpha`` fixes it; the Kalman noise from
    :func:`coassist.intent.kalman.tune_kalman` on the same validation trials. The ridge
    is then refitted on all training windows (every ``stride``-th). With fewer than two
    training trials there is nothing to validate on: α = ``fallback_alpha`` (or
    ``alpha``) and the Kalman defaults, recorded as untuned. ``tuned``: what
    :func:`tune_ridge_alpha` already returned for these very arguments (training tunes
    the skip's α first), so the search is not run twice.

    Returns (ridge, kalman, record) — the record is JSON-ready for the model's sidecar.
    """
    if len(trials) != len(ids) or not trials:
        raise ValueError(f"need one id per training trial, got {len(trials)} trials and {len(ids)} ids")
    all_ws = WindowSet(list(trials), window, dt, stride=stride)
    kalman = KalmanCA()
    record: dict[str, Any] = {
        "protocol": "validation trials split by trial from the training trials "
        "(features.validation_split); criterion: mean squared position error over the whole horizon"
    }
    if len(trials) < 2:
        record["protocol"] = "untuned: fewer than two training trials, no validation trial"
        ridge_rec: dict[str, Any] = {"tuned": False}
        alpha_used = fallback_alpha if alpha is None else alpha
    else:
        if alpha is None:
            alpha_used, search = tuned or tune_ridge_alpha(
                trials, ids, window, dt, input_scaler, target_scaler, seed=seed, stride=stride
            )
            ridge_rec = {"tuned": True, **search}
        else:
            alpha_used, ridge_rec = float(alpha), {"tuned": False, "fixed_by": "train.ridge_alpha"}
        fit_idx, val_idx = validation_split(ids, seed)
        record["fit_trials"], record["validation_trials"] = [ids[i] for i in fit_idx], [ids[i] for i in val_idx]
        kalman, record["constant_acceleration_search"] = tune_kalman(
            [trials[i] for i in val_idx], window.horizon, dt, first_tick=window.history - 1
        )
    ridge = RidgeBaseline.fit(all_ws, input_scaler, target_scaler, alpha_used)
    record["ridge"] = {"alpha": float(alpha_used), **ridge_rec}
    record["constant_acceleration"] = kalman.to_dict()
    return ridge, kalman, record
