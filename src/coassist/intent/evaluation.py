"""Scoring a model against the baselines on the same windows (thesis §5.2.4).

For each horizon N in :data:`coassist.metrics.HORIZONS` (5, 10, 20, 50 samples = 0.04,
0.08, 0.16, 0.4 s), e_RMS (eq. 5.6) and e_MAX (eq. 5.7–5.8; mean and max of the
per-tick maximum, see :func:`coassist.metrics.e_max`) of

- the model,
- the nominal reference (eq. 4.7),
- constant-velocity extrapolation,
- the ridge baseline fitted on the model's training windows (when the model has one),

all scored on exactly the same ticks: those where the model has a full history and
the whole horizon has been measured. Per-tick errors are pooled over all trials, so
long trials weigh more, as in the thesis' per-dataset figures.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from coassist.intent.baselines import constant_velocity_prediction, nominal_prediction
from coassist.intent.features import feature_names
from coassist.intent.model import IntentModel
from coassist.intent.sources import LabeledTrial
from coassist.metrics import HORIZONS, prediction_errors

__all__ = ["PREDICTORS", "evaluate_model", "results_table"]

PREDICTORS = ("model", "nominal", "constant_velocity", "ridge")


def evaluate_model(
    model: IntentModel,
    trials: Sequence[LabeledTrial],
    *,
    horizons: Sequence[int] = HORIZONS,
    held_out_only: bool = True,
) -> dict[str, Any]:
    """e_RMS and e_MAX per horizon for the model and the baselines, in m.

    Parameters
    ----------
    held_out_only : bool
        Skip trials the model was trained on (its sidecar's ``train_trials``); the
        skipped ids are listed in the result.

    Returns
    -------
    dict
        ``{"trials", "skipped", "n_ticks", "horizons", "dt", "results": {predictor:
        {str(N): {"e_rms", "e_max_mean", "e_max_max"}}}}``.
    """
    horizons = [int(h) for h in horizons if int(h) <= model.horizon]
    if not horizons:
        raise ValueError(f"no horizon fits the model's horizon of {model.horizon} samples")
    trained_on = set(model.info.get("train_trials", [])) if held_out_only else set()
    used = [lt for lt in trials if lt.id not in trained_on]
    skipped = [lt.id for lt in trials if lt.id in trained_on]
    if not used:
        raise ValueError(f"every given trial was used to train the model ({len(skipped)} trials); nothing held out")
    names = [p for p in PREDICTORS if p != "ridge" or model.ridge is not None]
    per: dict[str, dict[int, dict[str, list[np.ndarray]]]] = {
        p: {h: {"rms": [], "max": []} for h in horizons} for p in names
    }
    n_ticks = 0
    for lt in used:
        t = lt.trial
        model.check_compatible(feature_names(t.n_dof), t.meta.dt, what=f"trial {lt.id}")
        pm = model.predict_trial(t)
        mask = ~np.all(np.isfinite(pm), axis=(1, 2))
        preds = {
            "model": pm,
            "nominal": nominal_prediction(t, model.horizon),
            "constant_velocity": constant_velocity_prediction(t, model.horizon, model.dt),
        }
        if model.ridge is not None:
            preds["ridge"] = model.ridge.predict_trial(t)
        for p, pred in preds.items():
            pred = pred.copy()
            pred[mask] = np.nan  # score every predictor on the model's ticks only
            for h in horizons:
                if t.n_samples <= h or np.all(mask[: t.n_samples - h]):
                    continue
                e = prediction_errors(pred, t.pose, h)
                per[p][h]["rms"].append(e.rms)
                per[p][h]["max"].append(e.max)
        n_ticks += int(np.sum(~mask[: max(0, t.n_samples - max(horizons))]))
    results: dict[str, dict[str, dict[str, float]]] = {}
    for p in names:
        results[p] = {}
        for h in horizons:
            if not per[p][h]["rms"]:
                continue
            rms, mx = np.concatenate(per[p][h]["rms"]), np.concatenate(per[p][h]["max"])
            results[p][str(h)] = {"e_rms": float(rms.mean()), "e_max_mean": float(mx.mean()), "e_max_max": float(mx.max())}
    return {
        "trials": [lt.id for lt in used],
        "skipped": skipped,
        "n_ticks": n_ticks,
        "horizons": horizons,
        "dt": model.dt,
        "results": results,
    }


def results_table(result: dict[str, Any], title: str = "") -> Any:
    """A rich Table: predictors × (e_RMS, mean e_MAX) per horizon, in mm."""
    from rich.table import Table

    hs = [str(h) for h in result["horizons"]]
    dt = result["dt"]
    table = Table(title=title or f"held-out trials: {len(result['trials'])}, ticks scored: {result['n_ticks']}")
    table.add_column("predictor")
    for kind in ("e_RMS", "e_MAX"):
        for h in hs:
            table.add_column(f"{kind} {int(h) * dt:.2f}s [mm]", justify="right")
    best = {h: min(r[h]["e_rms"] for r in result["results"].values() if h in r) for h in hs}
    for p, r in result["results"].items():
        cells = []
        for h in hs:
            v = r.get(h, {}).get("e_rms")
            s = "–" if v is None else f"{1e3 * v:.2f}"
            cells.append(f"[bold]{s}[/]" if v is not None and v == best[h] else s)
        cells += ["–" if h not in r else f"{1e3 * r[h]['e_max_mean']:.2f}" for h in hs]
        table.add_row(p, *cells)
    return table
