"""The detour families (scenario.detours): each shows what it claims, measured on the paths the
operator generates, against the parameters that generated it; and every family keeps the
properties the project relies on (nothing before the onset tells the side, the box is cleared,
the motion ends at rest at the target, same seed → same trial)."""

import dataclasses

import numpy as np
import pytest
from scipy import optimize
from scipy.signal import find_peaks

from coassist.experiments.realism import turn_stats
from coassist.scenario.detours import (
    FAMILIES,
    Asymmetric,
    Bump,
    Corrective,
    Feint,
    Hesitant,
    Ringing,
    Skewed,
    Swing,
    Window,
    family_from_extra,
    progress_warp,
)
from coassist.scenario.operator import OperatorProfile, intent_trajectory, trial_shape
from coassist.scenario.populations import population_profile
from coassist.scenario.tasks import make_task, task_for_seed

DT = 0.008
N = 6000  # 48 s: every family's motion has ended on every task
Y0 = -0.615  # the linear path runs along +x at this y: its left normal is +y


def _person(family, **kw):
    """A person with a fixed shape (no jitter) passing on the left."""
    base = dict(clearance=0.02, anticipation=0.06, shape_jitter=0.0, pace_jitter=0.0, left_preference=1.0)
    return OperatorProfile("t", detour=family, **{**base, **kw})


def _middle_task(seed=0):
    """The linear path with the small box at 45 % of its length: room for every detour tested here."""
    return make_task("linear", np.random.default_rng(seed), obstacle_range=(0.45, 0.45))


def _lateral(intent):
    """(x, d): the intent's samples along the straight path and its shift to the left of it [m]."""
    return intent.positions[:, 0], intent.positions[:, 1] - Y0


def _crossing(x, y, level):
    """x where y (monotone on the samples given) crosses ``level``, linearly interpolated."""
    order = np.argsort(y)
    return float(np.interp(level, y[order], x[order]))


def _smoothstep_width():
    """u₉₀ − u₁₀ of S(u) = 6u⁵ − 15u⁴ + 10u³ (brentq, independent of the implementation)."""

    def S(u):
        return u**3 * (10 - 15 * u + 6 * u * u)

    return optimize.brentq(lambda u: S(u) - 0.9, 0, 1, xtol=1e-14) - optimize.brentq(
        lambda u: S(u) - 0.1, 0, 1, xtol=1e-14
    )


@pytest.mark.parametrize("ratio", [0.5, 2.0])
def test_asymmetric_returns_over_ratio_times_its_rise(ratio):
    task = _middle_task()
    intent = intent_trajectory(
        task, _person(Asymmetric(return_ratio=ratio, jitter=0.0)), np.random.default_rng(1), N, DT
    )
    x, d = _lateral(intent)
    A = d.max()
    assert A == pytest.approx(intent.amplitude, rel=1e-9)
    top = int(np.argmax(d))
    rise = _crossing(x[:top], d[:top], 0.9 * A) - _crossing(x[:top], d[:top], 0.1 * A)
    back = _crossing(x[top:], d[top:], 0.1 * A) - _crossing(x[top:], d[top:], 0.9 * A)
    width = _smoothstep_width()
    assert rise == pytest.approx(0.06 * width, abs=3e-4)  # the anticipation, sampled every ≤ 1 mm
    assert back / rise == pytest.approx(ratio, rel=0.01)
    # with jitter the trial's own ratio (recorded in the intent) is what the path shows
    jittery = _person(Asymmetric(return_ratio=ratio, jitter=0.3))
    intent = intent_trajectory(task, jittery, np.random.default_rng(5), N, DT)
    assert intent.detour.return_ratio != ratio
    x, d = _lateral(intent)
    top = int(np.argmax(d))
    A = d[top]
    rise = _crossing(x[:top], d[:top], 0.9 * A) - _crossing(x[:top], d[:top], 0.1 * A)
    back = _crossing(x[top:], d[top:], 0.1 * A) - _crossing(x[top:], d[top:], 0.9 * A)
    fit = min(0.06, (task.path.length - task.obstacle_arc - 0.02 - 0.05) / intent.detour.return_ratio)
    assert rise == pytest.approx(fit * width, abs=3e-4)  # shrunk to fit where the return would not
    assert back / rise == pytest.approx(intent.detour.return_ratio, rel=0.01)


