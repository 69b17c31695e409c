"""The online-α arbitration against hand-computed values and a fresh game at the same α."""

import math

import numpy as np
import pytest

from coassist.control import AssistiveController, CooperativeGame, Fault
from coassist.control.arbitration import AlphaArbiter, ArbitratedController, ArbitrationParameters, target_alpha
from coassist.model import ImpedanceModel

DT = 0.008


def thesis_game(alpha=0.9, horizon=20):
    model = ImpedanceModel([10, 10], [100, 100], 0, DT)
    Q = 100 * np.diag([1, 1, 1e-4, 1e-4])
    return CooperativeGame(
        model, Q_hh=Q, Q_hr=0, Q_rh=0, Q_rr=Q, R_h=[5e-4, 5e-4], R_r=[1e-4, 1e-4], alpha=alpha, horizon=horizon
    )


def test_target_alpha_of_each_law_by_hand():
    p = ArbitrationParameters(law="hand_force", alpha_min=0.5, alpha_max=0.9, force_scale=4.0)
    assert target_alpha(p, 0.0) == pytest.approx(0.5)
    assert target_alpha(p, 2.0) == pytest.approx(0.7)
    assert target_alpha(p, 40.0) == pytest.approx(0.9)
    c = ArbitrationParameters(law="confidence", alpha_min=0.5, alpha_max=0.9, error_scale=0.01)
    assert target_alpha(c, 0.0) == pytest.approx(0.9)
    assert target_alpha(c, 0.01) == pytest.approx(0.5 + 0.4 / math.e)
    t = ArbitrationParameters(law="target", alpha_min=0.3, alpha_max=0.9, target_scale=0.05)
    assert target_alpha(t, 0.0) == pytest.approx(0.3)
    assert target_alpha(t, 0.02) == pytest.approx(0.3 + 0.6 * 0.4)
    assert target_alpha(t, 0.5) == pytest.approx(0.9)


def test_target_law_reads_the_distance_to_the_plans_horizon_end():
    """e = ||x − y_ref,r(k+H)||: the tool 3 cm from the plan's last row gives α* = 0.3 + 0.6·0.6;
    the filter moves α by dt/τ of the step each tick; NaN in the plan leaves α alone."""
    p = ArbitrationParameters(law="target", alpha_min=0.3, alpha_max=0.9, target_scale=0.05, time_constant=0.08)
    arb = AlphaArbiter(p, 2, DT, alpha0=0.9)
    ref_r = np.zeros((20, 4))
    ref_r[-1, :2] = [0.40, 0.20]  # the plan's horizon ends here (relative to x0, like z)
    z = np.array([0.40, 0.23, 0.0, 0.0])  # 3 cm short of it
    target = 0.3 + 0.6 * 0.6
    a1 = arb.update(z, ref_r, np.zeros(2), ref_r)
    assert a1 == pytest.approx(0.9 + 0.1 * (target - 0.9))  # dt/τ = 0.008/0.08
    bad = ref_r.copy()
    bad[-1, 0] = np.nan
    assert arb.update(z, ref_r, np.zeros(2), bad) == a1
    for _ in range(400):
        a = arb.update(z, ref_r, np.zeros(2), ref_r)
    assert a == pytest.approx(target, abs=1e-9)


def test_alpha_follows_a_constant_hand_force_as_a_first_order_filter():
    p = ArbitrationParameters(law="hand_force", alpha_min=0.5, alpha_max=0.9, force_scale=4.0, time_constant=0.1)
    arb = AlphaArbiter(p, 2, DT, alpha0=0.6)
    g = DT / 0.1
    z, ref = np.zeros(4), np.zeros((20, 4))
    for k in range(1, 31):
        a = arb.update(z, ref, np.array([3.0, 4.0]))  # |w| = 5 N ≥ f_s: α* = 0.9
        assert a == pytest.approx(0.9 + (0.6 - 0.9) * (1 - g) ** k, rel=1e-12)
    # a non-finite force leaves α where it was
    assert arb.update(z, ref, np.array([np.nan, 0.0])) == a
    assert arb.update(z, ref, np.array(["x", object()], dtype=object)) == a
    arb.reset()
    assert arb.alpha == 0.6


