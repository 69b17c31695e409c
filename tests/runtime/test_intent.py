"""The intent stage's array twin: WindowIntentBatch row for row against each WindowIntent."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.interfaces import Fault, TrialContext
from coassist.runtime.intent import WindowIntent, WindowIntentBatch

DT = 0.008
CONTEXT = TrialContext(
    dt=DT, horizon=5, start=np.zeros(2), target=np.ones(2), reference=np.zeros((10, 4)), task="t", user="u", object="o"
)


class WindowSource:
    """A model-like source: the window's last x-y plus its mean x-y times the row number / 10."""

    model_id = "window-test"

    def __init__(self, history: int, horizon: int) -> None:
        self.history, self.horizon = history, horizon

    def reset(self, context: TrialContext) -> None:
        pass

    def predict(self, window: np.ndarray) -> np.ndarray:
        steps = np.arange(1, self.horizon + 1)[:, None]
        return window[-1, :2] + 0.1 * steps * window[:, :2].mean(axis=0)


@pytest.mark.parametrize("history", [0, 1, 4])
def test_the_batch_pushes_the_stages_windows_and_accepts_as_they_do(history):
    """Windows bit for bit those of each stage's push (the ring's padding at tick 0, its wrap),
    and ok where the stage's accept takes the row: a short answer, a NaN in the first horizon
    rows (a NaN past them is no fallback), a row farther from the tool than max_distance or
    rows faster than max_speed (issue 42), for rows leaving as their runs end."""
    rng = np.random.default_rng(history)
    horizon, need, n = 5, 3, 6
    source = WindowSource(history, horizon)
    stages = [WindowIntent(source, need) for _ in range(n)]
    twins = [WindowIntent(source, need) for _ in range(n)]
    for stage in stages + twins:
        stage.reset(CONTEXT)
    batch = WindowIntentBatch(twins)
    lim = stages[0].plausibility
    rows = np.arange(n)
    for k in range(3 * history + 4):
        if k == history + 2:
            rows = rows[1:]  # a run left
        features = rng.normal(0.0, 0.01, (rows.size, 8))
        windows = batch.push(k, rows, features)
        assert windows.shape == (rows.size, history, 8)
        for j, i in enumerate(rows.tolist()):
            assert windows[j].tolist() == stages[i].push(k, tuple(features[j])).tolist()
        answer = (
            np.stack([source.predict(w) for w in windows])
            if history
            else features[:, None, :2] + rng.normal(0.0, 0.001, (rows.size, horizon + 2, 2))
        )
        answer[0, 1, 0] = np.nan  # row 0: a NaN in use (a fallback)
        if rows.size > 1:
            answer[1, horizon:, :] = np.nan  # row 1: NaNs only past the horizon (taken)
        if rows.size > 3:
            answer[2, 3, 1] = features[2, 1] + lim.max_distance * 1.01  # row 2: one point too far (a fallback)
            answer[3, :, 0] = features[3, 0] + lim.max_speed * DT * 1.01 * np.arange(answer.shape[1])  # too fast
            answer[3, :, 1] = features[3, 1]
        positions, ok = batch.accept(rows, answer)
        for j, i in enumerate(rows.tolist()):
            pred, flags = stages[i].accept(answer[j])
            assert bool(ok[j]) == (flags == Fault.NONE), (k, i)
            if ok[j]:
                assert positions[j].tolist() == pred.tolist()
        assert not ok[0] and (rows.size < 2 or ok[1])
        assert rows.size < 4 or not (ok[2] or ok[3])
        assert ok[4:].all()  # the plain rows: near the tool, at a hand's speed
    short = np.zeros((rows.size, need - 1, 2))  # fewer rows than the controller needs: every row a fallback
    assert not batch.accept(rows, short)[1].any()
    with pytest.raises(ValueError, match="malformed"):
        batch.accept(rows, np.zeros((rows.size + 1, horizon, 2)))


def test_the_batch_takes_stages_of_one_history_and_horizon_only():
    with pytest.raises(ValueError, match="history"):
        WindowIntentBatch([WindowIntent(WindowSource(2, 5), 3), WindowIntent(WindowSource(3, 5), 3)])
    with pytest.raises(ValueError, match="horizon"):
        WindowIntentBatch([WindowIntent(WindowSource(2, 5), 3), WindowIntent(WindowSource(2, 6), 3)])