@pytest.mark.parametrize("peak", [-1, 1])
def test_skewed_peaks_before_or_after_the_obstacle(peak):
    task = _middle_task()
    skew = 0.4
    intent = intent_trajectory(task, _person(Skewed(skew=skew, peak=peak, jitter=0.0)), np.random.default_rng(1), N, DT)
    x, d = _lateral(intent)
    x_o = task.obstacle.center[0]
    P = 0.03 + 0.02  # half the box along the path plus the clearance: the plateau's half-length
    x_peak = x[int(np.argmax(d))]
    assert np.sign(x_peak - x_o) == peak
    assert x_peak - x_o == pytest.approx(peak * P, abs=2e-3)
    far = float(np.interp(x_o - peak * P, x, d))  # the plateau's other end: the box is cleared by A there
    assert d.max() / far == pytest.approx(1.0 + skew, rel=2e-3)
    assert far == pytest.approx(intent.amplitude, rel=2e-3)
    assert task.obstacle.signed_distance(intent.positions).min() >= 0.01 - 1e-9


def test_swing_overshoots_the_path_on_its_return_and_settles():
    task = _middle_task()
    o, mu = 0.3, 0.8
    intent = intent_trajectory(
        task, _person(Swing(overshoot=o, settle_ratio=mu, jitter=0.0)), np.random.default_rng(1), N, DT
    )
    x, d = _lateral(intent)
    top = int(np.argmax(d))
    assert -d[top:].min() == pytest.approx(o * intent.amplitude, rel=2e-3)
    # the realism statistic on the generated path says the same
    t = np.arange(N) * DT
    assert turn_stats(t, intent.positions, d)["return_overshoot"] == pytest.approx(o * intent.amplitude, rel=2e-3)
    # back on the path a(1 + μ) after the plateau
    x_o = task.obstacle.center[0]
    last = x[np.flatnonzero(np.abs(d) > 1e-7)[-1]]
    assert last - x_o == pytest.approx(0.05 + 0.06 * (1 + mu), abs=1e-3)
    # the shape families' overshoot parameter is the same return
    asym = intent_trajectory(
        task, _person(Asymmetric(return_ratio=1.0, overshoot=o, jitter=0.0)), np.random.default_rng(1), N, DT
    )
    assert -_lateral(asym)[1].min() == pytest.approx(o * asym.amplitude, rel=2e-3)


def test_corrective_is_made_of_its_sub_movements():
    task = _middle_task()
    family = Corrective(
        out_weights=(1.0, 0.7, 1.2), back_weights=(0.8, 1.2), overlap=0.25, overshoot=0.25, dips=4, dip_depth=0.6,
        dip_width=0.4, jitter=0.0,
    )  # fmt: skip
    person = _person(family, anticipation=0.07)
    intent = intent_trajectory(task, person, np.random.default_rng(1), N, DT)
    x, d = _lateral(intent)
    # the lateral path: one speed bell per stroke (3 out, 2 back, the correction)
    moving = np.flatnonzero(np.diff(x) > 1e-6)
    slope = np.abs(np.diff(d)[moving] / np.diff(x)[moving])
    strokes, _ = find_peaks(slope, prominence=0.02 * slope.max())
    assert len(strokes) == 3 + 2 + 1
    # swinging through the path on the return by the overshoot
    top = int(np.argmax(d))
    assert -d[top:].min() == pytest.approx(0.25 * intent.amplitude, rel=2e-3)
    # the progress: realism's sub-movement count on the trajectory is the dips + 1 (the bump's: 1)
    t = np.arange(N) * DT
    assert turn_stats(t, intent.positions, d)["submovements"] == 4 + 1
    plain = intent_trajectory(task, _person(Hesitant(depth=0.0, jitter=0.0)), np.random.default_rng(1), N, DT)
    assert turn_stats(t, plain.positions, _lateral(plain)[1])["submovements"] == 1
    # each dip slows the progress to (1 − depth): the speed against the same person's without dips (the
    # same path), at the same place
    smooth = intent_trajectory(
        task, _person(dataclasses.replace(family, dips=0), anticipation=0.07), np.random.default_rng(1), N, DT
    )
    ratio = _speed_ratio(intent, smooth)
    slow = ratio < 1.0 - 0.3
    starts = np.flatnonzero(slow[1:] & ~slow[:-1])
    assert len(starts) == 4
    assert ratio.min() == pytest.approx(1.0 - 0.6, abs=0.01)


