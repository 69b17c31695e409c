"""Fault injection on the controller step: ``step`` never raises, bad input is flagged.

Every case hands one bad argument to the assistive controller, IMP and MG and checks
that the tick returns zero robot effort with the expected flag instead of raising or
quietly converting the input (issue 12, "The tick"). Good inputs in other forms
(lists, ints, torch tensors without grad, references longer than one row for the
baselines) give the same effort as the plain float arrays, computed independently.
"""

from __future__ import annotations

import numpy as np
import pytest

from coassist.control import (
    AssistiveController,
    CooperativeGame,
    Fault,
    ImpedanceControl,
    InputBounds,
    ManualGuidance,
)
from coassist.model import ImpedanceModel

H = 50
MODEL = ImpedanceModel(M=[10, 10], D=[100, 100], K=[0, 0], dt=0.008)
Q = np.diag([1, 1, 1e-4, 1e-4])
K_IMP = np.diag([200.0, 200.0])


def controllers():
    game = CooperativeGame(
        MODEL, Q_hh=Q, Q_hr=0, Q_rh=0, Q_rr=Q, R_h=[5e-4, 5e-4], R_r=[1e-4, 1e-4], alpha=0.9, horizon=H
    )
    return {
        "cooperative": AssistiveController(game, effort_limit=100.0),
        "impedance": ImpedanceControl(MODEL, K_IMP, effort_limit=100.0),
        "manual": ManualGuidance(MODEL),
    }


def good_inputs():
    """A state 1 cm off along x, the human heading +x, the nominal reference at rest."""
    z = np.array([0.01, 0.0, 0.0, 0.0])
    ref_h = np.zeros((H, 4))
    ref_h[:, 0] = np.linspace(0.001, 0.05, H)
    ref_r = np.zeros((H, 4))
    return z, ref_h, ref_r, np.array([2.0, 0.0])


class RaisingFloat:
    def __float__(self):
        raise RuntimeError("no float for you")


class RaisingArray:
    def __array__(self, dtype=None, copy=None):
        raise KeyError("broken __array__")


def _replace(args, index, value):
    out = list(args)
    out[index] = value
    return tuple(out)


def bad_cases():
    """(case id, argument index, bad value, expected flag)."""
    z, ref_h, ref_r, w = good_inputs()
    huge_int = np.array([10**400, 0, 0, 0], dtype=object)
    cases = [
        ("z-object-10**400", 0, huge_int, Fault.INVALID_INPUT),
        ("ref_h-object-10**400", 1, np.array([[10**400] * 4] * H, dtype=object), Fault.INVALID_INPUT),
        ("wrench-object-10**400", 3, np.array([10**400, 0], dtype=object), Fault.INVALID_INPUT),
        ("z-list-10**400", 0, [10**400, 0, 0, 0], Fault.INVALID_INPUT),
        ("z-float-raises", 0, [RaisingFloat(), 0.0, 0.0, 0.0], Fault.INVALID_INPUT),
        ("wrench-float-raises", 3, np.array([RaisingFloat(), 0.0], dtype=object), Fault.INVALID_INPUT),
        ("z-array-raises", 0, RaisingArray(), Fault.INVALID_INPUT),
        ("z-bool", 0, np.array([True, False, False, False]), Fault.INVALID_INPUT),
        ("ref_h-bool", 1, np.ones((H, 4), dtype=bool), Fault.INVALID_INPUT),
        ("ref_r-bool", 2, np.zeros((H, 4), dtype=bool), Fault.INVALID_INPUT),
        ("wrench-bool", 3, np.array([True, False]), Fault.INVALID_INPUT),
        ("wrench-bool-mixed-list", 3, [True, 0.5], Fault.INVALID_INPUT),
        ("z-numeric-strings", 0, np.array(["0.01", "0", "0", "0"]), Fault.INVALID_INPUT),
        ("wrench-numeric-strings-list", 3, ["2.0", "0.0"], Fault.INVALID_INPUT),
        ("ref_r-bytes", 2, np.zeros((H, 4), dtype="S3"), Fault.INVALID_INPUT),
        ("z-complex", 0, z + 0j, Fault.INVALID_INPUT),
        ("z-None", 0, None, Fault.INVALID_INPUT),
        ("z-dict", 0, {"x": 0.0}, Fault.INVALID_INPUT),
        ("z-scalar", 0, 0.0, Fault.INVALID_INPUT),
        ("z-wrong-length", 0, np.zeros(3), Fault.INVALID_INPUT),
        ("z-(4,1)", 0, np.zeros((4, 1)), Fault.INVALID_INPUT),
        ("wrench-(6,)", 3, np.zeros(6), Fault.INVALID_INPUT),
        ("ref_h-no-rows", 1, np.zeros((0, 4)), Fault.INVALID_INPUT),
        ("ref_r-3-columns", 2, np.zeros((H, 3)), Fault.INVALID_INPUT),
        ("ref_h-1-D", 1, np.zeros(4 * H), Fault.INVALID_INPUT),
        # finite but implausible: flagged, not merely saturated
        ("z-1e200", 0, np.array([1e200, 0, 0, 0]), Fault.INVALID_INPUT),
        ("z-velocity-1e3", 0, np.array([0, 0, 1e3, 0]), Fault.INVALID_INPUT),
        ("ref_h-1e200", 1, np.full((H, 4), 1e200), Fault.INVALID_INPUT),
        (
            "ref_r-1e200",
            2,
            _replace((ref_r,), 0, np.where(np.arange(H)[:, None] == 3, 1e200, 0.0))[0],
            Fault.INVALID_INPUT,
        ),
        ("ref_h-1e6-m", 1, np.full((H, 4), 1e6), Fault.INVALID_INPUT),
        ("wrench-100-kN", 3, np.array([1e5, 0.0]), Fault.INVALID_INPUT),
        # non-finite: its own flag
        ("z-nan", 0, np.array([np.nan, 0, 0, 0]), Fault.NONFINITE_STATE),
        ("ref_h-inf", 1, np.full((H, 4), np.inf), Fault.NONFINITE_REFERENCE),
        ("wrench-nan", 3, np.array([0.0, np.nan]), Fault.NONFINITE_WRENCH),
    ]
    if np.finfo(np.longdouble).max > np.finfo(np.float64).max:  # x86 extended precision
        cases.append(("z-longdouble-1e4000", 0, np.array([np.longdouble("1e4000"), 0, 0, 0]), Fault.NONFINITE_STATE))
    return cases


