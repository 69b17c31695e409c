"""The guarded controllers: the law when inputs are good, zero effort and a flag when not."""

import logging

import numpy as np
import pytest

from coassist.config import THESIS_EVALUATION
from coassist.control import (
    AssistiveController,
    Fault,
    ImpedanceControl,
    ManualGuidance,
    cooperative_game,
    saturate,
)
from coassist.model import ImpedanceModel


@pytest.fixture
def plant():
    p = THESIS_EVALUATION.impedance
    return ImpedanceModel(p.M, p.D, p.K, p.dt)


@pytest.fixture
def assistive(plant):
    return AssistiveController(cooperative_game(plant, THESIS_EVALUATION.game), effort_limit=50.0)


def inputs(rng, horizon=50):
    return (
        rng.normal(size=4) * 0.01,
        rng.normal(size=(horizon, 4)) * 0.01,
        rng.normal(size=(horizon, 4)) * 0.01,
        rng.normal(size=2),
    )


def test_unsaturated_step_is_the_game_solution(assistive):
    z, ref_h, ref_r, wrench = inputs(np.random.default_rng(0))
    out = assistive.step(z, ref_h, ref_r, wrench)
    u_h, u_r = assistive.game.solve(z, ref_h, ref_r)
    assert out.fault == Fault.NONE
    np.testing.assert_array_equal(out.u_r, u_r)
    np.testing.assert_array_equal(out.u_h_model, u_h)


@pytest.mark.parametrize(
    "where, flag",
    [
        ("z", Fault.NONFINITE_STATE),
        ("ref_h", Fault.NONFINITE_REFERENCE),
        ("ref_r", Fault.NONFINITE_REFERENCE),
        ("wrench", Fault.NONFINITE_WRENCH),
    ],
)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_gives_zero_effort_and_a_flag(assistive, where, flag, bad):
    z, ref_h, ref_r, wrench = inputs(np.random.default_rng(1))
    args = {"z": z, "ref_h": ref_h, "ref_r": ref_r, "wrench": wrench}
    args[where].flat[1] = bad
    out = assistive.step(**args)
    assert out.fault & flag
    np.testing.assert_array_equal(out.u_r, [0.0, 0.0])


def test_fault_is_logged_once_and_the_loop_recovers(assistive, caplog):
    z, ref_h, ref_r, wrench = inputs(np.random.default_rng(2))
    bad = wrench.copy()
    bad[0] = np.nan
    with caplog.at_level(logging.WARNING, logger="coassist.control.controllers"):
        for _ in range(5):
            assistive.step(z, ref_h, ref_r, bad)
    assert len([r for r in caplog.records if "NONFINITE_WRENCH" in r.getMessage()]) == 1
    assert assistive.step(z, ref_h, ref_r, wrench).fault == Fault.NONE


def test_saturation_keeps_direction_and_respects_the_limit():
    u, clipped = saturate(np.array([30.0, -40.0]), np.array([10.0, 10.0]))
    assert clipped
    np.testing.assert_allclose(u, [7.5, -10.0])  # scaled by 10/40
    u, clipped = saturate(np.array([3.0, -4.0]), np.array([10.0, 10.0]))
    assert not clipped
    np.testing.assert_array_equal(u, [3.0, -4.0])


def test_controller_saturates_large_efforts(plant):
    controller = AssistiveController(cooperative_game(plant, THESIS_EVALUATION.game), effort_limit=1.0)
    ref_h = np.tile([0.3, 0.0, 0.0, 0.0], (50, 1))  # 30 cm away: a large effort
    out = controller.step(np.zeros(4), ref_h, np.zeros((50, 4)), np.zeros(2))
    raw = controller.game.solve(np.zeros(4), ref_h, np.zeros((50, 4)))[1]
    assert out.fault == Fault.SATURATED
    assert np.max(np.abs(out.u_r)) == pytest.approx(1.0)
    np.testing.assert_allclose(out.u_r / np.linalg.norm(out.u_r), raw / np.linalg.norm(raw))


@pytest.mark.parametrize(
    "args",
    [
        (np.zeros(4), np.zeros((3, 4)), np.zeros((50, 4)), np.zeros(2)),  # short reference
        (np.zeros(4), np.zeros((50, 4)), np.zeros((50, 4)), np.zeros(7)),  # wrench of another DOF count
        (0.5, np.zeros((50, 4)), np.zeros((50, 4)), np.zeros(2)),  # scalar state
        (np.zeros(4) + 1j, np.zeros((50, 4)), np.zeros((50, 4)), np.zeros(2)),  # complex state
        (np.zeros(4), "x", np.zeros((50, 4)), np.zeros(2)),  # not numbers
    ],
)
def test_invalid_inputs_never_raise_inside_the_loop(assistive, args):
    out = assistive.step(*args)
    assert out.fault == Fault.INVALID_INPUT
    np.testing.assert_array_equal(out.u_r, [0.0, 0.0])


