"""The present estimate and the path-hypotheses filter (issue 34), against hand computations."""

import hashlib
import json

import numpy as np
import pytest

from coassist._io import write_hashed_json
from coassist.interfaces import IntentSource, TrialContext
from coassist.scenario.intent_registry import load_intent_source
from coassist.scenario.objects import get_object
from coassist.scenario.operator import deformed_path
from coassist.scenario.path_hypotheses import (
    CALIBRATION_FILE,
    ArmGuess,
    FilterSettings,
    PathHypothesesIntent,
    PersonShape,
    calibrate,
    fit_detour,
    read_calibration,
    write_calibration,
)
from coassist.scenario.tasks import Box, MotionPlanner, NominalPath, Task

DT = 0.008
# A straight path along x and a 10 × 10 cm box on it midway: the detour can be written by hand.
PATH = np.stack([np.linspace(0.0, 1.0, 2001), np.zeros(2001)], axis=1)
BOX = ((0.5, 0.0), (0.1, 0.1))


def _context(obstacles=(BOX,), user="user-0", obj="handle", n=3000):
    ref = np.zeros((n, 4))
    return TrialContext(
        dt=DT,
        horizon=50,
        start=PATH[0].copy(),
        target=PATH[-1].copy(),
        reference=ref,
        task="linear",
        user=user,
        object=obj,
        path=PATH,
        obstacles=obstacles,
    )


def _smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def test_hypotheses_are_the_hand_built_detours():
    # left curve of the mean shape: y = (h_n + c)·b(s), b = 1 − smoothstep((|s − 0.5| − (h_t + c)) / a)
    shape = PersonShape(clearance=0.02, anticipation=0.1)
    src = PathHypothesesIntent(default=shape, settings=FilterSettings(shape_grid=(1.0,)))
    src.reset(_context())
    sides, pts = src.curves
    assert sides.tolist() == [1, -1]
    s = PATH[:, 0]
    bump = 1.0 - _smoothstep((np.abs(s - 0.5) - (0.05 + 0.02)) / 0.1)
    np.testing.assert_allclose(pts[0, :, 1], (0.05 + 0.02) * bump, atol=1e-12)
    np.testing.assert_allclose(pts[1, :, 1], -(0.05 + 0.02) * bump, atol=1e-12)
    np.testing.assert_array_equal(pts[:, :, 0], np.broadcast_to(s, (2, s.size)))
    # a grid of shapes: one curve per side and (c, a) pair, each the detour of its own shape
    src = PathHypothesesIntent(default=shape, settings=FilterSettings(shape_grid=(0.5, 1.0)))
    src.reset(_context())
    sides, pts = src.curves
    assert sides.tolist() == [1] * 4 + [-1] * 4
    amplitudes = np.abs(pts[:, :, 1]).max(axis=1)
    np.testing.assert_allclose(amplitudes, 0.05 + 0.02 * np.array([0.5, 0.5, 1, 1, 0.5, 0.5, 1, 1]), atol=1e-12)


def test_a_box_the_plan_already_clears_is_no_obstacle_of_its_path():
    """A scene may name every fixture on the table: a box the plan passes by more than half the person's largest
    clearance (here 2 × 2 cm, so 2 cm) gets no detour round it (the rows are the present estimate's), one nearer
    does, and beside the box on the path a far box changes nothing (the same curves, bit for bit)."""
    shape = PersonShape(clearance=0.02, anticipation=0.1)
    settings = FilterSettings(shape_grid=(0.5, 1.0, 2.0))

    def curves(obstacles):
        src = PathHypothesesIntent(default=shape, settings=settings)
        src.reset(_context(obstacles=obstacles))
        return src.curves

    beside = ((0.5, 0.05 + 0.0201), (0.1, 0.1))  # its near face 2.01 cm from the path: cleared
    grazing = ((0.5, 0.05 + 0.0199), (0.1, 0.1))  # 1.99 cm: in the way
    far = ((1.5, 1.5), (0.1, 0.1))
    assert curves((beside,))[0].size == 0 and curves((far,))[0].size == 0
    sides, pts = curves((grazing,))
    assert sorted(set(sides.tolist())) == [-1, 1] and np.abs(pts[:, :, 1]).max() > 0.05
    alone, with_far = curves((BOX,)), curves((far, BOX, beside))
    np.testing.assert_array_equal(alone[0], with_far[0])
    np.testing.assert_array_equal(alone[1], with_far[1])


