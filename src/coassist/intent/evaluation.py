"""Scoring a model against tuned baselines on the same ticks (thesis §5.2.4).

For each horizon N in :data:`coassist.metrics.HORIZONS` (5, 10, 20, 50 samples = 0.04,
0.08, 0.16, 0.4 s), e_RMS (eq. 5.6) and e_MAX (eq. 5.7–5.8; mean and max of the
per-tick maximum, see :func:`coassist.metrics.e_max`) of

- the model,
- the nominal reference (eq. 4.7),
- constant-velocity extrapolation,
- constant-acceleration extrapolation of a Kalman filter, its noise tuned on the model's
  validation trials (``info["baselines"]``; defaults, flagged untuned, for older models),
- the ridge baseline fitted on the model's training windows, its α tuned on the same
  validation trials (when the model has one),

all scored on exactly the same ticks at each horizon: those where the model has a full history and
that horizon has been measured (so a shorter horizon also scores the ticks near a trial's end that a
longer one cannot: ``n_ticks`` counts the longest horizon's). Per-tick errors are pooled over all trials (long
trials weigh more, as in the thesis' per-dataset figures); the per-trial e_RMS is kept
too, for the spread. The *best baseline* at a horizon is the baseline with the lowest
pooled e_RMS there; the model's gain over it is (e_best − e_model) / e_best.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from coassist._io import json_object_with
from coassist._progress import progress_bar
from coassist.intent.baselines import (
    constant_acceleration_prediction,
    constant_velocity_prediction,
    nominal_prediction,
)
from coassist.intent.features import feature_names
from coassist.intent.kalman import KalmanCA
from coassist.intent.model import IntentModel, lineage_train_trials
from coassist.intent.trials import LabeledTrial, content_digest
from coassist.metrics import HORIZONS, prediction_errors_by_horizon

__all__ = [
    "AGAINST",
    "BASELINES",
    "PREDICTORS",
    "ModelEvaluation",
    "best_baselines",
    "comparison_lines",
    "evaluate_model",
    "is_evaluation_file",
    "records_intent",
    "results_table",
    "scoring_target",
]

PREDICTORS = ("model", "nominal", "constant_velocity", "constant_acceleration", "ridge")
BASELINES = PREDICTORS[1:]


#: What :func:`evaluate_model` can score the predictors against (and what it is): the tool's future path (the thesis'
#: e_RMS) or the person's true intent (simulated trials).
AGAINST = {"tool": "the tool's future path", "intent": "the person's true intent"}

#: Scores of one predictor at one horizon: e_rms, e_max_mean, e_max_max [m], e_rms_trials
#: {trial id: e_RMS}, trial_median, trial_min, trial_max [m].
Scores = dict[str, Any]


@dataclass(frozen=True)
class ModelEvaluation:
    """What :func:`evaluate_model` measured (errors in m, horizons in ticks).

    trials : the scored trial ids.  skipped : the ids left out (the model trained on them).  copies : those of
        ``skipped`` left out for their contents (a training trial's, under another name).
    against : what every predictor's rows were scored against: ``"tool"`` (the tool's future path, the thesis'
        e_RMS) or ``"intent"`` (the person's true intent, simulated trials: what an intent-label model predicts).
    n_ticks : ticks scored at the longest horizon any trial was long enough for (the model's, every predictor on the
        same ones; a shorter horizon scores these and the ticks near each trial's end that only it reaches).
    horizons : the horizons [ticks] reported, ascending.  dt : [s] per tick.
    baselines : how the baselines were set up (the ridge's α, the Kalman filter's noise, the
        tuning protocol).
    results : predictor -> horizon -> :data:`Scores`.
    best_baseline : horizon -> the best baseline there and the model's gain over it
        (:func:`best_baselines`).
    """

    trials: tuple[str, ...]
    skipped: tuple[str, ...]
    n_ticks: int
    horizons: tuple[int, ...]
    dt: float
    baselines: dict[str, Any]
    results: dict[str, dict[int, Scores]]
    best_baseline: dict[int, dict[str, Any]]
    unit: str = "m"
    copies: tuple[str, ...] = ()
    against: str = "tool"

    def to_dict(self) -> dict[str, Any]:
        """The JSON record (``coassist evaluate``'s evaluation.json, the report's summary.json);
        ``json.dumps`` writes the integer horizons as the keys "5", "10", …."""
        return {
            "trials": list(self.trials),
            "skipped": list(self.skipped),
            "n_ticks": self.n_ticks,
            "horizons": list(self.horizons),
            "dt": self.dt,
            "unit": self.unit,
            "baselines": self.baselines,
            "results": self.results,
            "best_baseline": self.best_baseline,
            "copies": list(self.copies),
            "against": self.against,
        }


def model_kalman(model: IntentModel) -> KalmanCA:
    """The Kalman noise tuned with the model (its sidecar's ``baselines``), else the untuned defaults."""
    data = model.info.get("baselines", {}).get("constant_acceleration")
    return KalmanCA() if data is None else KalmanCA.from_dict(data)


def _tracked(items: Sequence[Any], progress: bool, what: str) -> Iterator[Any]:
    """``items`` one by one, a progress bar advancing after each (drawn only where ``progress``)."""
    with progress_bar(progress) as bar:
        task = bar.add_task(what, total=len(items))
        for item in items:
            yield item
            bar.advance(task)


def evaluate_model(
    model: IntentModel,
    trials: Sequence[LabeledTrial],
    *,
    horizons: Sequence[int] = HORIZONS,
    held_out_only: bool = True,
    stride: int = 1,
    against: str = "tool",
    progress: bool = False,
) -> ModelEvaluation:
    """e_RMS and e_MAX per horizon for the model and the baselines, in m.

    Parameters
    ----------
    model : the model to score.
    trials : the labelled trials to score it on (the baselines are scored on the same ticks).
    horizons : the prediction horizons [ticks] to report.
    held_out_only : bool
        Skip trials the model or the models it was started from were trained on (its sidecar's
        ``train_trials`` and its ``parent``'s: :func:`~coassist.intent.model.lineage_train_trials`), and copies of
        them under other names (their contents' digests, ``train_digests``); the skipped ids are listed in the
        result, the copies apart.
    stride : score every n-th of the model's ticks (:meth:`IntentModel.predict_trial`), every predictor on the
        same ticks (1: every tick).
    against : ``"tool"`` (every predictor against the tool's future path: what the thesis scores) or ``"intent"``
        (against the trial's true intent, which simulated trials record: an intent-label model's own target; a
        trial without it raises, naming it). :data:`AGAINST`.
    progress : draw a progress bar over the trials scored (a thesis-size model takes some 17 s a 2000-tick trial).

    Returns
    -------
    ModelEvaluation
        Per predictor and horizon N (an int): e_RMS, e_MAX and their spread over trials;
        per horizon the best baseline (:func:`best_baselines`).
    """
    horizons = [int(h) for h in horizons if int(h) <= model.horizon]
    if not horizons:
        raise ValueError(f"no horizon fits the model's horizon of {model.horizon} samples")
    if against not in AGAINST:
        raise ValueError(f"against must be one of {tuple(AGAINST)}, got {against!r}")
    trained_on = lineage_train_trials(model.info) if held_out_only else set()
    contents = lineage_train_trials(model.info, "train_digests") if held_out_only else set()
    copies = [lt.id for lt in trials if lt.id not in trained_on and contents and content_digest(lt.trial) in contents]
    left_out = trained_on | set(copies)
    skipped = [lt.id for lt in trials if lt.id in left_out]
    used = [lt for lt in trials if lt.id not in left_out]
    if not used:
        copied = f", {len(copies)} of them copies of its training trials under other names" if copies else ""
        raise ValueError(
            f"every given trial was used to train the model or the one it was started from ({len(skipped)} "
            f"trials{copied}); nothing held out"
        )
    kalman = model_kalman(model)
    names = [p for p in PREDICTORS if p != "ridge" or model.ridge is not None]
    per: dict[str, dict[int, dict[str, list[np.ndarray]]]] = {
        p: {h: {"rms": [], "max": []} for h in horizons} for p in names
    }
    per_trial: dict[str, dict[int, dict[str, float]]] = {p: {h: {} for h in horizons} for p in names}
    ticks = dict.fromkeys(horizons, 0)  # ticks scored at each horizon
    for lt in _tracked(used, progress, f"scoring {len(used)} held-out trials"):
        t = lt.trial
        model.check_compatible(feature_names(t.n_dof), t.meta.dt, what=f"trial {lt.id}")
        target = t.pose if against == "tool" else _intent_of(lt)
        pm = model.predict_trial(t, stride=stride)
        mask = ~np.all(np.isfinite(pm), axis=(1, 2))
        preds = {
            "model": pm,
            "nominal": nominal_prediction(t, model.horizon),
            "constant_velocity": constant_velocity_prediction(t, model.horizon, model.dt),
            "constant_acceleration": constant_acceleration_prediction(t, model.horizon, kalman, model.dt),
        }
        if model.ridge is not None:
            preds["ridge"] = model.ridge.predict_trial(t)
        scored = [h for h in horizons if not (t.n_samples <= h or np.all(mask[: t.n_samples - h]))]
        for p, pred in preds.items():
            pred = pred.copy()
            pred[mask] = np.nan  # score every predictor on the model's ticks only
            errors = prediction_errors_by_horizon(pred, target, scored)  # prediction_errors' per h, bit for bit
            for h in scored:
                e = errors[h]
                per[p][h]["rms"].append(e.rms)
                per[p][h]["max"].append(e.max)
                per_trial[p][h][lt.id] = float(e.rms.mean())
        for h in scored:
            ticks[h] += int(np.sum(~mask[: t.n_samples - h]))
    reached = [h for h in horizons if per["model"][h]["rms"]]
    n_ticks = ticks[max(reached)] if reached else 0  # the longest horizon scored's (a shorter one's are more)
    if not reached:  # (the table's best-of and the gains need one score)
        longest = max(lt.trial.n_samples for lt in used)
        raise ValueError(
            f"no held-out trial is long enough to score: each needs more than the model's history of "
            f"{model.window.history} samples plus a horizon of {min(horizons)}; the longest of the {len(used)} has "
            f"{longest}"
        )
    results: dict[str, dict[int, Scores]] = {}
    for p in names:
        results[p] = {}
        for h in horizons:
            if not per[p][h]["rms"]:
                continue
            rms, mx = np.concatenate(per[p][h]["rms"]), np.concatenate(per[p][h]["max"])
            spread = np.array(list(per_trial[p][h].values()))
            results[p][h] = {
                "e_rms": float(rms.mean()),
                "e_max_mean": float(mx.mean()),
                "e_max_max": float(mx.max()),
                "e_rms_trials": per_trial[p][h],
                "trial_median": float(np.median(spread)),
                "trial_min": float(spread.min()),
                "trial_max": float(spread.max()),
            }
    tuned = model.info.get("baselines", {})
    ridge_info = (
        None
        if model.ridge is None
        else {
            "alpha": model.ridge.alpha,
            "tuned": bool(tuned.get("ridge", {}).get("tuned", False)),
        }
    )
    baselines = {
        "ridge": ridge_info,
        "constant_acceleration": kalman.to_dict(),
        "protocol": tuned.get("protocol", "untuned (the model records no baseline tuning)"),
    }
    return ModelEvaluation(
        trials=tuple(lt.id for lt in used),
        skipped=tuple(skipped),
        copies=tuple(copies),
        against=against,
        n_ticks=n_ticks,
        horizons=tuple(horizons),
        dt=model.dt,
        baselines=baselines,
        results=results,
        best_baseline=best_baselines(results, horizons),
    )


def is_evaluation_file(path: Path) -> bool:
    """Whether ``path`` holds an evaluation record (``coassist evaluate``'s JSON: :meth:`ModelEvaluation.to_dict`
    and the model), which a new evaluation may replace; any other file (a trial, a sidecar, a figure) is not."""
    return json_object_with(path, ("trials", "results", "best_baseline", "model"))


def records_intent(trial) -> bool:
    """Whether ``trial`` records the person's true intent (a simulated trial's; a recording or an arm's has none)."""
    return trial.intent is not None and bool(np.isfinite(trial.intent).any())


def scoring_target(label: str, trials: Sequence[LabeledTrial], against: str | None) -> tuple[str, str]:
    """(what a model of window label ``label`` is scored against on ``trials``, a line to say or ""): ``against``
    where given, else what the model predicts where every trial records it (an intent model on simulated trials:
    ``"intent"``), else ``"tool"``; the line says where a model of another label is scored against the tool."""
    if against is None:
        against = "intent" if label == "intent" and all(records_intent(lt.trial) for lt in trials) else "tool"
    if against != "tool" or label == "tool":
        return against, ""
    what = "the person's intent" if label == "intent" else "the path the person alone would take"
    why = "" if label == "intent" else " (a target that is not one path of the trial: not scored here)"
    return (
        against,
        f"the model predicts {what} (label {label!r}){why}; its rows are scored against the tool's path here",
    )


def _intent_of(lt: LabeledTrial) -> np.ndarray:
    """The true intent of ``lt``'s trial, (T, d) [m]: what ``against="intent"`` scores against."""
    intent = lt.trial.intent
    if not records_intent(lt.trial):
        raise ValueError(
            f"trial {lt.id} records no intent (a recording or an arm's trial: only simulated trials know the "
            "person's intent); score against the tool's path there"
        )
    return np.asarray(intent, dtype=np.float64)


def best_baselines(
    results: Mapping[str, Mapping[int, Scores]], horizons: Sequence[int], model: str = "model"
) -> dict[int, dict[str, Any]]:
    """Per horizon: the baseline with the lowest pooled e_RMS and how the model compares.

    ``results`` is :attr:`ModelEvaluation.results`. Returns ``{N: {"name", "e_rms",
    "model_e_rms", "gain", "trials_model_better", "n_trials"}}``; ``gain`` = (e_best −
    e_model) / e_best (> 0: the model is better), ``trials_model_better`` counts trials
    whose own e_RMS is lower for the model.
    """
    res = results
    out: dict[int, dict[str, Any]] = {}
    for h in horizons:
        cands = [(res[b][h]["e_rms"], b) for b in BASELINES if b in res and h in res[b]]
        if not cands or h not in res.get(model, {}):
            continue
        best_e, best = min(cands)
        me = res[model][h]["e_rms"]
        mt, bt = res[model][h]["e_rms_trials"], res[best][h]["e_rms_trials"]
        common = [k for k in mt if k in bt]
        out[h] = {
            "name": best,
            "e_rms": best_e,
            "model_e_rms": me,
            "gain": (best_e - me) / best_e if best_e > 0 else 0.0,
            "trials_model_better": sum(mt[k] < bt[k] for k in common),
            "n_trials": len(common),
        }
    return out


def _baseline_label(result: ModelEvaluation, name: str) -> str:
    info = result.baselines
    if name == "ridge" and info.get("ridge"):
        r = info["ridge"]
        return f"ridge (α = {r['alpha']:.0e}, {'tuned on validation trials' if r['tuned'] else 'not tuned'})"
    if name == "constant_acceleration" and info.get("constant_acceleration"):
        k = info["constant_acceleration"]
        return (
            f"constant acceleration (Kalman, q = {k['jerk_psd']:.0e} m²/s⁵, r_v = {k['velocity_noise']:.0e} m/s, "
            f"{'tuned on validation trials' if k['tuned'] else 'not tuned'})"
        )
    return name.replace("_", " ")


def _mm(metres: float) -> str:
    """Metres as millimetres to three significant digits (errors span 0.005 mm at 0.04 s to mm at 0.4 s)."""
    return f"{1e3 * metres:.3g}"


def comparison_lines(result: ModelEvaluation, model: str = "model") -> list[str]:
    """One line per horizon: the best baseline, its e_RMS, and the model's gain over it, in mm and %. ``model``: what
    the lines call the model (its scores are :func:`evaluate_model`'s ``"model"`` whatever it is called)."""
    dt = result.dt
    lines = []
    for h, b in best_baselines(result.results, result.horizons).items():
        diff = 1e3 * (b["e_rms"] - b["model_e_rms"])
        verdict = "better" if diff > 0 else "worse" if diff < 0 else "equal"
        lines.append(
            f"{h * dt:.2f} s: best baseline {_baseline_label(result, b['name'])} e_RMS {_mm(b['e_rms'])} mm; "
            f"{model} {_mm(b['model_e_rms'])} mm: {abs(100 * b['gain']):.1f} % {verdict} ({diff:+.3g} mm), "
            f"{model} better on {b['trials_model_better']} of {b['n_trials']} trials"
        )
    return lines


def results_table(result: ModelEvaluation, title: str = "") -> Any:
    """A rich Table: predictors × e_RMS per horizon with its per-trial range, and mean e_MAX, in mm."""
    from rich.table import Table

    hs = result.horizons
    dt = result.dt
    table = Table(
        title=(title or f"held-out trials: {len(result.trials)}, ticks scored: {result.n_ticks}")
        + " — errors in mm; e_RMS pooled over ticks (min–max over trials)"
    )
    table.add_column("predictor")
    for h in hs:
        table.add_column(f"e_RMS {h * dt:.2f}s [mm]", justify="right")
    for h in hs:
        table.add_column(f"e_MAX {h * dt:.2f}s [mm]", justify="right")
    # a horizon no held-out trial was long enough for has no best (a row's cell says "–")
    best = {h: min((r[h]["e_rms"] for r in result.results.values() if h in r), default=math.inf) for h in hs}
    for p, r in result.results.items():
        cells = []
        for h in hs:
            if h not in r:
                cells.append("–")
                continue
            s = f"{_mm(r[h]['e_rms'])} ({_mm(r[h]['trial_min'])}–{_mm(r[h]['trial_max'])})"
            cells.append(f"[bold]{s}[/]" if r[h]["e_rms"] == best[h] else s)
        cells += ["–" if h not in r else _mm(r[h]["e_max_mean"]) for h in hs]
        table.add_row(p, *cells)
    return table