def test_non_finite_model_of_the_human_is_caught(assistive, monkeypatch):
    monkeypatch.setattr(assistive.game, "solve", lambda z, rh, rr: (np.array([-np.inf, 0.0]), np.array([1.0, 1.0])))
    out = assistive.step(*inputs(np.random.default_rng(3)))
    assert out.fault == Fault.NONFINITE_EFFORT
    np.testing.assert_array_equal(out.u_r, [0.0, 0.0])
    np.testing.assert_array_equal(out.u_h_model, [0.0, 0.0])


def test_a_law_that_raises_gives_zero_effort(assistive, monkeypatch):
    def broken(z, rh, rr):
        raise RuntimeError("boom")

    monkeypatch.setattr(assistive.game, "solve", broken)
    out = assistive.step(*inputs(np.random.default_rng(4)))
    assert out.fault == Fault.INTERNAL_ERROR
    np.testing.assert_array_equal(out.u_r, [0.0, 0.0])


def test_controllers_refuse_a_plant_with_stiffness(plant):
    stiff = plant.with_stiffness([10.0, 10.0])
    with pytest.raises(ValueError, match="model.K must be zero"):
        ManualGuidance(stiff)
    with pytest.raises(ValueError, match="model.K must be zero"):
        ImpedanceControl(stiff, 100.0, effort_limit=50.0)


def test_impedance_control_saturates_too(plant):
    imp = ImpedanceControl(plant, 1000.0, effort_limit=20.0)
    out = imp.step(np.zeros(4), np.zeros((1, 4)), np.array([[0.1, 0.0, 0.0, 0.0]]), np.zeros(2))
    np.testing.assert_allclose(out.u_r, [20.0, 0.0])
    assert out.fault == Fault.SATURATED


def test_impedance_control_is_a_spring_toward_the_nominal_reference(plant):
    imp = ImpedanceControl(plant, [200.0, 100.0], effort_limit=np.inf)
    z = np.array([0.1, 0.2, 5.0, 5.0])
    ref_r = np.array([[0.15, 0.1, 0.0, 0.0]])
    out = imp.step(z, np.zeros((1, 4)), ref_r, np.zeros(2))
    np.testing.assert_allclose(out.u_r, [200 * 0.05, 100 * -0.1])  # K (x_ref,r − x), hand computed
    assert imp.name == "impedance"


def test_manual_guidance_applies_no_effort(plant):
    mg = ManualGuidance(plant)
    out = mg.step(np.ones(4), np.ones((1, 4)) * 3, np.ones((1, 4)) * 2, np.ones(2))
    np.testing.assert_array_equal(out.u_r, [0.0, 0.0])
    assert out.fault == Fault.NONE


@pytest.mark.parametrize(
    "limit, message",
    [
        ([10.0, 0.0], "effort_limit must be > 0"),
        ([1, 2, 3], "effort_limit must be a number or 2"),
        ("a", "effort_limit must be a number"),
    ],
)
def test_effort_limit_is_validated(plant, limit, message):
    with pytest.raises(ValueError, match=message):
        ImpedanceControl(plant, 100.0, effort_limit=limit)


def test_effort_limit_is_required(plant):
    with pytest.raises(TypeError):
        AssistiveController(cooperative_game(plant, THESIS_EVALUATION.game))


# ---------------------------------------------------------------------- step_batch (lockstep runs)
def _batch(rng, B=12, horizon=50):  # B ≥ 8: the rows below
    """B ticks' inputs: ordinary rows and, at fixed rows, each kind of input the guard refuses or
    saturates, so every branch of step() is met inside one batch."""
    z = rng.normal(size=(B, 4)) * 0.01
    ref_h = rng.normal(size=(B, horizon, 4)) * 0.01
    ref_r = rng.normal(size=(B, horizon, 4)) * 0.01
    wrench = rng.normal(size=(B, 2))
    z[1, 0] = np.nan  # NONFINITE_STATE
    ref_h[2, 1, 3] = np.inf  # NONFINITE_REFERENCE
    ref_r[3, 0, 1] = 1e3  # finite, beyond InputBounds: INVALID_INPUT
    wrench[4, 1] = -np.inf  # NONFINITE_WRENCH
    ref_r[5:8] += 2.0  # references 2 m away, the tool at 3 m/s: efforts past the limits (SATURATED)
    ref_h[5:8] += 2.0
    z[5:8, 2:] = -3.0
    return z, ref_h, ref_r, wrench


def _controllers(plant):
    return {
        "cooperative": AssistiveController(cooperative_game(plant, THESIS_EVALUATION.game), effort_limit=[10.0, 12.0]),
        "impedance": ImpedanceControl(plant, [800.0, 400.0], effort_limit=20.0),
        "manual": ManualGuidance(plant),
    }