def test_feint_leans_the_other_way_before_going_round():
    task = _middle_task()
    lean, ratio = 0.25, 1.0
    intent = intent_trajectory(
        task, _person(Feint(lean=lean, lean_ratio=ratio, jitter=0.0)), np.random.default_rng(1), N, DT
    )
    assert intent.side == 1
    x, d = _lateral(intent)
    x_o = task.obstacle.center[0]
    # the right first, by lean · A, at its deepest before the rise to the left has begun (λ = 1: −P − 1.5a) ...
    low = int(np.argmin(d))
    assert -d[low] == pytest.approx(lean * intent.amplitude, rel=2e-3)
    assert x[low] - x_o == pytest.approx(-(0.05 + 1.5 * 0.06), abs=1e-3)
    # ... then round the left, the bump's height, the box cleared
    assert d.max() == pytest.approx(intent.amplitude, rel=2e-3) and x[int(np.argmax(d))] > x[low]
    assert task.obstacle.signed_distance(intent.positions).min() >= 0.01 - 1e-9
    # it leaves the path 2λa before the rise's half (−P − a/2 − 2λa) and is back on it a after the plateau
    # (f is exactly 0 off the detour, so any threshold above rounding finds its ends; 1 mm: the ticks' spacing along
    # the path, ≤ 0.5 mm at this pace, plus where a smoothstep of a few cm first exceeds 1e-12 m, ~10 µm)
    leaving = np.flatnonzero(np.abs(d) > 1e-12)
    assert x[leaving[0]] - x_o == pytest.approx(-(0.05 + 0.03 + 2 * ratio * 0.06), abs=1e-3)
    assert x[leaving[-1]] - x_o == pytest.approx(0.05 + 0.06, abs=1e-3)


def test_ringing_swings_through_the_path_each_swing_decay_times_the_last():
    task = _middle_task()
    o, r, mu = 0.3, 0.5, 0.8
    family = Ringing(overshoot=o, decay=r, swings=3, swing_ratio=mu, jitter=0.0)
    intent = intent_trajectory(task, _person(family), np.random.default_rng(1), N, DT)
    x, d = _lateral(intent)
    top = int(np.argmax(d))
    # after the top, each run on one side of the path has its extreme: −o A, +o r A, −o r² A, then the path
    after = d[top:]
    signs = np.sign(np.where(np.abs(after) > 1e-9, after, 0.0))
    runs = np.split(after, np.flatnonzero(np.diff(signs))[0:] + 1)
    extremes = [float(run[np.argmax(np.abs(run))]) for run in runs if np.abs(run).max() > 1e-9][1:]
    A = intent.amplitude
    assert extremes == pytest.approx([-o * A, o * r * A, -o * r * r * A], rel=2e-3)
    # back on the path a + 3 μ a after the plateau
    x_o = task.obstacle.center[0]
    last = x[np.flatnonzero(np.abs(d) > 1e-12)[-1]]  # exactly 0 after it: the threshold only above rounding
    assert last - x_o == pytest.approx(0.05 + 0.06 * (1 + 3 * mu), abs=1e-3)
    # one swing is the swing family's return (its settle ratio μ), up to the rounding of its other sum (a few ulp of 1)
    u = np.linspace(-0.3, 0.4, 2001)
    np.testing.assert_allclose(
        Ringing(overshoot=o, swings=1, swing_ratio=mu).profile(u, 0.05, 0.06),
        Swing(overshoot=o, settle_ratio=mu).profile(u, 0.05, 0.06),
        rtol=0.0,
        atol=1e-15,
    )


def test_every_familys_profile_is_exactly_0_outside_its_reach_and_not_just_inside():
    """f = 0 exactly before −P − k_b a and after P + k_a a (:meth:`DetourFamily.reach`): the path is the plan's there,
    to the last bit (where the operator's onset and the target are read); and the detour does reach both ends."""
    P, a = 0.05, 0.06
    families = [population_profile(pop, u, 3).detour.trial(np.random.default_rng(u)) for pop, u in PEOPLE]
    for family in [*families, Bump()]:
        k_b, k_a = family.reach()
        lo, hi = -P - k_b * a, P + k_a * a
        # strictly outside (at the ends themselves a stroke's unit time may round to just under 1)
        outside = np.concatenate([np.linspace(lo - 0.5, lo - 1e-6, 200), np.linspace(hi + 1e-6, hi + 3.0, 600)])
        f_out = family.profile(outside, P, a)
        assert not np.any(f_out), (family, outside[np.flatnonzero(f_out)[:3]])
        inside = np.array([lo + 0.02 * a, hi - 0.02 * a])
        assert np.all(family.profile(inside, P, a) != 0.0), family