def test_confidence_law_scores_the_prediction_made_d_ticks_ago():
    p = ArbitrationParameters(
        law="confidence", alpha_min=0.5, alpha_max=0.9, error_scale=0.01, error_lag=3, time_constant=0.2
    )
    g = DT / 0.2

    def path(k):  # the tool moves 1 mm per tick along x
        return np.array([0.001 * k, 0.0])

    for offset, expected_error in ((0.0, 0.0), (0.02, 0.02)):
        arb = AlphaArbiter(p, 2, DT, alpha0=0.9)
        error, alpha = 0.0, 0.9
        for k in range(60):
            ref = np.zeros((10, 4))
            ref[2, :2] = path(k + 3) + np.array([0.0, offset])  # row d−1 = 2: the position for tick k + 3
            arb.update(np.r_[path(k), 0.0, 0.0], ref, np.zeros(2))
            if k >= 3:  # from tick d on, the prediction made d ticks ago is scored
                error += g * (expected_error - error)
            alpha += g * (target_alpha(p, error) - alpha)
            assert arb.error == pytest.approx(error, abs=1e-12)
            assert arb.alpha == pytest.approx(alpha, abs=1e-12)
        assert (arb.alpha > 0.89) if offset == 0.0 else (arb.alpha < 0.75)


def test_arbitrated_step_is_the_fresh_equilibrium_at_the_arbitrated_alpha():
    rng = np.random.default_rng(3)
    params = ArbitrationParameters(law="hand_force", alpha_min=0.6, alpha_max=0.95, force_scale=5.0, time_constant=0.05)
    ctrl = ArbitratedController(AssistiveController(thesis_game(0.9), effort_limit=np.inf), params)
    assert ctrl.alpha == 0.9
    for _ in range(5):
        z, ref_h, ref_r = rng.normal(size=4) * 0.01, rng.normal(size=(20, 4)) * 0.01, rng.normal(size=(20, 4)) * 0.01
        wrench = rng.normal(size=2) * 3.0
        step = ctrl.step(z, ref_h, ref_r, wrench)
        fresh = thesis_game(ctrl.alpha)  # a new game built at the α the arbiter chose
        u_h, u_r = fresh.solve(z, ref_h, ref_r)
        np.testing.assert_allclose(step.u_r, u_r, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(step.u_h_model, u_h, rtol=1e-9, atol=1e-9)
    assert ctrl.alpha != 0.9
    before = ctrl.alpha
    bad = ctrl.step(np.zeros(4), np.zeros((20, 4)), np.zeros((20, 4)), np.array([np.inf, 0.0]))
    assert bad.fault & Fault.NONFINITE_WRENCH and not bad.u_r.any() and ctrl.alpha == before
    ctrl.reset()
    assert ctrl.alpha == 0.9


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(law="magic"), "arbitration.law"),
        (dict(alpha_min=0.9, alpha_max=0.5), "alpha_min"),
        (dict(alpha_max=1.5), r"arbitration.alpha_max must be in \[0, 1\]"),
        (dict(force_scale=0.0), "arbitration.force_scale"),
        (dict(error_lag=0), "arbitration.error_lag"),
    ],
)
def test_parameters_name_the_bad_field(change, message):
    with pytest.raises(ValueError, match=message):
        ArbitrationParameters(**change)


def test_a_cached_arbitrated_controller_gives_the_same_trial_every_time():
    """run_spec reuses controllers within a batch: the arbitration must start every trial afresh."""
    from coassist.sim import TrialSpec, run_spec

    spec = TrialSpec(
        task="linear", object="handle", controller="cooperative-arbitrated", preset="thesis-application-dm", seed=3
    )
    other = TrialSpec(
        task="curved", object="board", controller="cooperative-arbitrated", preset="thesis-application-dm", seed=4
    )
    alone = run_spec(spec)
    cache: dict = {}
    run_spec(other, cache)
    after_other = run_spec(spec, cache)
    np.testing.assert_array_equal(alone.pose, after_other.pose)
    assert alone.meta.controller == "cooperative+target"


def _online_alpha_twins(law: str, B: int) -> tuple[list[ArbitratedController], list[ArbitratedController]]:
    """Two sets of B online-α controllers alike (each its own game): one stepped in a batch, its twins one by one."""
    params = ArbitrationParameters(
        law=law, alpha_min=0.3, alpha_max=0.9, target_scale=0.05, force_scale=4.0, error_scale=0.01, error_lag=3
    )
    base = thesis_game(alpha=0.7)

    def controllers():
        return [
            ArbitratedController(AssistiveController(base.copy(), effort_limit=[10.0, 12.0]), params) for _ in range(B)
        ]

    return controllers(), controllers()