@pytest.mark.parametrize("kind", ["cooperative", "impedance", "manual"])
def test_step_batch_is_step_row_for_row_bit_for_bit(plant, kind, caplog):
    ctrl = _controllers(plant)[kind]
    z, ref_h, ref_r, wrench = _batch(np.random.default_rng(11))
    ref_rows = ref_h.shape[1] if kind == "cooperative" else 3  # IMP and MG take any rows ≥ 1
    ref_h, ref_r = ref_h[:, :ref_rows].copy(), ref_r[:, :ref_rows].copy()
    reference = _controllers(plant)[kind]  # a twin: warnings are per controller, once each
    expected = [reference.step(*row) for row in zip(z, ref_h, ref_r, wrench)]
    got = ctrl.step_batch(z, ref_h, ref_r, wrench)
    assert len(got) == len(expected)
    for b, (e, g) in enumerate(zip(expected, got)):
        assert g.fault == e.fault, b
        np.testing.assert_array_equal(g.u_r, e.u_r, err_msg=f"row {b}")
        np.testing.assert_array_equal(g.u_h_model, e.u_h_model, err_msg=f"row {b}")
    faults = [e.fault for e in expected]
    assert faults[1] & Fault.NONFINITE_STATE and faults[2] & Fault.NONFINITE_REFERENCE
    assert faults[3] == Fault.INVALID_INPUT and faults[4] & Fault.NONFINITE_WRENCH
    if kind != "manual":  # the rows the law pushes past the limit are scaled, as step() scales them
        assert all(faults[b] == Fault.SATURATED for b in (5, 7)) and faults[0] == Fault.NONE
    assert ctrl._warned == reference._warned  # the refused rows were reported as step() reports them


@pytest.mark.parametrize("kind", ["cooperative", "impedance", "manual"])
def test_effort_batch_gives_the_clean_steps_efforts_bit_for_bit(plant, kind):
    """The array path's call: clean[b] exactly where step() carries no flag (refused and
    saturated rows are not clean), and there u_r[b] is step()'s bit for bit; nothing warned."""
    ctrl = _controllers(plant)[kind]
    z, ref_h, ref_r, wrench = _batch(np.random.default_rng(14))
    expected = [_controllers(plant)[kind].step(*row) for row in zip(z, ref_h, ref_r, wrench)]
    u, clean = ctrl.effort_batch(z, ref_h, ref_r, wrench)
    assert u.shape == (z.shape[0], 2) and clean.dtype == bool
    np.testing.assert_array_equal(clean, [e.fault == Fault.NONE for e in expected])
    assert clean[0] and not clean[1:5].any() and (kind == "manual" or not clean[5:8].any())
    for b in np.flatnonzero(clean):
        np.testing.assert_array_equal(u[b], expected[b].u_r, err_msg=f"row {b}")
    np.testing.assert_array_equal(u[~clean], 0.0)
    assert ctrl._warned == Fault.NONE  # a row that is not clean was not stepped here
    # odd inputs (float32 rows): step() per row decides, the same answer
    u32, clean32 = ctrl.effort_batch(z.astype(np.float32), ref_h, ref_r, wrench)
    want32 = [_controllers(plant)[kind].step(*row) for row in zip(z.astype(np.float32), ref_h, ref_r, wrench)]
    np.testing.assert_array_equal(clean32, [e.fault == Fault.NONE for e in want32])
    for b in np.flatnonzero(clean32):
        np.testing.assert_array_equal(u32[b], want32[b].u_r)


def test_step_batch_falls_back_to_step_for_other_inputs(assistive):
    """float32 rows, a wrong shape, a law that raises: step() per row decides, as alone."""
    z, ref_h, ref_r, wrench = (a[:4] for a in _batch(np.random.default_rng(12)))
    z32 = z.astype(np.float32)
    for got, want in zip(
        assistive.step_batch(z32, ref_h, ref_r, wrench), [assistive.step(*r) for r in zip(z32, ref_h, ref_r, wrench)]
    ):
        assert got.fault == want.fault
        np.testing.assert_array_equal(got.u_r, want.u_r)
    short = ref_h[:, :10]
    assert all(s.fault == Fault.INVALID_INPUT for s in assistive.step_batch(z, short, ref_r, wrench))


def test_step_batch_survives_a_law_that_raises(assistive, monkeypatch):
    def broken(z, rh, rr):
        raise RuntimeError("boom")

    monkeypatch.setattr(assistive.game, "solve", broken)
    monkeypatch.setattr(assistive.game, "solve_batch", broken)
    z, ref_h, ref_r, wrench = (a[:3] for a in _batch(np.random.default_rng(13)))
    out = assistive.step_batch(z, ref_h, ref_r, wrench)
    assert [s.fault for s in out] == [Fault.INTERNAL_ERROR, Fault.NONFINITE_STATE, Fault.NONFINITE_REFERENCE]
    for s in out:
        np.testing.assert_array_equal(s.u_r, [0.0, 0.0])
