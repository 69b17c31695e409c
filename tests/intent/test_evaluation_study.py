"""The multi-seed predictor study's bookkeeping (coassist.experiments.predictors), on hand-made records."""

from __future__ import annotations

import pytest

from coassist.experiments.predictors import parse_variant, summarise
from coassist.intent.evaluation import ModelEvaluation


def _record(seed, model, ridge, cv):
    def r(v):
        return {50: {"e_rms": v}}

    best = min((ridge, "ridge"), (cv, "constant_velocity"))
    ev = ModelEvaluation(
        trials=("a",),
        skipped=(),
        n_ticks=1,
        horizons=(50,),
        dt=0.008,
        baselines={},
        results={"model": r(model), "ridge": r(ridge), "constant_velocity": r(cv)},
        best_baseline={50: {"name": best[1], "gain": (best[0] - model) / best[0]}},
    )
    return {"protocol": "user-a", "variant": "lstm", "seed": seed, "evaluation": ev}


def test_summary_is_the_median_and_range_over_seeds():
    recs = [_record(0, 1.0, 2.0, 3.0), _record(1, 3.0, 2.0, 4.0), _record(2, 1.5, 1.0, 0.5)]
    rows = summarise(recs)
    model = next(r for r in rows if r["predictor"] == "model")
    assert (model["median"], model["min"], model["max"], model["n"]) == (1.5, 1.0, 3.0, 3)
    gain = next(r for r in rows if r["predictor"] == "gain")
    # per seed, over the best baseline: (2-1)/2 = 0.5, (2-3)/2 = -0.5, (0.5-1.5)/0.5 = -2
    assert gain["over_best_median"] == pytest.approx(-0.5) and gain["over_best_min"] == pytest.approx(-2.0)
    # over the ridge: 0.5, -0.5, -0.5
    assert gain["over_ridge_median"] == pytest.approx(-0.5) and gain["over_ridge_max"] == pytest.approx(0.5)
    assert gain["best_baselines"] == ["ridge", "ridge", "constant_velocity"]


def test_variants_name_a_preset_and_train_fields():
    assert parse_variant("lstm:freeze_skip=true,epochs=3") == ("lstm", {"freeze_skip": True, "epochs": 3})
    with pytest.raises(ValueError, match="unknown preset 'huge'"):
        parse_variant("huge")
    with pytest.raises(ValueError, match="'wings=2' is not field=value"):
        parse_variant("default:wings=2")