def test_present_estimate_is_the_arm_solved_for_the_intent():
    # p̂ = p + (w + m a + Ĉ v)/K̂, rows p̂ + i·dt·v; a = (v(k) − v(k−1))/dt without a filter
    arm = ArmGuess(stiffness=500.0, damping=20.0)
    src = PathHypothesesIntent(horizon=4, arm=arm, settings=FilterSettings(accel_time=0.0), use_obstacles=False)
    assert isinstance(src, IntentSource) and src.model_id == "present"
    src.reset(_context(obj="heavy"))
    m = get_object("heavy").mass
    rows = [
        np.array([[0.1, 0.2, 0.05, -0.02, 3.0, -1.0, 0, 0]]),
        np.array([[0.1004, 0.1998, 0.06, -0.03, 4.0, 2.0, 0, 0]]),
    ]
    first = src.predict(rows[0])
    p, v, w = rows[0][0, :2], rows[0][0, 2:4], rows[0][0, 4:6]
    np.testing.assert_allclose(
        first, p + (w + 20.0 * v) / 500.0 + DT * np.arange(1, 5)[:, None] * v, rtol=0, atol=1e-15
    )
    second = src.predict(rows[1])
    p, v, w = rows[1][0, :2], rows[1][0, 2:4], rows[1][0, 4:6]
    a = (v - rows[0][0, 2:4]) / DT
    np.testing.assert_allclose(
        second, p + (w + m * a + 20.0 * v) / 500.0 + DT * np.arange(1, 5)[:, None] * v, rtol=0, atol=1e-14
    )
    # the obstacles are ignored by "present", whatever the context says
    src.reset(_context())
    assert src.curves[0].size == 0


def _scripted(src, intent, K=800.0, lag=6):
    """Feed a scripted trial: the tool trails the intent by ``lag`` ticks, the hand pulls with
    K (intent − tool) (the arm the present estimate assumes, with Ĉ v added back); the side per tick."""
    sides, first_rows = [], []
    for k in range(len(intent)):
        tool = intent[max(k - lag, 0)]
        vel = (intent[max(k - lag, 0)] - intent[max(k - lag - 1, 0)]) / DT
        w = K * (intent[k] - tool) - 10.0 * vel
        row = np.array([[tool[0], tool[1], vel[0], vel[1], w[0], w[1], 0.0, 0.0]])
        first_rows.append(src.predict(row)[0])
        sides.append(src.side)
    return np.asarray(sides), np.asarray(first_rows)


@pytest.mark.parametrize("side", [1, -1])
def test_filter_finds_the_side_soon_after_the_detour_starts(side):
    shape = PersonShape(clearance=0.02, anticipation=0.1)
    curve, _, _ = deformed_path(_task(), side, 0.02, 0.1)
    # the person walks the curve at 0.1 m/s (1 mm per 8 ms tick: every other polyline sample)
    intent = curve[::2][:450]
    src = PathHypothesesIntent(default=shape)
    src.reset(_context())
    sides, first = _scripted(src, intent)
    apart = int(np.argmax(np.abs(intent[:, 1]) > 1e-9))  # where the detour starts
    assert (sides[:apart] == 0).all()  # nothing to decide on the shared path
    decided = apart + int(np.argmax(sides[apart:] != 0))
    assert sides[decided] == side and (sides[decided:] == side).all()
    assert (decided - apart) * DT < 0.15  # s
    # once decided, the first row is on the person's curve: within 2 mm of the intent (lag + lead)
    late = slice(decided + 25, len(intent) - 10)
    assert np.max(np.linalg.norm(first[late] - intent[late], axis=1)) < 2e-3


def test_filter_stays_undecided_without_a_detour_and_follows_the_shared_path():
    src = PathHypothesesIntent(default=PersonShape(clearance=0.02, anticipation=0.1))
    src.reset(_context())
    intent = PATH[::2][:120]  # up to 0.12 m, well before the detours part (at 0.33 m)
    sides, first = _scripted(src, intent)
    assert (sides == 0).all()
    np.testing.assert_allclose(first[:, 1], 0.0, atol=1e-12)