def _online_alpha_ticks(B: int, seed: int):
    """30 ticks of B runs' controller inputs, each run its own distance to the plan (its own α); at tick 10 row 1's
    state is NaN (refused), row 2 is 2 m from its plan (saturated) and row 3's hand force 1e9 N (out of bounds)."""
    rng = np.random.default_rng(seed)
    offsets = rng.normal(size=(B, 4)) * 0.05
    for k in range(30):
        z = offsets + 0.001 * k
        ref_h = rng.normal(size=(B, 20, 4)) * 0.01
        ref_r = rng.normal(size=(B, 20, 4)) * 0.01 + offsets[:, None, :]
        wrench = rng.normal(size=(B, 2)) * 3.0
        if k == 10:
            z[1, 0] = np.nan
            ref_r[2] += 2.0
            ref_h[2] += 2.0
            wrench[3, 1] = 1e9
        yield k, z, ref_h, ref_r, wrench


@pytest.mark.parametrize("law", ["target", "hand_force", "confidence"])
def test_arbitrated_effort_batch_is_each_controllers_step_bit_for_bit(law):
    """B runs, each with its own controller and α history, stepped together for 30 ticks against
    twins stepped one by one: the same clean efforts bit for bit, the same α after every
    tick, and the rows the guard refuses or saturates are not clean (their α moved as step's)."""
    from coassist.control.arbitration import arbitrated_effort_batch, guard_key

    B = 6
    batch, alone = _online_alpha_twins(law, B)
    assert len({guard_key(c) for c in batch}) == 1
    for k, z, ref_h, ref_r, wrench in _online_alpha_ticks(B, seed=5):
        expected = [c.step(*row) for c, row in zip(alone, zip(z, ref_h, ref_r, wrench))]
        u, clean = arbitrated_effort_batch(batch, z, ref_h, ref_r, wrench)
        np.testing.assert_array_equal(clean, [e.fault == Fault.NONE for e in expected])
        for b in np.flatnonzero(clean):
            np.testing.assert_array_equal(u[b], expected[b].u_r, err_msg=f"tick {k} row {b}")
        assert [c.alpha for c in batch] == [c.alpha for c in alone]
        if k == 10:
            assert not clean[1] and not clean[2] and not clean[3]
    assert len({c.alpha for c in batch}) == B  # the runs' α differ: each row had its own gains
    u0, clean0 = arbitrated_effort_batch(
        [], np.zeros((0, 4)), np.zeros((0, 20, 4)), np.zeros((0, 20, 4)), np.zeros((0, 2))
    )
    assert u0.shape == (0, 2) and clean0.shape == (0,)


@pytest.mark.parametrize("law", ["target", "hand_force", "confidence"])
def test_arbitrated_step_batch_gives_each_controllers_step_bit_for_bit(law):
    """As above, the whole step: every row's u_r, u_h model and flags are its twin's ``step`` bit for bit
    (a refused row, a saturated one, inputs the batch cannot take at all), and the α after every tick."""
    from coassist.control.arbitration import arbitrated_step_batch

    B = 5
    batch, alone = _online_alpha_twins(law, B)
    seen = set()
    for k, z, ref_h, ref_r, wrench in _online_alpha_ticks(B, seed=7):
        if k == 20:  # float32 inputs: the batch does not take them, every row is its own guarded step
            z, ref_h, ref_r, wrench = (a.astype(np.float32) for a in (z, ref_h, ref_r, wrench))
        expected = [c.step(*row) for c, row in zip(alone, zip(z, ref_h, ref_r, wrench))]
        got = arbitrated_step_batch(batch, z, ref_h, ref_r, wrench)
        assert len(got) == B
        for b, (g, e) in enumerate(zip(got, expected)):
            np.testing.assert_array_equal(g.u_r, e.u_r, err_msg=f"tick {k} row {b}")
            np.testing.assert_array_equal(g.u_h_model, e.u_h_model, err_msg=f"tick {k} row {b}")
            assert g.fault == e.fault, (k, b)
            seen.add(e.fault)
        assert [c.alpha for c in batch] == [c.alpha for c in alone]
    assert {Fault.NONE, Fault.SATURATED, Fault.NONFINITE_STATE} <= seen and len(seen) >= 4
    assert len({c.alpha for c in batch}) == B
    assert (
        arbitrated_step_batch([], np.zeros((0, 4)), np.zeros((0, 20, 4)), np.zeros((0, 20, 4)), np.zeros((0, 2))) == []
    )


@pytest.mark.parametrize("alpha0", [math.nan, math.inf, True])
def test_the_arbiter_refuses_an_alpha0_that_is_no_finite_number(alpha0):
    # min/max carried a NaN through: α was NaN on every tick and after every reset
    with pytest.raises(ValueError, match="alpha0 must be"):
        AlphaArbiter(ArbitrationParameters(law="hand_force"), 2, 0.008, alpha0)
