"""The person model's online filter (coassist.scenario.person_intent) on scripted trials with known paths."""

from dataclasses import replace

import numpy as np
import pytest

from coassist.interfaces import IntentSource, TrialContext
from coassist.scenario.arm_identification import ArmEstimate
from coassist.scenario.path_model import fit_path_model
from coassist.scenario.person_intent import (
    PersonFilterSettings,
    PersonPathsIntent,
    normal_cdf_between,
    onset_log_ratio,
)

DT = 0.008
K = 800.0
ARM = ArmEstimate(stiffness=K, damping=10.0, trials=5, method="probe-iv")
NOMINAL = np.stack([np.linspace(0.0, 1.0, 501), np.zeros(501)], axis=1)
X = np.linspace(0.0, 1.0, 4001)


def _bump(centre, amplitude, width=0.12):
    return np.stack([X, amplitude * np.exp(-(((X - centre) / width) ** 4))], axis=1)


def _model(left=(0.49, 0.5, 0.51), right=(0.5, 0.52), amplitude=0.08):
    demos = [_bump(c, amplitude) for c in left] + [_bump(c, -amplitude) for c in right]
    return fit_path_model(NOMINAL, demos, noise=0.001)


def _context(path=NOMINAL, user="u"):
    return TrialContext(
        dt=DT,
        horizon=50,
        start=path[0].copy(),
        target=path[-1].copy(),
        reference=np.zeros((10, 4)),
        task="linear",
        user=user,
        object="handle",
        path=path,
    )


def _ready(settings=None):
    """The person filter on :func:`_model`'s person with ``settings`` (None: the class's default), reset to
    :func:`_context`."""
    src = PersonPathsIntent(paths={"u": _model()}, arms={"u": ARM}, settings=settings)
    src.reset(_context())
    return src


