"""The parameterisation study: each variant is trained as labelled, and scored on the same ticks."""

from __future__ import annotations

import pytest

pytest.importorskip("torch")

from coassist.experiments import parameterisation as par  # noqa: E402
from coassist.intent import evaluate_model, train_model  # noqa: E402

from ..intent.conftest import TINY, labeled  # noqa: E402


def test_variants_are_trained_as_labelled_and_scored_like_evaluate(monkeypatch):
    seen = []
    real_train = train_model

    def spy(trials, preset, config, **kw):
        seen.append((preset.window.input_frame, preset.window.target, preset.skip, config.mirror, config.train_stride))
        return real_train(trials, preset, config, **kw)

    monkeypatch.setattr("coassist.intent.train_model", spy)
    trials = labeled(5)
    labels = ["thesis: absolute in / absolute out", "+ mirror augmentation (the lstm preset)"]
    result = par.compare_parameterisations(
        trials, TINY, variants=labels, epochs=1, threads=1, train_stride=3, say=lambda m: None
    )
    assert seen == [("absolute", "absolute", False, False, 3), ("relative", "residual", True, True, 3)]
    assert [r["variant"] for r in result["rows"]] == labels
    # the last row is the default-preset variant: its numbers are evaluate_model's on the held-out trials
    from dataclasses import replace

    w, p, t = par.VARIANTS[labels[-1]]
    preset = replace(
        TINY,
        window=replace(TINY.window, **w),
        **p,
        train=replace(TINY.train, epochs=1, threads=1, train_stride=3, seed=0, **t),
    )
    ev = evaluate_model(real_train(trials, preset, preset.train), trials)
    for h, v in ev.results["model"].items():
        assert result["rows"][-1]["e_rms"][int(h)] == pytest.approx(v["e_rms"], rel=1e-12)
    ridge = next(b for b in result["baselines"] if b["predictor"] == "ridge")
    assert ridge["e_rms"][10] == pytest.approx(ev.results["ridge"][10]["e_rms"], rel=1e-12)
    text = par.markdown(result, "T")
    assert text.count("\n| ") == len(result["rows"]) + len(result["baselines"]) + 1  # rows + header