def _arc(positions):
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])


def _speed_ratio(slowed, plain):
    """|v| of ``slowed`` over |v| of ``plain`` at the same arc length along their (common) path, where both move."""
    s_slow, s_plain = _arc(slowed.positions), _arc(plain.positions)
    v_slow, v_plain = np.linalg.norm(slowed.velocities, axis=1), np.linalg.norm(plain.velocities, axis=1)
    inc = np.concatenate([[True], np.diff(s_plain) > 0])
    ref = np.interp(s_slow, s_plain[inc], v_plain[inc])
    where = (ref > 0.02) & (s_slow > 1e-3)
    return v_slow[where] / ref[where]


@pytest.mark.parametrize("depth", [0.7, 1.0])
def test_hesitant_slows_down_at_the_onset_for_its_duration(depth):
    task = _middle_task()
    family = Hesitant(depth=depth, duration=0.6, delay=0.1, ramp=0.25, jitter=0.0)
    rng_seed = 3
    intent = intent_trajectory(task, _person(family), np.random.default_rng(rng_seed), N, DT)
    plain = intent_trajectory(
        task, _person(dataclasses.replace(family, depth=0.0)), np.random.default_rng(rng_seed), N, DT
    )
    # the same path; the same motion until `delay` after the detour's onset
    first = int(np.flatnonzero(np.any(intent.positions != plain.positions, axis=1))[0])
    onset = int(np.flatnonzero(np.abs(plain.positions[:, 1] - Y0) > 0.0)[0])  # where the path leaves the nominal one
    assert (first - onset) * DT == pytest.approx(0.1, abs=2 * DT)
    # the speed at the same place dips to (1 − depth) of the plain one: a pause where depth = 1
    assert _speed_ratio(intent, plain).min() == pytest.approx(1.0 - depth, abs=0.01)
    if depth == 1.0:
        still = np.linalg.norm(intent.velocities, axis=1) == 0.0
        still[:onset] = False
        run = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]]))))[0]
        assert run * DT == pytest.approx(0.6 * (1 - 2 * 0.25), abs=2 * DT)  # the hold between the ramps
    # it costs depth · duration · (1 − ramp) of time, measured where both have passed the window
    lost = depth * 0.6 * (1 - 0.25)
    assert intent.end_time - plain.end_time == pytest.approx(lost, rel=1e-6)
    t = np.arange(N) * DT
    late = (t > onset * DT + 2.0) & (t < plain.end_time)
    x_late = np.interp(t[late] - lost, t, plain.positions[:, 0])
    assert np.max(np.abs(intent.positions[late, 0] - x_late)) < 2e-4  # m: the plain motion, `lost` later


def test_the_warp_is_its_integral_and_costs_the_documented_time():
    # w' from progress_warp integrated numerically (trapezoid, fine grid) against its closed-form w
    windows = (Window(0.3, 0.5, 0.8, 0.25), Window(1.5, 0.4, 1.0, 0.5), Window(2.5, 0.6, 0.3, 0.1))
    u = np.linspace(0.0, 4.0, 400_001)
    w, dw = progress_warp(u, windows)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (dw[1:] + dw[:-1]) * np.diff(u))])
    assert np.max(np.abs(w - integral)) < 1e-9
    assert w[-1] == pytest.approx(4.0 - sum(win.time_lost for win in windows), abs=1e-12)
    assert dw.min() == 0.0 and np.all(np.diff(w) >= 0)


def _forced_side_intents(task, profile, seed, n=N):
    left = intent_trajectory(
        task, dataclasses.replace(profile, left_preference=1.0), np.random.default_rng(seed), n, DT
    )
    right = intent_trajectory(
        task, dataclasses.replace(profile, left_preference=0.0), np.random.default_rng(seed), n, DT
    )
    return left, right


PEOPLE = [(pop, user) for pop in ("varied", "held-out", "unseen") for user in range(6)]


