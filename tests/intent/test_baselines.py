"""Baselines against hand-computed values, and the evaluation that uses them."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.data import Trial, TrialMeta
from coassist.intent import (
    LabeledTrial,
    RidgeBaseline,
    Scaler,
    WindowConfig,
    WindowSet,
    constant_velocity_prediction,
    evaluate_model,
    nominal_prediction,
    train_model,
)
from coassist.intent.features import scale_targets


def line_trial(n=40, dt=0.01):
    t = np.arange(n) * dt
    pose = np.stack([1.0 + 0.5 * t, -2.0 * t], axis=1)
    vel = np.tile([0.5, -2.0], (n, 1))
    meta = TrialMeta("u", "linear", "handle", "impedance", None, 0, "sim", dt)
    return Trial(meta=meta, time=t, pose=pose, velocity=vel, wrench=np.zeros_like(pose), reference=pose + [0.0, 0.1])


def test_constant_velocity_is_exact_on_a_straight_line():
    tr = line_trial()
    pred = constant_velocity_prediction(tr, 5)
    # By hand: tick 3, step 2 -> x(3) + 2·0.01·v = (1.015 + 0.01, -0.06 - 0.04).
    assert pred[3, 1] == pytest.approx([1.025, -0.10])
    for k in range(tr.n_samples - 5):
        assert np.allclose(pred[k], tr.pose[k + 1 : k + 6], atol=1e-12)


def test_nominal_is_the_reference_ahead():
    tr = line_trial()
    pred = nominal_prediction(tr, 3)
    assert np.array_equal(pred[4], tr.reference[5:8])
    assert np.array_equal(pred[-1], np.repeat(tr.reference[-1:], 3, axis=0))  # held past the end


def test_ridge_matches_the_closed_form_solve(trials):
    w = WindowConfig(history=6, decimation=2, horizon=4, input_frame="relative", target="relative")
    ws = WindowSet([lt.trial for lt in trials[:3]], w, 0.008)
    sin, sout = ws.fit_scalers()
    alpha = 0.3
    ridge = RidgeBaseline.fit(ws, sin, sout, alpha=alpha, chunk=37)  # chunking must not change the result
    sel = np.arange(len(ws))
    X = sin.transform(ws.raw_inputs(sel)).reshape(len(ws), -1)
    Y = scale_targets(sout, ws.raw_targets(sel))
    # Independent solve: augmented least squares [X 1; sqrt(alpha) I 0] [W; b] = [Y; 0].
    n, p = X.shape
    A = np.block([[X, np.ones((n, 1))], [np.sqrt(alpha) * np.eye(p), np.zeros((p, 1))]])
    B = np.vstack([Y, np.zeros((p, Y.shape[1]))])
    sol = np.linalg.lstsq(A, B, rcond=None)[0]
    assert np.allclose(ridge.W, sol[:-1], atol=1e-8)
    assert np.allclose(ridge.b, sol[-1], atol=1e-8)


def test_evaluation_scores_every_predictor_on_the_same_ticks(trials, tiny):
    model = train_model(trials, tiny, tiny.train)
    res = evaluate_model(model, trials)
    assert set(res["trials"]).isdisjoint(model.info["train_trials"]) and res["skipped"]
    assert res["horizons"] == [5, 10]  # horizons beyond the model's 10 samples are dropped
    assert set(res["results"]) == {"model", "nominal", "constant_velocity", "ridge"}
    # Hand check of constant velocity's e_RMS on the scored ticks of the held-out trial.
    lt = next(lt for lt in trials if lt.id in res["trials"])
    t = lt.trial
    ks = np.arange(tiny.window.history - 1, t.n_samples - 5)
    err = [np.sqrt(np.mean(np.sum((t.pose[k] + np.outer(np.arange(1, 6) * 0.008, t.velocity[k]) - t.pose[k + 1 : k + 6]) ** 2, axis=1))) for k in ks]
    assert res["results"]["constant_velocity"]["5"]["e_rms"] == pytest.approx(np.mean(err), rel=1e-12)
    with pytest.raises(ValueError, match="nothing held out"):
        evaluate_model(model, [lt for lt in trials if lt.id in model.info["train_trials"]])


def test_scaler_is_immutable():
    s = Scaler([0.0], [1.0])
    with pytest.raises(ValueError):
        s.lo[0] = 3.0
    assert isinstance(LabeledTrial("a", "b", line_trial()), tuple)