def test_the_stages_answer_check_is_prediction_plausible():
    """The stage's per-tick check (written in fewer numpy calls, issue 44) accepts exactly the answers
    prediction_plausible accepts: 3000 random float64 answers around both bounds, with NaN and inf, 1 to 60
    rows. Exact: both take the same differences of the same floats and compare them with the same bounds."""
    from coassist.interfaces import PlausibilityLimits, prediction_plausible

    lim = PlausibilityLimits(max_distance=0.2, max_speed=1.0)
    stage = WindowIntent(WindowSource(1, 60), 1, plausibility=lim)
    stage.reset(CONTEXT)
    rng = np.random.default_rng(7)
    used = 0
    for k in range(3000):
        tool = rng.uniform(-0.5, 0.5, 2)
        n = int(rng.integers(1, 61))
        step = rng.choice([0.5, 0.99, 1.01, 2.0]) * DT * rng.uniform(-1.0, 1.0, (n, 2))
        rows = tool + rng.choice([0.0, 0.15, 0.199]) * rng.uniform(-1.0, 1.0, 2) + np.cumsum(step, axis=0)
        if rng.random() < 0.05:
            rows[rng.integers(n), rng.integers(2)] = rng.choice([np.nan, np.inf, -np.inf])
        stage.push(k, (*tool.tolist(), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        want = prediction_plausible(rows, tool, DT, lim)
        assert (stage.accept(rows)[0] is not None) == want, k
        used += want
    assert 300 < used < 2700  # both outcomes well represented


def test_a_row_far_from_the_tool_is_a_fallback_not_a_push():
    """prediction_plausible's rule in the stage: a row max_distance from the tool (either axis) is
    used, one beyond it is a fallback (flagged; PREDICTOR_STALLED once it persists); consecutive rows
    max_speed · dt apart are used, more is a fallback."""
    from coassist.interfaces import PlausibilityLimits, prediction_plausible

    lim = PlausibilityLimits(max_distance=0.2, max_speed=1.0)
    stage = WindowIntent(WindowSource(1, 5), 5, stall_ticks=2, plausibility=lim)
    stage.reset(CONTEXT)
    tool = (0.3, -0.6)
    near = np.array(tool) + np.linspace(0.0, 0.004, 5)[:, None] * [1.0, 0.0]  # 0.5 m/s along x
    for k, (rows, usable) in enumerate(
        [
            (near, True),
            (near + [0.0, 0.2 - 1e-9], True),  # every row just within 0.2 m of the tool on y: used
            (near + [0.0, 0.2 + 1e-9], False),  # just beyond it: a fallback
            (np.array(tool) + np.arange(5)[:, None] * [DT * 0.99, 0.0], True),  # 0.99 m/s: used
            (np.array(tool) + np.arange(5)[:, None] * [DT * 1.01, 0.0], False),  # 1 % faster: a fallback
        ]
    ):
        stage.push(k, (*tool, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        assert prediction_plausible(rows, np.array(tool), DT, lim) == usable, k
        pred, flags = stage.accept(rows)
        assert (pred is not None, flags) == (usable, Fault.NONE if usable else Fault.PREDICTION_FALLBACK), k
    far = near + [1.0, 0.0]
    for k in range(5, 8):  # the third bad row in a row (stall_ticks = 2): stalled
        stage.push(k, (*tool, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        pred, flags = stage.accept(far)
    assert pred is None and flags == Fault.PREDICTION_FALLBACK | Fault.PREDICTOR_STALLED
    with pytest.raises(ValueError, match="plausibility must be a PlausibilityLimits"):
        WindowIntent(WindowSource(1, 5), 5, plausibility=0.5)


@pytest.mark.parametrize("dtype", [np.complex128, object, bool, np.str_])
def test_an_answer_not_of_real_numbers_is_a_fallback_not_a_clean_row(dtype):
    """A source's answer of complex, object, boolean or string dtype is no positions: a fallback (flagged,
    PREDICTOR_STALLED once it persists), never a clean row on which the tick's human_reference then raised
    (a complex answer once passed as Fault.NONE and ended the run with internal_error). The array twin
    refuses such an answer whole (every row would be a fallback)."""
    stage = WindowIntent(WindowSource(0, 3), 3, stall_ticks=2)
    stage.reset(CONTEXT)
    tool = (0.3, -0.2)
    answer = np.tile(np.array(tool), (3, 1)).astype(dtype)  # the tool's own position: plausible as numbers
    flags = []
    for k in range(4):
        stage.push(k, (*tool, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        pred, f = stage.accept(answer)
        assert pred is None
        flags.append(f)
    fb, stalled = Fault.PREDICTION_FALLBACK, Fault.PREDICTION_FALLBACK | Fault.PREDICTOR_STALLED
    assert flags == [fb, fb, stalled, stalled]
    batch = WindowIntentBatch([stage])
    rows = np.arange(1)
    batch.push(4, rows, np.array([[*tool, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="real numbers"):
        batch.accept(rows, answer[None])


@pytest.mark.parametrize("dtype", [np.float32, np.int64, np.uint8])
def test_an_answer_of_another_real_dtype_is_used_as_float64(dtype):
    """Floats and ints are positions: the stage and its array twin take them, converted to float64 with the
    same values (what the tick's float64 arithmetic would have promoted them to), flagged nothing."""
    stage = WindowIntent(WindowSource(0, 3), 3)
    stage.reset(CONTEXT)
    tool = (2.0, 3.0)  # integral, so an int answer can lie on the tool
    answer = np.array([[2.0, 3.0], [2.0, 3.0], [2.0, 3.0]], dtype=dtype)
    stage.push(0, (*tool, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    pred, flags = stage.accept(answer)
    assert flags == Fault.NONE and pred.dtype == np.float64 and pred.tolist() == [[2.0, 3.0]] * 3
    batch = WindowIntentBatch([stage])
    rows = np.arange(1)
    batch.push(0, rows, np.array([[*tool, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]))
    positions, ok = batch.accept(rows, answer[None])
    assert ok.tolist() == [True] and positions.dtype == np.float64 and positions[0].tolist() == [[2.0, 3.0]] * 3
    same = np.full((3, 2), 0.25)  # a float64 answer is returned as it is: no copy, nothing computed anew
    stage.push(1, (0.25, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert stage.accept(same)[0].base is same


class _DuckPredictor:
    """A real-time predictor as a lab's own may be: tick() answers whatever it is told to, checking nothing."""

    horizon, history, errors, model_id = 3, 2, 0, "duck"

    def __init__(self, answers) -> None:
        self.answers = list(answers)

    def reset(self, context) -> None:
        pass

    def tick(self, sample, nominal):
        return self.answers.pop(0), Fault.NONE, 0


def test_the_realtime_stage_refuses_implausible_rows_as_the_window_stage_does():
    """RealtimeIntent holds what reaches the controller to prediction_plausible whatever its predictor checked:
    rows farther than max_distance from the tick's tool, or faster than max_speed, are a fallback, counted toward
    a stall after the history filled (before, a duck-typed predictor's rows 3 m from the tool reached the
    controller unflagged); rows within both bounds are used as they are. Its limits default to the predictor's
    own config.plausibility where it has one; anything but a PlausibilityLimits is refused."""
    from coassist.interfaces import PlausibilityLimits
    from coassist.runtime.intent import RealtimeIntent

    lim = PlausibilityLimits(max_distance=0.2, max_speed=1.0)
    tool = np.array([0.4, -0.1])
    near = tool + np.arange(1, 4)[:, None] * [0.99 * DT, 0.0]  # 0.99 m/s, 3 rows ahead: plausible
    far = tool + [0.2 + 1e-9, 0.0] + np.zeros((3, 1))  # just beyond max_distance, at rest
    fast = tool + np.arange(1, 4)[:, None] * [1.01 * DT, 0.0]  # 1 % faster than max_speed
    script = [(near, True), (far, False), (near, True), (fast, False), (far, False), (far, False), (far, False)]
    stage = RealtimeIntent(_DuckPredictor([a for a, _ in script]), stall_ticks=2, plausibility=lim)
    stage.reset(CONTEXT)
    row = (*tool.tolist(), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    got = []
    for k, (answer, usable) in enumerate(script):
        pred, flags = stage.update(k, row, np.zeros((3, 2)))
        assert (pred is not None) == usable, k
        if usable:
            assert pred.tolist() == answer.tolist()
        got.append(flags)
    fb = Fault.PREDICTION_FALLBACK
    # tick 1 is before the history (2) filled: no stall count; ticks 3, 4, 5, 6 count 1, 2, 3, 4 > stall_ticks = 2
    assert got == [Fault.NONE, fb, Fault.NONE, fb, fb, fb | Fault.PREDICTOR_STALLED, fb | Fault.PREDICTOR_STALLED]

    class Configured(_DuckPredictor):
        class config:  # noqa: N801 - a RealtimePredictor's config, duck-typed
            plausibility = lim

    assert RealtimeIntent(Configured([])).plausibility is lim
    assert RealtimeIntent(_DuckPredictor([])).plausibility == PlausibilityLimits()
    with pytest.raises(ValueError, match="plausibility must be a PlausibilityLimits"):
        RealtimeIntent(_DuckPredictor([]), plausibility=0.5)


def test_the_realtime_stage_refuses_a_complex_answer():
    """A real-time answer of complex numbers is a fallback (its imaginary part was dropped with a ComplexWarning)."""
    from coassist.runtime.intent import RealtimeIntent

    answer = np.zeros((3, 2)) + 0.1j
    pred, flags = RealtimeIntent(_DuckPredictor([answer])).update(0, (0.0,) * 8, np.zeros((3, 2)))
    assert pred is None and flags == Fault.PREDICTION_FALLBACK


def test_answers_accepted_together_are_each_stages_accept_bit_for_bit():
    """accept_together (the array path's check of its per-run sources' answers, issue 44) gives each stage's own
    accept: the rows and flags, the stall count of a fallback, for answers of one shape and of others (a short one, a
    float32 one, an object one, a raised predict's None), with NaNs in and past the horizon, far and fast rows."""
    from coassist.runtime.intent import accept_together

    rng = np.random.default_rng(7)
    horizon, need, n = 5, 3, 9
    source = WindowSource(2, horizon)
    stages = [WindowIntent(source, need, stall_ticks=1) for _ in range(n)]
    twins = [WindowIntent(source, need, stall_ticks=1) for _ in range(n)]
    lim = stages[0].plausibility
    for stage in stages + twins:
        stage.reset(CONTEXT)
    for k in range(4):
        features = rng.normal(0.0, 0.01, (n, 8))
        answers = [stage.answer(k, tuple(f)) for stage, f in zip(stages, features)]
        for twin, f in zip(twins, features):
            twin.push(k, tuple(f))
        answers[0] = answers[0].copy()
        answers[0][1, 0] = np.nan  # a NaN in use
        answers[1] = np.vstack([answers[1], np.full((2, 2), np.nan)])  # NaNs past the horizon: taken
        answers[2] = answers[2].copy()
        answers[2][3, 1] = features[2, 1] + lim.max_distance * 1.01  # too far
        answers[3] = answers[3][: need - 1]  # too short
        answers[4] = answers[4].astype(np.float32)  # another real dtype: converted
        answers[5] = answers[5].astype(object)  # no numbers
        answers[6] = None  # the source raised
        answers[7] = answers[7].copy()
        answers[7][:, 0] = features[7, 0] + lim.max_speed * DT * 1.01 * np.arange(horizon)  # too fast
        together = accept_together(stages, answers)
        for j, (stage, twin, answer) in enumerate(zip(stages, twins, answers)):
            want = twin.accept(answer)
            got = together[j]
            assert got[1] == want[1], (k, j)
            assert (got[0] is None) == (want[0] is None) and (got[0] is None or got[0].tobytes() == want[0].tobytes())
            assert stage._bad == twin._bad  # the stall count as the stage's own accept leaves it
        assert [g[1] == Fault.NONE for g in together] == [False, True, False, False, True, False, False, False, True]
