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
    assert set(res.trials).isdisjoint(model.info["train_trials"]) and res.skipped
    assert res.horizons == (5, 10)  # horizons beyond the model's 10 samples are dropped
    assert set(res.results) == {"model", "nominal", "constant_velocity", "constant_acceleration", "ridge"}
    # Hand check of constant velocity's e_RMS on the scored ticks of the held-out trial.
    lt = next(lt for lt in trials if lt.id in res.trials)
    t = lt.trial
    ks = np.arange(tiny.window.history - 1, t.n_samples - 5)
    err = [
        np.sqrt(
            np.mean(
                np.sum(
                    (t.pose[k] + np.outer(np.arange(1, 6) * 0.008, t.velocity[k]) - t.pose[k + 1 : k + 6]) ** 2, axis=1
                )
            )
        )
        for k in ks
    ]
    assert res.results["constant_velocity"][5]["e_rms"] == pytest.approx(np.mean(err), rel=1e-12)
    with pytest.raises(ValueError, match="nothing held out"):
        evaluate_model(model, [lt for lt in trials if lt.id in model.info["train_trials"]])


def test_scaler_is_immutable():
    s = Scaler([0.0], [1.0])
    with pytest.raises(ValueError):
        s.lo[0] = 3.0
    assert isinstance(LabeledTrial("a", "b", line_trial()), tuple)


# ----------------------------------------------------------------------------- tuned baselines


def _validation_mse_by_hand(ridge, ws):
    """Mean over windows of Σ_i ||x̂(k+i) − x(k+i)||² / H, positions decoded independently."""
    from coassist.intent.features import decode_target, unscale_targets

    sel = np.arange(len(ws))
    out = ridge.predict_scaled(ridge.input_scaler.transform(ws.raw_inputs(sel)))
    pose, vel = ws.anchors(sel)
    h, d = ws.window.horizon, ws.n_dof
    pred = decode_target(unscale_targets(ridge.target_scaler, out, h, d), pose, vel, ws.window, ws.dt)
    return float(np.mean(np.sum((pred - ws.future(sel)) ** 2, axis=2)))


def test_tuned_ridge_alpha_minimises_the_validation_error_over_the_grid(trials):
    from coassist.intent.baselines import fit_tuned_baselines, ridge_validation_errors
    from coassist.intent.features import validation_split

    w = WindowConfig(
        history=6, decimation=2, horizon=4, input_frame="relative", target="residual", target_scaling="step"
    )
    ids = [lt.id for lt in trials]
    tr = [lt.trial for lt in trials]
    sin, sout = WindowSet(tr, w, 0.008).fit_scalers()
    alphas = (1e-6, 1e-3, 1e-1, 1.0, 10.0, 1e3)
    fit_idx, val_idx = validation_split(ids, seed=3)
    fit_ws = WindowSet([tr[i] for i in fit_idx], w, 0.008)
    val_ws = WindowSet([tr[i] for i in val_idx], w, 0.008)
    # Independent: a fresh closed-form ridge per α (tested above against lstsq), scored by hand.
    by_hand = np.array([_validation_mse_by_hand(RidgeBaseline.fit(fit_ws, sin, sout, a), val_ws) for a in alphas])
    fast = ridge_validation_errors(fit_ws, val_ws, sin, sout, alphas)
    # Tolerance from conditioning: the two paths (one eigendecomposition for every α against a
    # fresh solve) each give W to a relative κ_α·ε, κ_α = (λ_max + α)/(λ_min + α) of the centred
    # X'X (2e9 at α = 1e-6 here), and the length-p products X·W add p·ε. That moves a prediction
    # by δ ≈ (κ_α + p)·ε·rms(target) and the MSE by 2·δ·sqrt(MSE) + δ², relative 2·δ/sqrt(MSE)
    # (3.7e-4 at α = 1e-6, where the fit is nearly exact: MSE 2e-15 m²). A floor of n·ε covers
    # the sums over the n validation windows. A wrong α or decoding is off by ≫ 1 %.
    sel = np.arange(len(fit_ws))
    X = sin.transform(fit_ws.raw_inputs(sel)).reshape(len(fit_ws), -1)
    lam = np.linalg.svd(X - X.mean(axis=0), compute_uv=False) ** 2
    eps = np.finfo(float).eps
    delta = np.array([(lam.max() + a) / (lam.min() + a) + X.shape[1] for a in alphas]) * eps
    delta *= np.sqrt(np.mean(val_ws.raw_targets(np.arange(len(val_ws))) ** 2))
    rtol = 10 * (2 * delta / np.sqrt(by_hand) + (delta / np.sqrt(by_hand)) ** 2) + len(val_ws) * eps
    assert np.all(np.abs(fast - by_hand) <= rtol * by_hand), (fast, by_hand, rtol)
    assert by_hand.max() > 1.5 * by_hand.min()  # the grid matters on these trials
    ridge, kalman, record = fit_tuned_baselines(tr, ids, w, 0.008, sin, sout, seed=3, stride=1)
    assert record["validation_trials"] == [ids[i] for i in val_idx] and record["ridge"]["tuned"]
    # the default grid includes the hand grid's best neighbourhood; re-check its argmin independently
    grid = record["ridge"]["alphas"]
    hand_full = [_validation_mse_by_hand(RidgeBaseline.fit(fit_ws, sin, sout, a), val_ws) for a in grid]
    assert ridge.alpha == grid[int(np.argmin(hand_full))]
    refit = RidgeBaseline.fit(WindowSet(tr, w, 0.008), sin, sout, ridge.alpha)  # refitted on all training windows
    np.testing.assert_allclose(ridge.W, refit.W, rtol=1e-10, atol=1e-12)  # the same solve on the same windows
    assert kalman.tuned and {ids[i] for i in val_idx}.isdisjoint(record["fit_trials"])


