"""Thesis §5.2.4 indexes against numbers worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coassist.metrics import (
    HORIZONS,
    distance_to_target,
    e_max,
    e_rms,
    f_rms,
    jerk_rms,
    overshoot,
    peak_effort_ratio,
    precision_sigma,
    prediction_errors,
    prediction_errors_by_horizon,
    time_to_target,
    tracking_error_rms,
)

GARBAGE = 1e3  # predictions that must never be scored


def hand_example():
    """T = 4, d = 2, H = 2. pred[k, i-1] is for tick k+i.

    k=0: step 1 off by (3, 4) -> 5, step 2 exact -> 0
    k=1: step 1 off by (1, 0) -> 1, step 2 off by (0, -2) -> 2
    k=2: step 1 off by (0, 0.5) -> 0.5, step 2 would be tick 4 (does not exist)
    """
    pose = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    pred = np.full((4, 2, 2), GARBAGE)
    pred[0, 0] = [4.0, 4.0]
    pred[0, 1] = [1.0, 1.0]
    pred[1, 0] = [2.0, 1.0]
    pred[1, 1] = [0.0, -1.0]
    pred[2, 0] = [0.0, 1.5]
    return pred, pose


def test_hand_example_horizon_2():
    pred, pose = hand_example()
    errs = prediction_errors(pred, pose, 2)
    np.testing.assert_array_equal(errs.tick, [0, 1])  # k + 2 < 4
    np.testing.assert_allclose(errs.rms, [math.sqrt(12.5), math.sqrt(2.5)], rtol=1e-15)
    np.testing.assert_allclose(errs.max, [5.0, 2.0], rtol=1e-15)
    assert e_rms(pred, pose, 2) == pytest.approx((3.5355339059327378 + 1.5811388300841898) / 2, rel=1e-14)
    assert e_max(pred, pose, 2) == (pytest.approx(3.5, rel=1e-14), pytest.approx(5.0, rel=1e-14))


def test_intent_error_scores_against_the_intent_not_the_tool():
    """The tool sits still at the origin; the intent moves 1 m per tick along x. The prediction
    (the intent itself, offset by (0, 0.3) m) is 0.3 m from the intent at every step and
    far from the tool. By hand, H = 2: e_int = 0.3 m at each of the two scored ticks."""
    tool = np.zeros((4, 2))
    intent = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    pred = np.full((4, 2, 2), GARBAGE)
    for k in range(2):
        pred[k] = intent[k + 1 : k + 3] + [0.0, 0.3]
    assert e_rms(pred, intent, 2) == pytest.approx(0.3, rel=1e-14)  # e_RMS against the intent
    # Against the tool the same prediction is off by sqrt(mean(|(k+i, 0.3)|²)) at tick k:
    # k=0: sqrt((1.09 + 4.09) / 2), k=1: sqrt((4.09 + 9.09) / 2).
    by_hand = (math.sqrt(2.59) + math.sqrt(6.59)) / 2
    assert e_rms(pred, tool, 2) == pytest.approx(by_hand, rel=1e-14)


def test_hand_example_horizon_1():
    pred, pose = hand_example()
    errs = prediction_errors(pred, pose, 1)
    np.testing.assert_array_equal(errs.tick, [0, 1, 2])
    assert e_rms(pred, pose, 1) == pytest.approx(6.5 / 3, rel=1e-14)
    result = e_max(pred, pose, 1)
    assert result.mean == pytest.approx(6.5 / 3, rel=1e-14) and result.max == pytest.approx(5.0, rel=1e-14)


def test_nan_prediction_ticks_are_skipped():
    pred, pose = hand_example()
    pred[1] = np.nan  # no prediction at tick 1
    errs = prediction_errors(pred, pose, 2)
    np.testing.assert_array_equal(errs.tick, [0])
    assert e_rms(pred, pose, 2) == pytest.approx(math.sqrt(12.5), rel=1e-14)
    pred[0] = np.nan
    with pytest.raises(ValueError, match="no tick has a finite prediction"):
        e_rms(pred, pose, 2)


@pytest.mark.parametrize("horizon", [1, 5, 20, 50])
def test_constant_offset_1d(horizon):
    """A 1-D prediction offset by c from the measured future gives e_RMS = e_MAX = c."""
    c = 0.037
    t, h = 120, 50
    rng = np.random.default_rng(horizon)
    pose = np.cumsum(rng.normal(size=t)) * 0.01
    pred = np.full((t, h), GARBAGE)
    for k in range(t):
        for i in range(1, h + 1):
            if k + i < t:
                pred[k, i - 1] = pose[k + i] + c
    assert e_rms(pred, pose, horizon) == pytest.approx(c, rel=1e-12)
    assert e_max(pred, pose, horizon) == (pytest.approx(c, rel=1e-12), pytest.approx(c, rel=1e-12))
    assert len(prediction_errors(pred, pose, horizon).tick) == t - horizon


def test_matches_a_naive_loop():
    rng = np.random.default_rng(3)
    t, h, d, n = 40, 8, 3, 6
    pose = rng.normal(size=(t, d))
    pred = rng.normal(size=(t, h, d))
    rms, mx = [], []
    for k in range(t):
        if k + n >= t:
            continue
        e = [math.sqrt(sum((pred[k, i - 1, j] - pose[k + i, j]) ** 2 for j in range(d))) for i in range(1, n + 1)]
        rms.append(math.sqrt(sum(x * x for x in e) / n))
        mx.append(max(e))
    assert e_rms(pred, pose, n) == pytest.approx(sum(rms) / len(rms), rel=1e-13)
    assert e_max(pred, pose, n) == (pytest.approx(sum(mx) / len(mx), rel=1e-13), pytest.approx(max(mx), rel=1e-13))


def test_horizons():
    assert HORIZONS == (5, 10, 20, 50)
    assert [round(n * 0.008, 3) for n in HORIZONS] == [0.04, 0.08, 0.16, 0.4]


@pytest.mark.parametrize(
    "pred_shape, pose_shape, horizon, message",
    [
        ((10, 5, 2), (10, 2), 6, r"between 1 and the prediction's H = 5"),
        ((10, 5, 2), (10, 2), 0, r"between 1"),
        ((10, 5, 2), (10, 2), True, r"integer"),
        ((10, 5, 2), (10, 2), 2.0, r"integer"),
        ((10, 5, 3), (10, 2), 2, r"prediction has shape \(10, 5, 3\), expected \(10, H, 2\)"),
        ((9, 5, 2), (10, 2), 2, r"expected \(10, H, 2\)"),
        ((4, 5, 2), (4, 2), 4, r"4 samples is too short for a horizon of 4"),
    ],
)
def test_prediction_errors_validation(pred_shape, pose_shape, horizon, message):
    with pytest.raises(ValueError, match=message):
        prediction_errors(np.zeros(pred_shape), np.zeros(pose_shape), horizon)


def test_prediction_errors_rejects_bad_pose():
    pose = np.zeros((10, 2))
    pose[3, 1] = np.nan
    with pytest.raises(ValueError, match="pose has non-finite"):
        e_rms(np.zeros((10, 5, 2)), pose, 2)


def test_f_rms_hand_values():
    assert f_rms([[3.0, 4.0], [0.0, 0.0], [6.0, 8.0]]) == pytest.approx(5.0, rel=1e-15)  # (5 + 0 + 10) / 3
    assert f_rms([[3.0, 4.0, 100.0], [6.0, -8.0, -7.0]], axes=(0, 1)) == pytest.approx(7.5, rel=1e-15)
    assert f_rms([-2.0, 2.0, 5.0]) == pytest.approx(3.0, rel=1e-15)
    with pytest.raises(ValueError, match="axes"):
        f_rms(np.zeros((3, 2)), axes=(0, 2))
    with pytest.raises(ValueError, match="wrench has non-finite"):
        f_rms([[np.nan, 1.0]])


def test_distance_to_target():
    np.testing.assert_allclose(distance_to_target([[4.0, 5.0], [1.0, 1.0]], [1.0, 1.0]), [5.0, 0.0], rtol=1e-15)
    with pytest.raises(ValueError, match=r"target has shape \(3,\), expected \(2,\)"):
        distance_to_target(np.zeros((2, 2)), [0.0, 0.0, 0.0])


def test_sigma_hand_values():
    # dt = 1 s, tau = 3 s -> 3 samples from the first one inside the ball (|x| <= 0.025)
    pose = np.array([1.0, 0.5, 0.02, 0.01, 0.03, 0.0, 0.2])[:, None]
    assert precision_sigma(pose, [0.0], 1.0, tau=3.0) == pytest.approx(0.02, rel=1e-14)  # (0.02+0.01+0.03)/3
    # leaving the ball afterwards still counts (the mean is over tau after first entry)
    assert precision_sigma(pose, [0.0], 1.0, tau=5.0) == pytest.approx(0.26 / 5, rel=1e-14)
    # fewer than tau seconds left: average over what remains
    assert precision_sigma(pose[:4], [0.0], 1.0, tau=3.0) == pytest.approx(0.015, rel=1e-14)
    # never inside the ball
    assert math.isnan(precision_sigma(pose[:2], [0.0], 1.0))
    assert math.isnan(time_to_target(pose[:2], [0.0], 1.0))
    # the ball is closed: exactly epsilon is inside
    assert precision_sigma([[0.1], [0.025], [0.0]], [0.0], 1.0, tau=2.0) == pytest.approx(0.0125, rel=1e-14)


def test_sigma_2d_and_time_to_target():
    pose = np.array([[4.0, 5.0], [1.01, 1.0], [1.0, 1.02], [3.0, 3.0]])
    assert precision_sigma(pose, [1.0, 1.0], 0.5, tau=1.0) == pytest.approx(0.015, rel=1e-12)
    assert time_to_target(pose, [1.0, 1.0], 0.5) == 0.5
    # a larger epsilon enters earlier
    assert time_to_target(pose, [1.0, 1.0], 0.5, epsilon=10.0) == 0.0


def test_sigma_thesis_window_is_375_samples():
    """dt = 8 ms, tau = 3 s: exactly 375 samples from the first entry."""
    dist = np.full(1000, 0.5)
    dist[10:385] = 0.01  # 375 samples at 1 cm
    dist[385:] = 0.02  # would pull the mean up if a 376th sample were used
    pose = np.column_stack([dist, np.zeros_like(dist)])
    assert precision_sigma(pose, [0.0, 0.0], 0.008) == pytest.approx(0.01, rel=1e-12)
    assert time_to_target(pose, [0.0, 0.0], 0.008) == pytest.approx(0.08, rel=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"dt": 0.0}, "dt"),
        ({"dt": 0.008, "epsilon": -1.0}, "epsilon"),
        ({"dt": 0.008, "tau": float("nan")}, "tau"),
    ],
)
def test_sigma_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        precision_sigma(np.zeros((5, 2)), [0.0, 0.0], **kwargs)


# --------------------------------------------------------------------------- smoothness and stability


def test_jerk_of_a_cubic_is_six_times_its_coefficient():
    dt = 0.01
    t = np.arange(50) * dt
    pose = np.stack([2.0 * t**3 + t, -0.5 * t**3], axis=1)  # jerk (12, −3): norm sqrt(153)
    assert jerk_rms(pose, dt) == pytest.approx(math.sqrt(153.0), rel=1e-6)
    # a straight line at constant speed has no jerk
    assert jerk_rms(np.stack([t, 2 * t], axis=1), dt) == pytest.approx(0.0, abs=1e-6)


def test_jerk_rms_is_the_rms_over_the_third_differences():
    dt = 0.5
    # differences: [0, 0, 1, −1] → [0, 1, −2] → third [1, −3]; /dt³ = 8, −24
    pose = np.array([0.0, 0.0, 0.0, 1.0, 0.0])
    assert jerk_rms(pose, dt) == pytest.approx(math.sqrt((8.0**2 + 24.0**2) / 2))
    with pytest.raises(ValueError, match="at least 4 samples"):
        jerk_rms(np.zeros((3, 2)), dt)


def test_overshoot_of_a_step_response():
    # intent steps from 0 to 1 at k = 10; the tool rises, peaks at 1.25 and settles at 1
    intent = np.r_[np.zeros(10), np.ones(40)]
    tool = np.r_[np.zeros(10), np.linspace(0.2, 1.25, 10), np.linspace(1.25, 1.0, 10), np.ones(20)]
    assert overshoot(tool, intent) == pytest.approx(0.25)
    # the same step downwards: the tool undershoots to −1.25
    assert overshoot(-tool, -intent) == pytest.approx(0.25)
    # a tool that never passes the intent has none
    assert overshoot(np.minimum(tool, 1.0), intent) == 0.0


def test_overshoot_at_each_turn_of_a_back_and_forth_intent():
    # intent: 0 → 2 (k 0–20), back to 0.5 (k 20–40), rests; the tool passes 2 by 0.1 and 0.5 by 0.3
    intent = np.r_[np.linspace(0, 2, 21), np.linspace(2, 0.5, 21)[1:], np.full(20, 0.5)]
    tool = intent.copy()
    tool[22] = 2.1  # past the maximum, while the intent is already coming back
    tool[45] = 0.2  # past the final rest, below it
    y = np.zeros_like(intent)
    pose, ref = np.stack([tool, y], axis=1), np.stack([intent, y], axis=1)
    assert overshoot(pose, ref) == pytest.approx(0.3)
    tool[45] = 0.5
    assert overshoot(np.stack([tool, y], axis=1), ref) == pytest.approx(0.1)
    # turns of the intent smaller than tol are not turns: a 0.5 mm ripple is ignored
    ripple = np.r_[np.linspace(0, 1, 20), np.full(5, 0.9995), np.ones(20)]
    assert overshoot(ripple + 0.0003, ripple, tol=1e-3) == pytest.approx(0.0003)


def test_tracking_error_and_peak_effort_ratio_by_hand():
    pose = np.array([[0.0, 0.0], [3.0, 4.0]])
    intent = np.zeros((2, 2))
    assert tracking_error_rms(pose, intent) == pytest.approx(math.sqrt(25.0 / 2))
    u_r = np.array([[3.0, 4.0], [0.0, 1.0]])  # peak 5
    u_h = np.array([[0.0, 2.0], [1.0, 0.0]])  # peak 2
    assert peak_effort_ratio(u_r, u_h) == pytest.approx(2.5)
    assert math.isnan(peak_effort_ratio(u_r, np.zeros((2, 2))))
    with pytest.raises(ValueError, match="intent has shape"):
        tracking_error_rms(pose, np.zeros((3, 2)))


def test_clearance_against_hand_computation():
    from coassist.metrics import clearance, clearance_deficit

    center, size = (0.5, 0.0), (0.1, 0.2)  # the box spans x 0.45…0.55, y −0.1…0.1
    # passing above the box 5 cm up: the nearest point of the path is (0.5, 0.15) → 0.05 m
    above = np.stack([np.linspace(0, 1, 101), np.full(101, 0.15)], axis=1)
    assert clearance(above, center, size) == pytest.approx(0.05, abs=1e-15)
    # a single point diagonally off a corner: 3-4-5 triangle from (0.55, 0.1)
    assert clearance([[0.58, 0.14]], center, size) == pytest.approx(0.05, abs=1e-15)
    # inside, 2 cm from the nearest face (x = 0.55): −0.02
    assert clearance([[0.53, 0.0]], center, size) == pytest.approx(-0.02, abs=1e-15)
    # the tool 1 cm closer than the intent at its nearest point: deficit +0.01; farther: negative
    closer = above - [0.0, 0.01]
    assert clearance_deficit(closer, above, center, size) == pytest.approx(0.01, abs=1e-15)
    assert clearance_deficit(above, closer, center, size) == pytest.approx(-0.01, abs=1e-15)
    with pytest.raises(ValueError, match="size"):
        clearance(above, center, (0.1, 0.0))


@pytest.mark.parametrize(("t", "h", "d"), [(200, 50, 2), (70, 50, 1), (61, 50, 3), (30, 8, 2)])
def test_prediction_errors_by_horizon_are_prediction_errors_bit_for_bit(t, h, d):
    """Every horizon's ticks, RMS and max equal the one-horizon function's exactly (the same float operations on
    the same elements), float32 predictions with NaN rows (unscored ticks) and a NaN inside one row included."""
    rng = np.random.default_rng(t + h + d)
    pose = np.cumsum(rng.normal(0, 1e-3, (t, d)), axis=0)
    pred = (pose[:, None, :] + rng.normal(0, 2e-3, (t, h, d))).astype(np.float32)
    pred[:5] = np.nan  # the history not yet full
    pred[t // 2, h // 2] = np.nan  # one step of one tick: scored at the shorter horizons only
    horizons = [k for k in (5, 10, 20, 50, h) if k <= h and k < t]
    got = prediction_errors_by_horizon(pred, pose, horizons)
    assert sorted(got) == sorted(set(horizons))
    for k in horizons:
        want = prediction_errors(pred, pose, k)
        for field in ("tick", "rms", "max"):
            assert np.array_equal(getattr(got[k], field), getattr(want, field)), (k, field)


def test_prediction_errors_by_horizon_refuse_what_prediction_errors_refuses():
    pose = np.zeros((20, 2))
    with pytest.raises(ValueError, match="too short for a horizon of 20"):
        prediction_errors_by_horizon(np.zeros((20, 30, 2)), pose, [5, 20])
    with pytest.raises(ValueError, match="between 1 and the prediction's H = 10"):
        prediction_errors_by_horizon(np.zeros((20, 10, 2)), pose, [5, 11])
    with pytest.raises(ValueError, match="no tick has a finite prediction over the first 5 steps"):
        prediction_errors_by_horizon(np.full((20, 10, 2), np.nan), pose, [5])
    assert prediction_errors_by_horizon(np.zeros((20, 10, 2)), pose, []) == {}