def test_a_preference_alone_never_decides_and_a_person_going_straight_gets_no_detour():
    # a strong preference for the right (4 of 4 calibration trials: 1/6) and a person who walks straight
    # through where the box is: no evidence, no decision, and the rows stay on the straight path
    src = PathHypothesesIntent(default=PersonShape(clearance=0.02, anticipation=0.1, left_preference=1 / 6))
    src.reset(_context())
    sides, first = _scripted(src, PATH[::2][:700])
    assert (sides == 0).all()
    # the rows leave the left curve's (the shared path's, while the sides agree) within the divergence
    # tolerance (0.5 mm over the horizon) and fade to the present estimate as the sides part
    assert np.max(np.abs(first[:, 1])) < PathHypothesesIntent().settings.divergence


def test_no_single_tick_decides_and_the_side_is_kept_past_the_obstacle():
    shape = PersonShape(clearance=0.02, anticipation=0.1)
    src = PathHypothesesIntent(default=shape)
    src.reset(_context())
    cap = src.settings.evidence_rate * DT
    curve, _, _ = deformed_path(_task(), 1, 0.02, 0.1)
    intent = curve[::2][:450]
    log_odds = []
    for k in range(len(intent)):
        _scripted_tick(src, intent, k)
        log_odds.append(src._log_odds)
    assert np.max(np.abs(np.diff(log_odds))) <= cap + 1e-12  # at most evidence_rate·dt per tick
    assert src.side == 1
    # past the obstacle (x > 0.5), a hand that pulls hard to the right changes nothing
    for _ in range(50):
        row = np.array([[0.6, 0.07, 0.1, 0.0, 0.0, -40.0, 0.0, 0.0]])
        src.predict(row)
    assert src.side == 1


def _scripted_tick(src, intent, k, K=800.0, lag=6):
    tool = intent[max(k - lag, 0)]
    vel = (intent[max(k - lag, 0)] - intent[max(k - lag - 1, 0)]) / DT
    w = K * (intent[k] - tool) - 10.0 * vel
    return src.predict(np.array([[tool[0], tool[1], vel[0], vel[1], w[0], w[1], 0.0, 0.0]]))


def _task():
    nominal = NominalPath("line", PATH)
    return Task("linear", MotionPlanner(nominal, 10.0), Box(*BOX), 0.5)


def test_calibration_recovers_a_known_detour():
    task = _task()
    for side, c, a in ((1, 0.02, 0.1), (-1, 0.04, 0.2)):
        pts, _, _ = deformed_path(task, side, c, a)
        assert fit_detour(task, pts, clearances=[0.01, 0.02, 0.04], anticipations=[0.05, 0.1, 0.2]) == (side, c, a)
    shape = calibrate([(1, 0.02, 0.1), (-1, 0.08, 0.4), (1, 0.04, 0.2)])
    assert shape.clearance == pytest.approx(0.04) and shape.anticipation == pytest.approx(0.2)
    assert shape.left_preference == pytest.approx(3 / 5) and shape.trials == 3
    with pytest.raises(ValueError, match="at least one"):
        calibrate([])


