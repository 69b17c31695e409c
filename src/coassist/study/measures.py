"""What a study measures in one trial (thesis §5.2.4, plus what a pHRI paper reports beside it).

All on the x-y task plane, from the trial as written (:class:`coassist.data.Trial`):

- ``f_rms`` [N]: mean norm of the measured hand force (eq. 5.9, :func:`coassist.metrics.f_rms`);
- ``sigma`` [m]: mean distance to the target over τ = 3 s after first entering the ε-ball
  (eq. 5.10–5.11, :func:`coassist.metrics.precision_sigma`); NaN if never reached;
- ``overshoot`` [m]: how far the tool went past the target along the plan's final approach
  direction u (the unit vector from the last plan point 2 cm or more before the target to
  the target), after first entering the ε-ball::

      overshoot = max(0, max_{k ≥ k_enter} (x(k) − x_target) · u)

  defined for a person as for a simulated operator (the simulated operator's overshoot past
  its own intent, :func:`coassist.metrics.overshoot`, needs the intent only a simulation
  knows; the report adds it where the trials carry it);
- ``jerk`` [m/s³]: RMS jerk of the tool (:func:`coassist.metrics.jerk_rms`);
- ``time_to_target`` [s]: from the trial's start to the first entry into the ε-ball;
- ``e_rms`` [m]: the prediction in use against the measured future poses at 50 samples
  (0.4 s; eq. 5.6, :func:`coassist.metrics.prediction_errors`) over the ticks that had one —
  the model's in-loop error, or the nominal plan's where no model was in the loop.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from coassist.data import Trial
from coassist.metrics import f_rms, jerk_rms, overshoot, precision_sigma, prediction_errors, time_to_target

__all__ = ["MEASURES", "E_RMS_HORIZON", "trial_measures"]

#: (key, label, unit, scale to the unit shown, lower is better)
MEASURES = (
    ("f_rms", "f_RMS", "N", 1.0),
    ("sigma", "σ at the target", "mm", 1e3),
    ("overshoot", "overshoot past the target", "mm", 1e3),
    ("jerk", "jerk RMS", "m/s³", 1.0),
    ("time_to_target", "time to target", "s", 1.0),
    ("e_rms", "e_RMS at 0.4 s", "mm", 1e3),
)
E_RMS_HORIZON = 50


def _approach(reference: np.ndarray, target: np.ndarray, back: float = 0.02) -> np.ndarray | None:
    far = np.flatnonzero(np.linalg.norm(reference - target, axis=1) >= back)
    if far.size == 0:
        return None
    u = target - reference[far[-1]]
    return u / np.linalg.norm(u)


def trial_measures(trial: Trial) -> dict[str, Any]:
    """The module's measures of ``trial`` (NaN where undefined), plus the simulated operator's
    ``overshoot_intent`` [m] where the trial carries its intent."""
    dt = trial.meta.dt
    extra = trial.meta.extra
    pose = np.asarray(trial.pose[:, :2])
    target = np.asarray(extra["target"], dtype=float)[:2]
    eps = float(extra.get("arrive_radius", 0.025))
    out: dict[str, Any] = {
        "f_rms": f_rms(trial.wrench[:, :2]),
        "sigma": precision_sigma(pose, target, dt, epsilon=eps),
        "jerk": jerk_rms(pose, dt) if len(pose) >= 4 else math.nan,
        "time_to_target": time_to_target(pose, target, dt, epsilon=eps),
    }
    inside = np.flatnonzero(np.linalg.norm(pose - target, axis=1) <= eps)
    u = _approach(np.asarray(trial.reference[:, :2]), target)
    out["overshoot"] = (
        max(0.0, float(np.max((pose[inside[0] :] - target) @ u))) if inside.size and u is not None else math.nan
    )
    e = math.nan
    if trial.prediction is not None and trial.prediction.shape[1] >= E_RMS_HORIZON:
        ok = np.isfinite(trial.prediction[:, :E_RMS_HORIZON, :2]).all(axis=(1, 2))
        if ok.sum() > E_RMS_HORIZON:
            errs = prediction_errors(trial.prediction[:, :, :2], pose, E_RMS_HORIZON).rms
            errs = errs[np.isfinite(errs)]
            e = float(errs.mean()) if errs.size else math.nan
    out["e_rms"] = e
    if trial.intent is not None and np.isfinite(trial.intent).all():
        out["overshoot_intent"] = overshoot(pose, trial.intent[:, :2])
    return {k: float(v) for k, v in out.items()}