def test_fixed_ridge_alpha_and_single_trial_are_recorded_untuned(trials):
    from coassist.intent.baselines import fit_tuned_baselines

    w = WindowConfig(history=6, decimation=2, horizon=4, input_frame="relative", target="relative")
    tr, ids = [lt.trial for lt in trials], [lt.id for lt in trials]
    sin, sout = WindowSet(tr, w, 0.008).fit_scalers()
    ridge, _, rec = fit_tuned_baselines(tr, ids, w, 0.008, sin, sout, seed=0, alpha=0.3)
    assert ridge.alpha == 0.3 and not rec["ridge"]["tuned"]
    ridge, kalman, rec = fit_tuned_baselines(tr[:1], ids[:1], w, 0.008, sin, sout, seed=0, fallback_alpha=2.0)
    assert ridge.alpha == 2.0 and not rec["ridge"]["tuned"] and not kalman.tuned


def test_kalman_first_update_matches_the_hand_computation():
    from coassist.intent.kalman import KalmanCA, kalman_ca_filter

    # dt = 1, r_p = r_v = σ_a0 = 1, q ≈ 0: P⁻ = F F' = [[2.25, 1.5, .5], [1.5, 2, 1], [.5, 1, 1]],
    # S = P⁻[:2, :2] + I, K = P⁻ H' S⁻¹ = [[.6, .2], [.2, 17/30], [0, 1/3]]; from s0 = 0 and
    # z1 = (p, v) = (1, 3): ŝ1 = K z1 = (1.2, 1.9, 1.0).
    k = KalmanCA(jerk_psd=1e-12, velocity_noise=1.0, position_noise=1.0, initial_acceleration=1.0)
    pose = np.array([[0.0], [1.0]])
    vel = np.array([[0.0], [3.0]])
    s = kalman_ca_filter(pose, vel, 1.0, [k])[0]
    np.testing.assert_allclose(s[1, :, 0], [1.2, 1.9, 1.0], atol=1e-9)
    # x̂(k+i) = p + i v + i²/2 a: 1.2 + 1.9 + 0.5 = 3.6 and 1.2 + 3.8 + 2.0 = 7.0
    np.testing.assert_allclose(k.predict(pose, vel, 2, 1.0)[1, :, 0], [3.6, 7.0], atol=1e-9)


def test_kalman_filter_equals_the_textbook_recursion_whatever_ran_before():
    """The gains are computed once per (dt, parameters) and reused (a memo of a data-free
    recursion): trials of any length, in any order, filter exactly as the textbook loop that
    updates P alongside the state."""
    from coassist.intent import kalman
    from coassist.intent.kalman import KalmanCA, kalman_ca_filter

    params = [KalmanCA(jerk_psd=3.0, velocity_noise=0.02), KalmanCA(jerk_psd=50.0, velocity_noise=0.005)]
    dt = 0.008

    def textbook(pose, vel):
        F, Q1 = kalman._model(dt)
        H = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        out = []
        for p in params:
            R = np.diag([p.position_noise**2, p.velocity_noise**2])
            P = np.diag([p.position_noise**2, p.velocity_noise**2, p.initial_acceleration**2])
            s = np.stack([pose[0], vel[0], np.zeros(pose.shape[1])])
            rows = [s]
            for k in range(1, len(pose)):
                s, P = F @ s, F @ P @ F.T + p.jerk_psd * Q1
                K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
                s = s + K @ (np.stack([pose[k], vel[k]]) - H @ s)
                P = (np.eye(3) - K @ H) @ P @ (np.eye(3) - K @ H).T + K @ R @ K.T
                rows.append(s)
            out.append(np.array(rows))
        return np.array(out)

    rng = np.random.default_rng(4)
    kalman._GAIN_MEMO.clear()
    for n in (40, 300, 7, 301):  # shorter after longer: the memo's prefix; longer: it grows
        pose = np.cumsum(rng.normal(size=(n, 2)), axis=0) * 1e-3
        vel = rng.normal(size=(n, 2)) * 1e-2
        # different operation order from the vectorised filter: agreement to rounding of O(1) mm states
        np.testing.assert_allclose(kalman_ca_filter(pose, vel, dt, params), textbook(pose, vel), rtol=1e-9, atol=1e-12)