def test_calibration_file_round_trip_and_errors_name_the_field(tmp_path):
    shapes = {"user-1": PersonShape(0.03, 0.12, 0.7, 4)}
    folder = write_calibration(tmp_path / "paths", shapes, arm=ArmGuess(900.0, 12.0))
    src = read_calibration(folder, horizon=20)
    assert src.shapes == shapes and src.arm == ArmGuess(900.0, 12.0) and src.horizon == 20
    digest = hashlib.sha256((folder / CALIBRATION_FILE).read_bytes()).hexdigest()[:12]
    assert src.model_id == f"paths:paths@{digest}"  # the folder's name and the file's digest
    loaded = load_intent_source(str(folder), horizon=20)
    assert isinstance(loaded, PathHypothesesIntent) and loaded.shapes == shapes
    assert isinstance(load_intent_source("paths"), PathHypothesesIntent)
    doc = json.loads((folder / CALIBRATION_FILE).read_text())
    doc["shapes"]["user-1"]["left_preference"] = 1.0
    (folder / CALIBRATION_FILE).write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="does not match its 'sha256'"):  # edited: refused for its hash
        read_calibration(folder)
    write_calibration(folder, shapes, arm=ArmGuess(900.0, 12.0))
    raw = json.loads((folder / CALIBRATION_FILE).read_text())
    raw["shapes"]["user-1"]["left_preference"] = 1.0
    del raw["sha256"]
    write_hashed_json(folder / CALIBRATION_FILE, {k: v for k, v in raw.items() if k != "format"}, format=raw["format"])
    with pytest.raises(ValueError, match="left_preference"):  # hashed again: refused for the value
        read_calibration(folder)
    (folder / CALIBRATION_FILE).write_text("{")
    with pytest.raises(ValueError, match=CALIBRATION_FILE):
        read_calibration(folder)
    with pytest.raises(ValueError, match="PersonShape.clearance"):
        PersonShape(clearance=-0.01)
    with pytest.raises(ValueError, match="FilterSettings.kappa"):
        FilterSettings(kappa=2.0)
    for grid in (1.0, "0.5", (1.0, 0.5), (0.5, 0.5), ()):
        with pytest.raises(ValueError, match="FilterSettings.shape_grid"):
            FilterSettings(shape_grid=grid)


def test_one_curve_stands_for_all_where_they_coincide():
    # The shared-curve shortcut gives the rows and the side of the whole filter (to rounding: a mixture of
    # identical rows sums weights that add to one), over a scripted trial that starts, detours and ends.
    shape = PersonShape(clearance=0.02, anticipation=0.1)
    curve, _, _ = deformed_path(_task(), 1, 0.02, 0.1)
    intent = curve[::2]
    fast, full = PathHypothesesIntent(default=shape), PathHypothesesIntent(default=shape)
    full.shared_fast_path = False
    fast.reset(_context())
    full.reset(_context())
    shortcut = 0
    for k in range(len(intent)):
        tool = intent[max(k - 6, 0)]
        vel = (intent[max(k - 6, 0)] - intent[max(k - 7, 0)]) / DT
        w = 800.0 * (intent[k] - tool) - 10.0 * vel
        row = np.array([[tool[0], tool[1], vel[0], vel[1], w[0], w[1], 0.0, 0.0]])
        hyp = fast._hyp
        i = int(fast._idx[0])
        shortcut += bool(i + 100 < hyp.first_apart or i > hyp.last_apart + 100)
        np.testing.assert_allclose(fast.predict(row), full.predict(row), rtol=0, atol=1e-12)
        assert fast.side == full.side
    assert shortcut > 300  # the shortcut was taken on both shared stretches


def test_each_curve_keeps_its_nearest_point_within_the_search_window():
    # The filter's step 1 (its hot loop, written as flat gathers) against the direct search: on every curve,
    # the point nearest the tool (Euclidean) among those within ±search_window of the curve's last phase.
    shape = PersonShape(clearance=0.02, anticipation=0.1)
    curve, _, _ = deformed_path(_task(), -1, 0.03, 0.12)
    intent = curve[::2]
    src = PathHypothesesIntent(default=shape)
    src.shared_fast_path = False
    src.reset(_context())
    hyp = src._hyp
    n_pts = hyp.points.shape[1]
    widest = min(n_pts, max(2, int(np.ceil(src.settings.search_window / hyp.step))))
    for k in range(0, len(intent), 3):
        tool = intent[max(k - 6, 0)] + np.array([0.0, 0.004])  # beside every curve, never on one
        vel = (intent[max(k - 6, 0)] - intent[max(k - 7, 0)]) / DT
        w = 800.0 * (intent[k] - tool) - 10.0 * vel
        before = src._idx.copy()
        src.predict(np.array([[tool[0], tool[1], vel[0], vel[1], w[0], w[1], 0.0, 0.0]]))
        for n in range(hyp.points.shape[0]):
            ids = np.arange(max(before[n] - widest, 0), min(before[n] + widest, n_pts - 1) + 1)
            dist = np.linalg.norm(hyp.points[n, ids] - tool, axis=1)
            assert dist[ids == src._idx[n]][0] == dist.min()