BAD = bad_cases()


@pytest.mark.parametrize("name", ["cooperative", "impedance", "manual"])
@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_bad_input_is_flagged_never_raised(name, case):
    _, index, value, flag = case
    controller = controllers()[name]
    args = _replace(good_inputs(), index, value)
    step = controller.step(*args)  # must not raise
    assert step.fault & flag, f"{case[0]}: expected {flag!r}, got {step.fault!r}"
    np.testing.assert_array_equal(step.u_r, np.zeros(2))
    np.testing.assert_array_equal(step.u_h_model, np.zeros(2))


def test_torch_tensors():
    torch = pytest.importorskip("torch")
    controller = controllers()["cooperative"]
    z, ref_h, ref_r, w = good_inputs()
    reference = controller.step(z, ref_h, ref_r, w)
    assert reference.fault == Fault.NONE and np.abs(reference.u_r).max() > 0.1
    with_grad = torch.tensor(z, requires_grad=True)
    assert controller.step(with_grad, ref_h, ref_r, w).fault == Fault.INVALID_INPUT
    plain = controller.step(torch.tensor(z), torch.tensor(ref_h), torch.tensor(ref_r), torch.tensor(w))
    assert plain.fault == Fault.NONE
    np.testing.assert_allclose(plain.u_r, reference.u_r, rtol=1e-12)


def test_lists_and_ints_are_numbers():
    controller = controllers()["cooperative"]
    z, ref_h, ref_r, w = good_inputs()
    reference = controller.step(z, ref_h, ref_r, w)
    as_lists = controller.step(z.tolist(), ref_h.tolist(), ref_r.tolist(), [2, 0])
    assert as_lists.fault == Fault.NONE
    np.testing.assert_array_equal(as_lists.u_r, reference.u_r)
    ints = controller.step(np.zeros(4, dtype=np.int32), np.zeros((H, 4), dtype=np.int64), ref_r, np.zeros(2, int))
    assert ints.fault == Fault.NONE


def test_inputs_just_inside_the_bounds_are_used():
    bounds = InputBounds()
    controller = controllers()["impedance"]
    z = np.array([bounds.position, 0.0, bounds.velocity, 0.0])  # exactly at the bound: plausible
    step = controller.step(z, np.zeros((1, 4)), np.zeros((1, 4)), np.array([bounds.wrench, 0.0]))
    assert not step.fault & Fault.INVALID_INPUT
    # IMP's spring K (x_ref,r − x) = 200 · (0 − 10) N, saturated to the 100 N limit
    assert step.fault == Fault.SATURATED
    np.testing.assert_allclose(step.u_r, [-100.0, 0.0])


def test_bounds_are_configurable_and_validated():
    tight = ImpedanceControl(MODEL, K_IMP, effort_limit=100.0, bounds=InputBounds(position=0.005))
    z, ref_h, ref_r, w = good_inputs()  # z is 1 cm off: beyond a 5 mm bound
    assert tight.step(z, ref_h, ref_r, w).fault == Fault.INVALID_INPUT
    for bad in (0.0, -1.0, np.nan, "ten"):
        with pytest.raises(ValueError, match="InputBounds.position"):
            InputBounds(position=bad)
    with pytest.raises(ValueError, match="bounds must be an InputBounds"):
        ManualGuidance(MODEL, bounds={"position": 1.0})


def test_baselines_take_the_assistive_controllers_references():
    """IMP and MG accept the (50, 4) references built for the game and read their first row."""
    c = controllers()
    z, ref_h, ref_r, w = good_inputs()
    ref_r = ref_r.copy()
    ref_r[:, 0] = np.linspace(0.03, 0.2, H)  # nominal ahead of the tool; only row 0 (x_ref,r(k+1)) matters
    imp = c["impedance"].step(z, ref_h, ref_r, w)
    assert imp.fault == Fault.NONE
    np.testing.assert_allclose(imp.u_r, [200.0 * (0.03 - 0.01), 0.0])  # K (x_ref,r(k+1) − x), by hand: 4 N
    one_row = c["impedance"].step(z, ref_h[:1], ref_r[:1], w)
    np.testing.assert_array_equal(one_row.u_r, imp.u_r)
    mg = c["manual"].step(z, ref_h, ref_r, w)
    assert mg.fault == Fault.NONE
    np.testing.assert_array_equal(mg.u_r, np.zeros(2))
    # the assistive controller itself still wants exactly `horizon` rows
    assert c["cooperative"].step(z, ref_h[:10], ref_r[:10], w).fault == Fault.INVALID_INPUT


def test_a_bad_tick_does_not_poison_the_next():
    controller = controllers()["cooperative"]
    args = good_inputs()
    before = controller.step(*args)
    for _, index, value, _flag in BAD:
        controller.step(*_replace(args, index, value))
    after = controller.step(*args)
    assert after.fault == before.fault == Fault.NONE
    np.testing.assert_array_equal(after.u_r, before.u_r)