def test_kalman_constant_acceleration_is_exact_on_a_parabola():
    from coassist.intent.kalman import KalmanCA

    dt, n = 0.008, 600
    t = np.arange(n) * dt
    a = np.array([0.3, -0.8])
    pose = np.array([0.1, 0.2]) + np.outer(t, [0.05, 0.02]) + 0.5 * np.outer(t**2, a)
    vel = np.array([0.05, 0.02]) + np.outer(t, a)
    pred = KalmanCA(jerk_psd=1.0, velocity_noise=1e-3).predict(pose, vel, 50, dt)
    k = 500  # long after the filter's transient: the parabola is a noise-free path of the model
    truth = pose[k] + np.outer(dt * np.arange(1, 51), vel[k]) + 0.5 * np.outer((dt * np.arange(1, 51)) ** 2, a)
    np.testing.assert_allclose(pred[k], truth, atol=1e-7)
    # constant velocity misses the curvature by a/2 τ² at 0.4 s: 0.5·0.8·0.16 = 64 mm on y
    assert abs((pose[k, 1] + 0.4 * vel[k, 1]) - truth[-1, 1]) == pytest.approx(0.064, rel=1e-9)


@pytest.mark.parametrize("horizon", [10, 50])
def test_kalman_tuning_picks_the_grid_minimum(trials, horizon):
    from coassist.intent.kalman import KalmanCA, tune_kalman

    qs, rvs = (1e-1, 1e2, 1e5), (1e-4, 1e-2)
    tr = [lt.trial for lt in trials[:2]]
    best, rec = tune_kalman(tr, horizon, 0.008, first_tick=19, jerk_psd_grid=qs, velocity_noise_grid=rvs)
    by_hand = {}
    for q in qs:
        for rv in rvs:
            sse, n = 0.0, 0
            for t in tr:
                p = KalmanCA(q, rv, tuned=True).predict(t.pose, t.velocity, horizon, 0.008)
                for k in range(19, t.n_samples - horizon):
                    sse += np.sum((p[k] - t.pose[k + 1 : k + 1 + horizon]) ** 2) / horizon
                    n += 1
            by_hand[(q, rv)] = sse / n
    # tune_kalman sums the error as a quadratic form (kalman.py), losing ~3 of 16 digits to
    # cancellation; this is the direct sum over the horizon.
    np.testing.assert_allclose(np.array(rec["validation_mse"]).ravel(), list(by_hand.values()), rtol=1e-9)
    assert (best.jerk_psd, best.velocity_noise) == min(by_hand, key=by_hand.get) and best.tuned


@pytest.mark.parametrize("first_tick", [0, 7])
def test_kalman_tuning_of_trials_of_every_length_equals_the_direct_sum(first_tick):
    """All trials are filtered at once (kalman._validation_sse); trials of different lengths,
    in no order, one too short to score and one that scores a single tick, give each grid
    point the direct sum over the horizon of KalmanCA.predict's (per-trial, matrix-product)
    filter, and the ticks counted by hand."""
    from types import SimpleNamespace

    from coassist.intent.kalman import KalmanCA, tune_kalman

    rng = np.random.default_rng(11)
    horizon, dt = 12, 0.008
    lengths = (60, first_tick + horizon, 95, first_tick + horizon + 1, 41)  # the 2nd scores nothing, the 4th one tick
    trials = [
        SimpleNamespace(
            pose=0.4 + np.cumsum(rng.normal(size=(n, 2)), axis=0) * 1e-3, velocity=rng.normal(size=(n, 2)) * 1e-2
        )
        for n in lengths
    ]
    qs, rvs = (1e-1, 1e3), (1e-4, 3e-3, 1e-2)
    _, rec = tune_kalman(trials, horizon, dt, first_tick=first_tick, jerk_psd_grid=qs, velocity_noise_grid=rvs)
    want, ticks = [], sum(max(0, n - horizon - first_tick) for n in lengths)
    for q in qs:
        for rv in rvs:
            sse = 0.0
            for t in trials:
                p = KalmanCA(q, rv, tuned=True).predict(t.pose, t.velocity, horizon, dt)
                for k in range(first_tick, t.pose.shape[0] - horizon):
                    sse += np.sum((p[k] - t.pose[k + 1 : k + 1 + horizon]) ** 2) / horizon
            want.append(sse / ticks)
    assert rec["validation_ticks"] == ticks
    # the quadratic form loses ~3 of 16 digits to cancellation (see the test above)
    np.testing.assert_allclose(np.array(rec["validation_mse"]).ravel(), want, rtol=1e-9)


def test_kalman_parameters_are_validated():
    from coassist.intent.kalman import KalmanCA

    with pytest.raises(ValueError, match="kalman.jerk_psd"):
        KalmanCA(jerk_psd=-1.0)
    with pytest.raises(ValueError, match="malformed Kalman"):
        KalmanCA.from_dict({"q": 1.0})
