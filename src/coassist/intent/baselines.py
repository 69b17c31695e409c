"""Baselines every intent model is scored against, on the same windows.

- nominal: ŷ_ref,h(k+i) = y_ref,r(k+i), the planner's reference over the horizon — the
  assumption of dataset D0 (eq. 4.7);
- constant velocity: x(k) + i·dt·ẋ(k);
- ridge regression: a linear map from the same scaled input window to the same scaled
  target as the network, fitted in closed form on the same training windows.

All return predictions shaped like :attr:`coassist.data.Trial.prediction`: (T, H, d),
``pred[k, i-1]`` for tick k+i, in m.
"""

from __future__ import annotations

import math

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
)

__all__ = ["RidgeBaseline", "constant_velocity_prediction", "nominal_prediction"]


def nominal_prediction(trial: Trial, horizon: int) -> np.ndarray:
    """ŷ(k+i) = reference(k+i) (eq. 4.7), holding the last reference past the end. (T, H, d)."""
    t = trial.n_samples
    idx = np.minimum(np.arange(t)[:, None] + np.arange(1, horizon + 1)[None, :], t - 1)
    return trial.reference[idx]


def constant_velocity_prediction(trial: Trial, horizon: int, dt: float | None = None) -> np.ndarray:
    """ŷ(k+i) = x(k) + i·dt·ẋ(k), with the measured velocity; dt defaults to the trial's. (T, H, d)."""
    return constant_velocity(trial.pose, trial.velocity, horizon, trial.meta.dt if dt is None else dt)


class RidgeBaseline:
    """Ridge regression on the network's scaled, flattened input windows.

    Minimises Σ ||y − (W'x + b)||² + alpha ||W||² over the training windows (b not
    penalised), where x is the scaled window (steps·4·d) and y the scaled target
    (H·d), in closed form: W = (Xc'Xc + alpha I)⁻¹ Xc'Yc with Xc, Yc centred.
    The normal equations are accumulated in chunks, so any number of windows fits.
    """

    def __init__(self, W: np.ndarray, b: np.ndarray, alpha: float, window: WindowConfig,
                 input_scaler: Scaler, target_scaler: Scaler, dt: float) -> None:  # fmt: skip
        self.W, self.b, self.alpha = np.asarray(W, np.float64), np.asarray(b, np.float64), float(alpha)
        self.window, self.input_scaler, self.target_scaler, self.dt = window, input_scaler, target_scaler, float(dt)

    @classmethod
    def fit(cls, windows: WindowSet, input_scaler: Scaler, target_scaler: Scaler, alpha: float = 1.0,
            chunk: int = 4096) -> RidgeBaseline:  # fmt: skip
        if not (math.isfinite(alpha) and alpha >= 0):
            raise ValueError(f"alpha must be a finite number >= 0, got {alpha!r}")
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
        a = sxx - n * np.outer(mx, mx) + alpha * np.eye(sxx.shape[0])
        W = np.linalg.solve(a, sxy - n * np.outer(mx, my))
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
        return {"W": torch.from_numpy(self.W.copy()), "b": torch.from_numpy(self.b.copy()),
                "alpha": torch.tensor([self.alpha], dtype=torch.float64)}  # fmt: skip

    @classmethod
    def from_state_dict(cls, state: dict[str, torch.Tensor], window: WindowConfig, input_scaler: Scaler,
                        target_scaler: Scaler, dt: float) -> RidgeBaseline:  # fmt: skip
        try:
            return cls(state["W"].numpy(), state["b"].numpy(), float(state["alpha"][0]), window, input_scaler,
                       target_scaler, dt)  # fmt: skip
        except KeyError as exc:
            raise ValueError(f"ridge weights miss tensor {exc}") from None