@pytest.mark.parametrize(("population", "user"), PEOPLE)
def test_every_family_keeps_the_operators_properties(population, user):
    profile = population_profile(population, user)
    for kind in ("linear", "curved", "sinusoidal", "z"):
        for seed, obstacle in ((0, "small"), (1, "small"), (2, "large")):
            task = task_for_seed(kind, 700 + seed, obstacle=obstacle)
            left, right = _forced_side_intents(task, profile, seed)
            assert (left.side, right.side) in ((1, -1), (1, 1), (-1, -1))  # a side may be impossible (the Z)
            # before the detour's onset the same intent, bit for bit, whichever side is drawn (the first tick
            # past the onset's point may round to the same position and differ in velocity alone)
            differ = np.any(left.positions != right.positions, axis=1) | np.any(
                left.velocities != right.velocities, axis=1
            )
            apart = np.flatnonzero(differ)
            assert apart.size or left.side == right.side
            if apart.size:
                k = apart[0]
                assert k > 0
                np.testing.assert_array_equal(left.positions[:k], right.positions[:k])
                np.testing.assert_array_equal(left.velocities[:k], right.velocities[:k])
                assert np.min(np.linalg.norm(left.positions[k][None] - task.path.points, axis=1)) < 1e-3
            for intent in (left, right):
                # the box cleared by half this trial's clearance (the draws: side, pace, shape)
                rng = np.random.default_rng(seed)
                rng.random(), rng.normal()
                clearance, _ = trial_shape(profile, rng)
                assert task.obstacle.signed_distance(intent.positions).min() >= 0.5 * clearance - 1e-9
                # ends at rest at the target
                np.testing.assert_allclose(intent.positions[-1], task.target, atol=1e-9)
                assert not intent.velocities[-1].any()
                assert intent.end_time < (N - 1) * DT
                assert type(intent.detour) in (type(profile.detour), Bump)  # Bump: the family did not fit
            # same seed, same trial
            again = intent_trajectory(
                task, dataclasses.replace(profile, left_preference=1.0), np.random.default_rng(seed), N, DT
            )
            assert np.array_equal(again.positions, left.positions) and again.detour == left.detour


def test_families_round_trip_through_their_record_and_name_bad_fields():
    for population, user in PEOPLE:
        family = population_profile(population, user).detour
        assert family_from_extra(family.to_extra()) == family
    assert set(FAMILIES) == {"asymmetric", "skewed", "swing", "corrective", "hesitant", "feint", "ringing", "bump"}
    assert family_from_extra(Bump().to_extra()) == Bump()
    with pytest.raises(ValueError, match="Asymmetric.return_ratio"):
        Asymmetric(return_ratio=0.0)
    with pytest.raises(ValueError, match="Skewed.peak"):
        Skewed(peak=0)
    with pytest.raises(ValueError, match="Corrective.out_weights"):
        Corrective(out_weights=())
    with pytest.raises(ValueError, match="Hesitant.depth"):
        Hesitant(depth=1.5)
    with pytest.raises(ValueError, match="Feint.lean"):
        Feint(lean=-0.1)
    with pytest.raises(ValueError, match="Ringing.swings"):
        Ringing(swings=0)
    with pytest.raises(ValueError, match="unknown parameters"):
        family_from_extra({"family": "swing", "overshot": 0.2})
    with pytest.raises(ValueError, match="OperatorProfile.detour"):
        OperatorProfile("t", detour="swing")


def test_a_family_that_does_not_fit_goes_round_as_the_bump_and_says_so():
    # a return 15 anticipations long with a swing-through cannot end before the path's end: the bump instead
    task = _middle_task()
    person = _person(Asymmetric(return_ratio=15.0, overshoot=0.5, jitter=0.0))
    intent = intent_trajectory(task, person, np.random.default_rng(1), N, DT)
    assert isinstance(intent.detour, Bump)
    np.testing.assert_allclose(intent.positions[-1], task.target, atol=1e-9)
    assert task.obstacle.signed_distance(intent.positions).min() >= 0.01 - 1e-9
    x, d = _lateral(intent)
    top = int(np.argmax(d))
    rise = _crossing(x[:top], d[:top], 0.9 * d[top]) - _crossing(x[:top], d[:top], 0.1 * d[top])
    back = _crossing(x[top:], d[top:], 0.1 * d[top]) - _crossing(x[top:], d[top:], 0.9 * d[top])
    assert back / rise == pytest.approx(1.0, rel=0.01) and d.min() > -1e-12  # symmetric, no swing-through