def _walk(intent):
    """The intent walked at 0.1 m/s: its points 1 mm apart (X is 0.25 mm apart)."""
    seg = np.linalg.norm(np.diff(intent, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.arange(0.0, arc[-1], 0.1 * DT)
    return np.stack([np.interp(s, arc, intent[:, 0]), np.interp(s, arc, intent[:, 1])], axis=1)


def _tool(intent, k, lag=6):
    """The tool's position and velocity at tick k of a scripted trial: ``lag`` ticks behind the intent."""
    return intent[max(k - lag, 0)], (intent[max(k - lag, 0)] - intent[max(k - lag - 1, 0)]) / DT


def _tick(src, intent, k, lag=6):
    """Tick k of a scripted trial: the tool trails the intent by ``lag`` ticks (:func:`_tool`) and the hand pulls
    with the arm the model knows (so the present estimate is the intent itself); the rows."""
    tool, vel = _tool(intent, k, lag)
    w = K * (intent[k] - tool) - ARM.damping * vel
    return src.predict(np.array([[tool[0], tool[1], vel[0], vel[1], w[0], w[1], 0.0, 0.0]]))


def _scripted(src, intent):
    """A whole scripted trial: the way decided and the first row, per tick."""
    sides, first = [], []
    for k in range(len(intent)):
        first.append(_tick(src, intent, k)[0])
        sides.append(src.side)
    return np.asarray(sides), np.asarray(first)


def test_it_is_an_intent_source_of_the_persons_arm():
    src = PersonPathsIntent(paths={"u": _model()}, arms={"u": ARM})
    assert isinstance(src, IntentSource) and src.history == 1
    # the model knows one plan: on another the rows are the present estimate held, as the default source gives it
    # (carried at the tool's velocity, as they were, they overshot more than MG for people a model did not hold);
    # the plan's first 60 % (its vertices on the model's plan) is another plan too
    row = np.array([[0.1, 0.2, 0.1, 0.0, 4.0, -2.0, 0.0, 0.0]])
    present = np.array([0.1, 0.2]) + (np.array([4.0, -2.0]) + 10.0 * np.array([0.1, 0.0])) / K
    for other in (NOMINAL + [0.0, 0.2], NOMINAL[: int(0.6 * len(NOMINAL))]):
        src.reset(_context(path=other))
        np.testing.assert_allclose(src.predict(row), np.tile(present, (50, 1)), rtol=0, atol=1e-15)
    # a person nobody calibrated gets the assumed arm and no paths
    src.reset(_context(user="stranger"))
    assert src.side == 0


@pytest.mark.parametrize(("amplitude", "centre"), [(0.08, 0.505), (-0.08, 0.515)], ids=["left", "right"])
def test_the_way_is_found_soon_after_the_detour_starts_and_the_rows_follow_it(amplitude, centre):
    src = _ready()
    intent = _walk(_bump(centre, amplitude))
    sides, first = _scripted(src, intent)
    way = int(np.sign(amplitude))
    out = int(np.argmax(np.abs(intent[:, 1]) > 0.002))  # the person is 2 mm off the plan
    assert (sides[:out] != -way).all()
    decided = out + int(np.argmax(sides[out:] == way))
    assert (sides[decided:] == way).all()  # and it stays decided
    assert (decided - out) * DT < 0.3  # s
    # once decided the first row is on the person's path: this trial's detour is one of the hypotheses
    # (a demonstration shifted along the plan), and the rows mix it with its neighbours 5 mm along the
    # plan, as much across on a ramp of slope one: within 5 mm of the intent, a millimetre or two mostly
    late = slice(decided + 25, len(intent) - 60)
    error = np.linalg.norm(first[late] - intent[late], axis=1)
    assert np.max(error) < 5e-3 and np.median(error) < 2e-3


def _feint(way, amplitude=0.08, lean=0.3):
    """A path round the bump at 0.5 on ``way`` (+1 left) that first leans the other way (a feint: ``lean`` of the
    amplitude, at 0.25 of the plan, back on the plan before the detour starts)."""
    path = _bump(0.5, way * amplitude)
    path[:, 1] += _bump(0.25, -way * lean * amplitude, width=0.06)[:, 1]
    return path


@pytest.mark.parametrize("rule", ["offset", "onset"])
@pytest.mark.parametrize("way", [1, -1], ids=["left", "right"])
def test_a_person_who_feints_is_read_by_the_side_their_own_paths_lie_on(way, rule):
    # a person whose every path leans the wrong way before going round (left paths lean right first, right paths
    # left): with side_orientation the lean is evidence for the way their paths lean there, so the way they take is
    # decided at the lean and never the other; without it an offset to the left is evidence for the left way, and the
    # lean decides the wrong one first (the rows then pull the tool the wrong way until the person's detour undoes it)
    demos = [_feint(1) for _ in range(3)] + [_feint(-1) for _ in range(2)]
    model = fit_path_model(NOMINAL, demos, noise=0.001)
    intent = _walk(_feint(way))
    lean = int(np.argmax(np.abs(intent[:, 1]) > 0.002))  # the lean leaves the plan by 2 mm
    sides = {}
    for oriented in (False, True):
        st = PersonFilterSettings(side_orientation=oriented, side_rule=rule)
        src = PersonPathsIntent(paths={"u": model}, arms={"u": ARM}, settings=st)
        src.reset(_context())
        sides[oriented] = _scripted(src, intent)[0]
    assert (sides[False] == -way).any()  # the lean, read as a way, decided the wrong one
    assert not (sides[True] == -way).any()
    decided = int(np.argmax(sides[True] == way))
    assert (sides[True][decided:] == way).all() and (decided - lean) * DT < 0.5  # at the lean, and it stays


def test_a_person_who_goes_straight_gets_no_detour_and_no_single_tick_decides():
    src = PersonPathsIntent(paths={"u": _model(left=(0.5,) * 4, right=(0.5,))}, arms={"u": ARM})
    src.reset(_context())
    cap = src.settings.evidence_rate * DT
    intent = _walk(NOMINAL)[:700]
    odds, sides = [], []
    for k in range(len(intent)):
        _tick(src, intent, k)
        odds.append(src._log_odds)
        sides.append(src.side)
    # a habit of 4 to 1 starts the odds at the prior but never decides alone; straight ahead adds nothing
    assert (np.asarray(sides) == 0).all()
    assert np.max(np.abs(np.diff(odds))) <= cap + 1e-12


def test_each_curve_keeps_its_nearest_point_within_the_search_window():
    src = _ready()
    hyp = src._hyp
    intent = _walk(_bump(0.5, 0.08))
    G = hyp.points.shape[1]
    for k in range(len(intent)):
        before = src._idx.copy()
        _tick(src, intent, k)
        tool = intent[max(k - 6, 0)]
        for n in range(len(before)):
            lo, hi = max(0, before[n] - src._widest), min(G, before[n] + src._widest + 1)
            d2 = np.sum((hyp.points[n, lo:hi] - tool) ** 2, axis=1)
            assert d2[src._idx[n] - lo] == d2.min()


def test_bad_settings_name_the_field():
    for field, value in (("kappa", 0.0), ("shifts", (0.01, -0.01)), ("shifts", ()), ("max_offset", 5.0)):
        with pytest.raises(ValueError, match=f"PersonFilterSettings.{field}"):
            PersonFilterSettings(**{field: value})


def test_the_rows_of_every_curve_at_once_are_each_curves_own_interpolation():
    """_Curves.along (one search over all curves) against np.interp on each curve alone, ends clipped."""
    from coassist.scenario.person_intent import _Curves

    curves = _Curves(_model(), (-0.015, 0.0, 0.015))
    rng = np.random.default_rng(3)
    n = rng.integers(0, len(curves.ways), 6)
    s = rng.uniform(-0.1, 1.3, (6, 50))  # beyond both ends too: the curves are about 1.05 m long
    got = curves.along(n, s)
    for i, k in enumerate(n):
        arc, pts = curves.arc[k], curves.points[k]
        want = np.stack([np.interp(s[i], arc, pts[:, 0]), np.interp(s[i], arc, pts[:, 1])], axis=1)
        # the stride added to the arc lengths (under 30 m here) costs at most a few ulps of it
        np.testing.assert_allclose(got[i], want, rtol=0.0, atol=1e-12)


def test_a_curve_held_far_from_the_tool_gives_no_rows():
    """Seed 1's held-out operator 2 (2026-12-02): round a detour wider than any of their demonstrations, the way's
    curves kept their phase in a local minimum 0.24 m behind the tool (each curve is searched within
    ``search_window`` of its last phase); one curve of the other way stayed near, so the rows went on from the
    far ones, 0.18 m behind the tool, and the robot held the tool there against 35 N until the time limit.
    Here: the way decided, its curves' phases put 0.25 m behind the tool; the rows must be the present
    estimate's, not the far curves'."""
    src = _ready()
    intent = _walk(NOMINAL)
    k = int(np.argmax(intent[:, 0] > 0.3))
    for i in range(k):
        _tick(src, intent, i)
    hyp = src._hyp
    left = hyp.on_way[1]
    behind = np.argmin(np.abs(hyp.points[left, :, 0] - 0.05), axis=1)  # each left curve's point at x = 0.05
    src._idx[left] = behind
    src._side, src._log_odds, src._mix = 1, 5.0, 1.0
    rows = _tick(src, intent, k)
    tool = intent[k - 6]
    # the present estimate is the intent itself here (_tick), the rows start there: far from x = 0.05
    assert np.linalg.norm(rows[0] - intent[k]) < 0.01, rows[0]
    assert np.all(rows[:, 0] > tool[0] - 0.01)
    assert src._mix == 0.0  # through the present estimate, as on a change of mind


def test_on_a_way_nobody_took_the_rows_are_the_present_estimates_without_the_mirror():
    # the calibration went left three times; this trial goes right. With follow_mirror the rows run along the
    # mirror of the left paths; without, once the right way is decided, they are the present estimate's rows
    # q + hedge_velocity·i·dt·v (q: the intent itself here, the arm known), never a curve.
    model = _model(left=(0.49, 0.5, 0.51), right=())
    intent = _walk(_bump(0.505, -0.08))
    rows = {}
    for follow in (True, False):
        src = PersonPathsIntent(
            paths={"u": model}, arms={"u": ARM}, settings=PersonFilterSettings(follow_mirror=follow)
        )
        src.reset(_context())
        rows[follow], sides = [], []
        for k in range(len(intent)):
            rows[follow].append(_tick(src, intent, k))
            sides.append(src.side)
        sides = np.asarray(sides)
        assert sides[-1] == -1  # the way is found either way
    decided = int(np.argmax(sides == -1))
    late = range(decided + 1, len(intent) - 60)
    st = PersonFilterSettings()
    for k in late:
        tool, prev = intent[max(k - 6, 0)], intent[max(k - 7, 0)]
        vel = (tool - prev) / DT
        hedge = intent[k] + st.hedge_velocity * np.outer(DT * np.arange(1, 51), vel)
        np.testing.assert_allclose(rows[False][k], hedge, atol=1e-9)
    # and the mirror's rows differ from them: the test can fail
    assert max(np.abs(rows[True][k] - rows[False][k]).max() for k in late) > 1e-3


def test_a_way_shown_fewer_times_than_min_way_paths_gives_the_present_estimates_rows():
    # the calibration went left three times and right once; this trial goes right. With min_way_paths 1 (the
    # default) the rows follow the one right path; with 2, once the right way is decided, they are the present
    # estimate's rows (as on a way nobody took), and on the left way (three paths) nothing changes
    model = _model(left=(0.49, 0.5, 0.51), right=(0.5,))
    st = PersonFilterSettings()
    for side, bump in ((-1, _bump(0.505, -0.08)), (1, _bump(0.505, 0.08))):
        intent = _walk(bump)
        rows = {}
        for least in (1, 2):
            src = PersonPathsIntent(
                paths={"u": model}, arms={"u": ARM}, settings=PersonFilterSettings(min_way_paths=least)
            )
            src.reset(_context())
            rows[least], sides = [], []
            for k in range(len(intent)):
                rows[least].append(_tick(src, intent, k))
                sides.append(src.side)
            sides = np.asarray(sides)
            assert sides[-1] == side
        decided = int(np.argmax(sides == side))
        late = range(decided + 1, len(intent) - 60)
        if side == 1:  # the left way: three paths, followed alike
            assert all(np.array_equal(rows[1][k], rows[2][k]) for k in range(len(intent)))
            continue
        for k in late:
            tool, prev = intent[max(k - 6, 0)], intent[max(k - 7, 0)]
            hedge = intent[k] + st.hedge_velocity * np.outer(DT * np.arange(1, 51), (tool - prev) / DT)
            np.testing.assert_allclose(rows[2][k], hedge, atol=1e-9)
        assert max(np.abs(rows[1][k] - rows[2][k]).max() for k in late) > 1e-3  # the test can fail
    # a way nobody took is left to follow_mirror: with the mirror followed, min_way_paths changes nothing there
    unseen = _model(left=(0.49, 0.5, 0.51), right=())
    intent = _walk(_bump(0.505, -0.08))
    mirrored = {}
    for least in (1, 2):
        src = PersonPathsIntent(
            paths={"u": unseen},
            arms={"u": ARM},
            settings=PersonFilterSettings(follow_mirror=True, min_way_paths=least),
        )
        src.reset(_context())
        mirrored[least] = np.asarray([_tick(src, intent, k) for k in range(len(intent))])
        assert src.side == -1
    np.testing.assert_array_equal(mirrored[1], mirrored[2])
    with pytest.raises(ValueError, match="PersonFilterSettings.min_way_paths"):
        PersonFilterSettings(min_way_paths=0)


@pytest.mark.parametrize(
    ("z", "h", "sigma"), [(0.001, 0.002, 0.002), (-0.003, 0.05, 0.0025), (0.004, 0.0005, 0.001), (0.02, 0.1, 0.002)]
)
def test_the_onset_rule_is_the_likelihood_ratio_of_an_offset_anywhere_into_either_way(z, h, sigma):
    from scipy import integrate, stats

    # p±(z) = (1/h) ∫ φ((z ∓ u)/σ)/σ du over u ∈ [0, h], integrated numerically
    def density(sign):
        value, _ = integrate.quad(lambda u: stats.norm.pdf(z - sign * u, scale=sigma), 0.0, h, epsabs=0.0, epsrel=1e-12)
        return value / h

    expected = np.log(density(1.0)) - np.log(density(-1.0))
    assert onset_log_ratio(z, h, sigma) == pytest.approx(expected, rel=1e-8)
    assert onset_log_ratio(-z, h, sigma) == pytest.approx(-expected, rel=1e-12)  # odd in z


def test_the_onset_rule_is_the_offset_rule_where_the_ways_are_close_and_stops_growing_where_they_part():
    sigma, z = 0.002, 0.001
    # h ≪ σ: z·h/σ² (two Gaussians at ±h/2), to first order (the next term is O(h²/σ²) relative)
    h = 1e-5
    assert onset_log_ratio(z, h, sigma) == pytest.approx(z * h / sigma**2, rel=1e-4)
    # h ≫ σ: log Φ(z/σ) − log Φ(−z/σ), whatever h
    from scipy import stats

    limit = stats.norm.logcdf(z / sigma) - stats.norm.logcdf(-z / sigma)
    for h in (0.05, 0.5):
        assert onset_log_ratio(z, h, sigma) == pytest.approx(limit, rel=1e-12)
    assert onset_log_ratio(0.0, 0.05, sigma) == 0.0 and onset_log_ratio(z, 0.0, sigma) == 0.0


def test_the_normal_cdf_difference_keeps_its_digits_in_either_tail():
    from scipy import stats

    for a, b in ((0.3, -1.2), (9.0, 8.5), (-8.5, -9.0), (30.0, 29.0)):
        expected = stats.norm.sf(b) - stats.norm.sf(a) if b > 0 else stats.norm.cdf(a) - stats.norm.cdf(b)
        assert normal_cdf_between(a, b) == pytest.approx(expected, rel=1e-10)
    assert normal_cdf_between(30.0, 29.0) > 0.0  # Φ(30) − Φ(29) computed as 1 − 1 would be 0


def test_no_way_evidence_where_the_ways_are_closer_than_the_evidence_gap():
    # a person who walks 1 cm left of the plan (beyond what the lateral bias may take, 5 mm): the offset is evidence
    # for the left way only where the ways' mean paths are at least evidence_gap apart
    model = _model(left=(0.5,), right=(0.5,))
    intent = _walk(NOMINAL + [0.0, 0.01])[:600]
    for gap in (0.0, 0.02):
        src = PersonPathsIntent(
            paths={"u": model}, arms={"u": ARM}, settings=PersonFilterSettings(evidence_gap=gap, side_rule="onset")
        )
        src.reset(_context())
        hyp, prior = src._hyp, src._log_odds
        moved = []
        for k in range(len(intent)):
            before = src._log_odds
            _tick(src, intent, k)
            moved.append((float(hyp.gap[src._nominal_at]), src._log_odds - before))
        closer = [d for g, d in moved if g < 0.02]
        if gap > 0.0:
            assert closer and all(d == 0.0 for d in closer)  # no evidence until the ways are 2 cm apart
            assert src._log_odds > prior  # and then the offset tells the way
        else:
            assert max(closer) > 0.0  # the test can fail: without the gap the same ticks move the odds


def test_the_hedge_without_its_lateral_part_carries_only_the_progress_along_the_plan():
    # undecided, the rows are the present estimate's with half the tool's velocity; with hedge_lateral off only
    # its component along the plan (here x): a sideways drift of the tool is not extrapolated into a push
    model = _model()
    intent = _walk(NOMINAL)[:400]
    intent[:, 1] = 0.0015 * np.sin(np.arange(len(intent)) * 0.05)  # swaying, within the dead zone
    rows = {}
    for lateral in (True, False):
        src = PersonPathsIntent(
            paths={"u": model}, arms={"u": ARM}, settings=PersonFilterSettings(hedge_lateral=lateral)
        )
        src.reset(_context())
        rows[lateral] = []
        for k in range(len(intent)):
            rows[lateral].append((_tick(src, intent, k), src._mix, src.side))
    st = PersonFilterSettings()
    steps = st.hedge_velocity * DT * np.arange(1, 51)
    checked, sideways = 0, 0.0
    for k, (row, mix, side) in enumerate(rows[False]):
        if mix != 0.0 or side != 0 or k < 7:
            continue
        tool, prev = intent[k - 6], intent[k - 7]
        vel = (tool - prev) / DT
        np.testing.assert_allclose(row, intent[k] + np.outer(steps, [vel[0], 0.0]), atol=1e-9)
        lat_row = rows[True][k][0]
        np.testing.assert_allclose(lat_row, intent[k] + np.outer(steps, vel), atol=1e-9)
        checked += 1
        sideways = max(sideways, abs(vel[1]))
    assert checked > 30 and sideways * steps[-1] > 1e-4  # the two differ by more than 0.1 mm: the test can fail


@pytest.mark.parametrize("noise", [0.0005, 0.001])
def test_the_dead_zone_grows_with_the_persons_calibration_noise(noise):
    # a person who walks a lasting offset left of the plan (no lateral bias learnt): the offset counts for the left
    # way only beyond the dead zone, the larger of dead_zone (2 mm) and dead_zone_noise × the calibration's noise σ₀:
    # 2 mm for σ₀ = 0.5 mm, 3 mm for σ₀ = 1 mm
    model = replace(_model(left=(0.5,), right=(0.5,)), noise=noise)
    for offset in (0.0025, 0.0035):
        intent = _walk(NOMINAL + [0.0, offset])[:600]
        for multiple in (0.0, 3.0):
            zone = max(0.002, multiple * noise)
            settings = PersonFilterSettings(dead_zone_noise=multiple, bias_limit=0.0, side_rule="onset")
            src = PersonPathsIntent(paths={"u": model}, arms={"u": ARM}, settings=settings)
            src.reset(_context())
            prior = src._log_odds
            for k in range(len(intent)):
                _tick(src, intent, k)
            if offset > zone:
                assert src._log_odds > prior + 0.5, (offset, multiple)  # evidence for the left way
            else:
                # within the dead zone: none (the onset rule's log ratio of a zero offset is 0 to an ulp per tick)
                assert abs(src._log_odds - prior) < 1e-12, (offset, multiple)


def test_the_dead_zone_multiple_is_validated():
    with pytest.raises(ValueError, match="dead_zone_noise"):
        PersonFilterSettings(dead_zone_noise=-1.0)


def test_the_rows_keep_the_persons_offset_from_their_curves_fading_over_the_residual_time():
    # a person 3 mm left of their own detour: on its flat top (the curves parallel to the plan) the decided way's
    # rows with residual_time τ are the rows without it plus 3 mm across the plan, fading as e^{−i·dt/τ} along the
    # horizon. Scripted tool positions: the evidence, and so every other part of the rows, is the same in both runs
    tau, shift = 0.2, 0.003
    intent = _walk(_bump(0.5, 0.08) + [0.0, shift])
    rows = {}
    for residual in (0.0, tau):
        src = _ready(PersonFilterSettings(residual_time=residual, bias_limit=0.0))
        rows[residual] = [(_tick(src, intent, k), src.side) for k in range(len(intent))]
    fade = np.exp(-DT * np.arange(1, 51) / tau)
    top = [k for k in range(len(intent)) if abs(intent[k, 0] - 0.5) < 0.03]  # the bump's flat top, ±3 cm
    assert len(top) > 20
    for k in top:
        (plain, side), (kept, side_kept) = rows[0.0][k], rows[tau][k]
        assert side == side_kept == 1
        diff = kept - plain
        np.testing.assert_allclose(diff[:, 0], 0.0, atol=1e-12)  # across the plan only (its normal is y)
        np.testing.assert_allclose(diff[:, 1] / fade, diff[0, 1] / fade[0], rtol=1e-9)  # one offset, fading
        assert abs(diff[0, 1] / fade[0] - shift) < 0.3e-3  # the person's 3 mm off their curves


def test_the_hedge_carries_a_share_of_the_progress_while_the_person_leaves_their_line():
    # undecided (decide out of reach), the hedge rows are the present estimate's plus hedge_velocity·i·dt of the
    # tool's progress along the plan; with hedge_leaving h, while the estimate is further than the dead zone from the
    # person's line (here the plan: no bias), only h of it: the plan's way on is no longer where the person goes
    intent = _walk(NOMINAL)[:400]
    intent[:, 1] = 0.004 * np.sin(np.arange(len(intent)) * 0.05)  # swaying 4 mm: in and out of the 2 mm dead zone
    rows = {}
    for leaving in (1.0, 0.5):
        st = PersonFilterSettings(hedge_lateral=False, hedge_leaving=leaving, bias_limit=0.0, decide=20.0)
        src = _ready(st)
        rows[leaving] = [(_tick(src, intent, k), src._mix) for k in range(len(intent))]
    steps = 0.5 * DT * np.arange(1, 51)
    inside = outside = 0
    for k in range(7, len(intent)):
        (full, mix_full), (part, mix_part) = rows[1.0][k], rows[0.5][k]
        if mix_full != 0.0 or mix_part != 0.0:
            continue
        vel = (intent[k - 6] - intent[k - 7]) / DT
        np.testing.assert_allclose(full, intent[k] + np.outer(steps, [vel[0], 0.0]), atol=1e-9)
        share = 0.5 if abs(intent[k, 1]) > 0.002 else 1.0
        np.testing.assert_allclose(part, intent[k] + np.outer(share * steps, [vel[0], 0.0]), atol=1e-9)
        inside += share == 1.0
        outside += share == 0.5
    assert inside > 20 and outside > 20


def test_the_rows_advance_at_the_persons_pace_when_told_to():
    # pace_time τ_p: the decided way's rows run at the tool's speed along each curve plus the rate of the present
    # estimate's lead along it, (ℓ − ℓ̄)/τ_p, ℓ̄ the lead low-passed over τ_p. On the plan's straight part (the curves
    # flat there to 4e-5 m) the lead is how far the intent is ahead of the tool: a person who slows (0.1 → 0.03 m/s
    # over 0.3 s) pulls the rows back by that rate, computed here from the script alone
    speed = np.concatenate([np.full(120, 0.1), np.linspace(0.1, 0.03, 40), np.full(90, 0.03)])
    intent = np.stack([np.concatenate([[0.0], np.cumsum(speed[:-1] * DT)]), np.zeros(len(speed))], axis=1)
    tau, lag = 0.1, 6
    rows = {}
    for pace in (0.0, tau):
        src = _ready(PersonFilterSettings(pace_time=pace))
        rows[pace] = [_tick(src, intent, k, lag) for k in range(len(intent))]
    gain, low, steps = 1.0 - np.exp(-DT / tau), None, DT * np.arange(1, 51)
    slowed = 0
    for k in range(len(intent)):
        lead = intent[k, 0] - intent[max(k - lag, 0), 0]
        low = lead if low is None else low
        rate = lead - low
        low += gain * rate
        rate /= tau
        tool_speed = (intent[max(k - lag, 0), 0] - intent[max(k - lag - 1, 0), 0]) / DT
        if k < 120 or tool_speed + rate <= 0.0:
            # before the person slows the filter's lead differs from the script's at the start (the tool starting
            # from rest, its inertia put back: 2 % of the start's washout, 4e-6 m/s of rate left at tick 120); where
            # the rows would run backwards they stand still (speed ≥ 0), not this closed form
            continue
        diff = rows[tau][k] - rows[0.0][k]
        np.testing.assert_allclose(diff[:, 0], rate * steps, rtol=0, atol=1e-7)
        np.testing.assert_allclose(diff[:, 1], 0.0, atol=1e-4)
        slowed += rate < -0.005  # at least 5 mm/s slower than the tool
    assert slowed > 20
    with pytest.raises(ValueError, match="pace_time"):
        PersonFilterSettings(pace_time=-0.1)


def test_a_bad_row_costs_one_tick_and_leaves_the_filter_as_it_was():
    """A NaN or an infinity in one feature row is kept out of every state (the hand's filter, the smoothing, the
    bias, the odds): that tick's rows are NaN (the loop's check falls back to the plan for it) and every later row
    is what the filter gives the same trial without that row, bit for bit. Before, one NaN velocity made every later
    row NaN: the loop fell back for the rest of the trial and stopped the arm."""
    intent = _walk(_bump(0.49, 0.08))
    rows = [
        np.array([[*intent[max(k - 6, 0)], *(intent[max(k - 6, 0)] - intent[max(k - 7, 0)]) / DT, 0.0, 0.0, 0.0, 0.0]])
        for k in range(400)
    ]
    for k, row in enumerate(rows):
        row[0, 4:6] = K * (intent[k] - row[0, :2]) - ARM.damping * row[0, 2:4]
    for field, value in ((2, np.nan), (4, np.inf), (0, -np.inf)):
        sources = []
        for src in (
            PersonPathsIntent(paths={"u": _model()}, arms={"u": ARM}),
            PersonPathsIntent(arms={"u": ARM}, extrapolation=0.0),  # the present estimate held
        ):
            twin = PersonPathsIntent(paths=src.paths, arms=src.arms, extrapolation=src.extrapolation)
            src.reset(_context())
            twin.reset(_context())
            sources.append((src, twin))
        bad = rows[150].copy()
        bad[0, field] = value
        for src, twin in sources:
            for k, row in enumerate(rows):
                if k == 150:
                    assert np.isnan(src.predict(bad)).all()  # the bad row: no rows, nothing kept
                got, want = src.predict(row), twin.predict(row)
                np.testing.assert_array_equal(got, want)  # the trial with the row left out, bit for bit
            assert np.isfinite(got).all()


def test_a_person_who_steps_off_every_curve_is_read_on_them_again_where_they_come_back():
    """On a hairpin plan (two legs 15 cm apart) a person who steps 11 cm aside on the first leg (beyond max_offset,
    toward the second leg) and comes back: while off, the rows are the present estimate's; back, the held phases find
    them again. (A search for the phases further along, tried, threw them onto the second leg, nearer the person
    stepped aside, and the rows never read the first leg's curves again, its detour included.)"""
    t = np.linspace(-np.pi / 2, np.pi / 2, 200)
    leg1 = np.stack([np.linspace(0.0, 0.5, 500), np.zeros(500)], axis=1)
    turn = np.stack([0.5 + 0.075 * np.cos(t), 0.075 + 0.075 * np.sin(t)], axis=1)
    leg2 = np.stack([np.linspace(0.5, 0.0, 500), np.full(500, 0.15)], axis=1)
    plan = np.concatenate([leg1, turn[1:], leg2[1:]])

    def detour(a):  # a 3 cm detour on the first leg
        p = plan.copy()
        first = np.arange(len(p)) < 500
        p[first, 1] += a * np.exp(-(((p[first, 0] - 0.25) / 0.08) ** 4))
        return p

    model = fit_path_model(plan, [detour(0.03), detour(0.032), detour(-0.03)], noise=0.001)
    walked = _walk(detour(0.03))
    k0 = int(np.argmax(walked[:, 0] >= 0.12))
    aside = np.stack([np.full(120, walked[k0, 0]), np.linspace(0.0, 0.11, 120)], axis=1)
    intent = np.concatenate([walked[:k0], aside, aside[::-1], walked[k0:]])
    src = PersonPathsIntent(paths={"u": model}, arms={"u": ARM})
    src.reset(_context(path=plan))
    on = []
    for k in range(len(intent)):
        _tick(src, intent, k, lag=0)
        on.append(src.on_curves)
    off = [k for k in range(k0, k0 + 240) if not on[k]]
    # off every curve only while aside, at its farthest (the held phases over 10 cm away)
    assert all(on[:k0]) and off and all(np.abs(intent[off, 1]) > 0.1)
    assert all(on[k0 + 240 :])  # back on the first leg, and on along the rest of the plan


def test_another_plan_whose_points_lie_on_the_models_gets_the_present_estimate():
    """The model knows one plan: a run's plan is the model's only where each lies within 1 cm of the other, both ways,
    and their ends meet. A straight plan from the start of an L to its end (its two points on the L), and the L's
    first half, passed the one-sided test and were given the L's curves."""
    leg = np.linspace(0.0, 0.5, 251)
    ell = np.concatenate([np.stack([leg, np.zeros(251)], axis=1), np.stack([np.full(250, 0.5), leg[1:]], axis=1)])
    model = fit_path_model(ell, [ell + [0.0, 0.0]] * 3, noise=0.001)
    for plan, used in ((ell, True), (ell[[0, -1]], False), (ell[:251], False), (ell + [0.0, 0.02], False)):
        src = PersonPathsIntent(paths={"u": model}, arms={"u": ARM})
        src.reset(_context(path=plan))
        assert src.on_curves is used


def test_the_curves_likelihoods_forget_at_the_memorys_rate():
    # likelihood_memory τ_m: each curve's log-likelihood is the sum of its ticks' terms, each weighted by
    # e^(−age·dt/τ_m), less its way's best (a constant per way, which the weights do not see). The terms are those of
    # the same trial without the memory (whose log-likelihoods sum them unweighted: their tick-to-tick changes, up to a
    # constant per way); the way's evidence does not read the likelihoods, and with no lateral bias (which is learnt
    # while the rows follow a way, and so reads them) both runs see the same ticks. A curve once at the floor of −60 in
    # either run (clipped there) is left out from then on
    tau = 0.3
    intent = _walk(_bump(0.5, 0.08))
    srcs = [_ready(PersonFilterSettings(likelihood_memory=memory, bias_limit=0.0)) for memory in (0.0, tau)]
    hyp = srcs[0]._hyp
    decay = np.exp(-DT / tau)
    summed = np.zeros(len(hyp.ways))
    before = [src._loglik.copy() for src in srcs]
    clipped = np.zeros(len(hyp.ways), dtype=bool)
    checked = 0
    for k in range(len(intent)):
        for src in srcs:
            _tick(src, intent, k)
        plain, kept = srcs[0]._loglik, srcs[1]._loglik
        assert srcs[0].side == srcs[1].side
        clipped |= (plain <= -60.0) | (kept <= -60.0)
        for way in hyp.on_way:
            part = hyp.way_slice[way]
            step = plain[part] - before[0][part]
            q = srcs[0]._q[hyp.by_way[part]]  # the way's curves' present estimates this tick (the same in both runs)
            if np.max(np.sum((q - q.mean(axis=0)) ** 2, axis=1)) < srcs[0].settings.divergence ** 2:
                # the way's curves were not apart: neither run's likelihoods moved
                assert not step.any() and (kept[part] == before[1][part]).all()
                continue
            summed[part] = decay * summed[part] + step
            top = int(np.argmax(kept[part]))
            keep = ~clipped[part]
            if keep[top] and keep.sum() >= 2:
                want = summed[part] - summed[part][top]
                np.testing.assert_allclose(kept[part][keep], want[keep], atol=1e-9 * (1.0 + np.abs(want[keep]).max()))
                checked += 1
        before = [plain.copy(), kept.copy()]
    assert checked > 200
    # and it forgets: without the memory the likelihoods keep what the trial showed early on; with it they are bounded
    # by about τ_m's worth of ticks
    assert np.ptp(srcs[1]._loglik) < np.ptp(srcs[0]._loglik)


def test_the_brake_puts_every_row_its_time_of_the_tools_velocity_behind():
    # brake_time τ_b: every row of a led person is the brake-free filter's row less τ_b·v (v the tool's velocity of
    # the tick), and nothing else of the filter moves (the way, the phases, the likelihoods: the brake reads nothing
    # back); a bad τ_b names its field
    tau = 0.06
    intent = _walk(_bump(0.5, 0.08))
    plain, braked = _ready(PersonFilterSettings()), _ready(PersonFilterSettings(brake_time=tau))
    moving = 0
    for k in range(len(intent)):
        tool_v = _tool(intent, k)[1]  # the velocity _tick tells the filter
        want, got = _tick(plain, intent, k), _tick(braked, intent, k)
        assert got.shape == want.shape == (plain.horizon, 2)
        # one subtraction of the same two floats per column: the same bits as the closed form
        np.testing.assert_array_equal(got, want - np.array((tau * tool_v[0], tau * tool_v[1])))
        assert plain.side == braked.side and (plain._loglik == braked._loglik).all()
        moving += bool(np.any(tool_v))
    assert moving > len(intent) // 2  # the tool moved on most ticks: the brake was measured, not a zero
    with pytest.raises(ValueError, match="brake_time"):
        PersonFilterSettings(brake_time=-0.01)
