"""Deceleration-gated damping (issue 34): the law against its equation, and the wrapper."""

import numpy as np
import pytest

from coassist.control.controllers import ControlStep
from coassist.control.deceleration_damping import DampingParameters, DecelerationDamping, deceleration_damping
from coassist.control.presets import DECELERATION_DAMPING, get_preset, make_controller
from coassist.interfaces import Fault
from coassist.model.impedance import ImpedanceModel

P = DampingParameters(gain=40.0, decel_ref=0.5, accel_time=0.0)


def test_law_is_the_gated_damping_of_the_docstring():
    v = np.array([0.1, 0.0])
    # slowing down at 0.25 m/s² along the motion: half the gate, −0.5·40·v (the gate goes through a dot
    # product, a norm and two quotients: up to ~5 roundings, whatever BLAS computes them)
    np.testing.assert_allclose(deceleration_damping(v, np.array([-0.25, 0.3]), P), -0.5 * 40.0 * v, rtol=1e-14)
    # past a_ref the gate is full; speeding up or turning at constant speed: nothing
    np.testing.assert_allclose(deceleration_damping(v, np.array([-2.0, 0.0]), P), -40.0 * v, rtol=1e-15)
    np.testing.assert_array_equal(deceleration_damping(v, np.array([0.3, 0.0]), P), 0.0)
    np.testing.assert_array_equal(deceleration_damping(v, np.array([0.0, 1.0]), P), 0.0)
    np.testing.assert_array_equal(deceleration_damping(np.zeros(2), np.array([-1.0, 0.0]), P), 0.0)
    # a batch is row for row the single law; the extra force never points along the motion
    rng = np.random.default_rng(0)
    V, A = rng.normal(size=(50, 2)), rng.normal(size=(50, 2))
    batch = deceleration_damping(V, A, P)
    for b in range(50):
        np.testing.assert_array_equal(batch[b], deceleration_damping(V[b], A[b], P))
    assert (np.sum(batch * V, axis=1) <= 0.0).all()


class _Constant:
    """A stand-in controller: a fixed effort, a flag on demand."""

    def __init__(self, model, u, fault=Fault.NONE):
        self.name, self.model, self.horizon, self.effort_limit = "constant", model, 1, np.array([30.0, 30.0])
        self.u, self.fault = np.asarray(u, float), fault

    def step(self, z, ref_h, ref_r, wrench):
        return ControlStep(self.u.copy(), np.zeros(2), self.fault)


def _model():
    return ImpedanceModel(np.diag([10.0, 10.0]), np.diag([100.0, 100.0]), np.zeros((2, 2)), 0.008)


def test_wrapper_adds_the_law_with_the_tools_acceleration():
    ctrl = DecelerationDamping(_Constant(_model(), [1.0, -2.0]), P)
    ref = np.zeros((1, 4))
    z0 = np.array([0.0, 0.0, 0.10, 0.0])
    z1 = np.array([0.0, 0.0, 0.098, 0.0])  # −0.25 m/s² over one tick
    np.testing.assert_array_equal(ctrl.step(z0, ref, ref, np.zeros(2)).u_r, [1.0, -2.0])  # no acceleration yet
    out = ctrl.step(z1, ref, ref, np.zeros(2))
    a = (z1[2:] - z0[2:]) / 0.008
    np.testing.assert_allclose(out.u_r, np.array([1.0, -2.0]) + deceleration_damping(z1[2:], a, P), rtol=1e-15)
    # a refused tick stays refused; reset forgets the velocity
    refused = DecelerationDamping(_Constant(_model(), [0.0, 0.0], Fault.NONFINITE_STATE), P)
    refused.step(z0, ref, ref, np.zeros(2))
    assert refused.step(z1, ref, ref, np.zeros(2)).u_r.tolist() == [0.0, 0.0]
    ctrl.reset()
    np.testing.assert_array_equal(ctrl.step(z1, ref, ref, np.zeros(2)).u_r, [1.0, -2.0])


def test_wrapper_saturates_keeping_the_direction():
    ctrl = DecelerationDamping(
        _Constant(_model(), [29.0, 0.0]), DampingParameters(gain=1000.0, decel_ref=0.1, accel_time=0.0)
    )
    ref = np.zeros((1, 4))
    ctrl.step(np.array([0, 0, -0.5, 0.5]), ref, ref, np.zeros(2))
    out = ctrl.step(np.array([0, 0, -0.4, 0.4]), ref, ref, np.zeros(2))
    assert out.fault & Fault.SATURATED
    assert np.max(np.abs(out.u_r)) == pytest.approx(30.0)


def test_damped_kind_is_the_arbitrated_controller_with_the_preset_law():
    ctrl = make_controller("cooperative-damped", get_preset("thesis-application-damped"))
    assert isinstance(ctrl, DecelerationDamping) and ctrl.params == DECELERATION_DAMPING
    assert ctrl.alpha == pytest.approx(0.9)
    with pytest.raises(ValueError, match="DampingParameters.decel_ref"):
        DampingParameters(decel_ref=0.0)


@pytest.mark.parametrize("bad", [None, np.array([0.0]), np.array([0.0, 0.0, 0.2])], ids=repr)
def test_a_state_of_other_dofs_is_refused_and_leaves_the_filter(bad):
    # the inner controller flags it; the wrapper neither raises (None, [0.0]) nor reads a short state's tail as the
    # velocity into its acceleration estimate (a 3-long state was broadcast into â and moved the efforts after it)
    ref = np.zeros((1, 4))
    z0 = np.array([0.0, 0.0, 0.10, 0.0])
    z1 = np.array([0.0, 0.0, 0.098, 0.0])  # −0.25 m/s² over one tick

    def efforts(with_bad_tick):
        ctrl = DecelerationDamping(_Constant(_model(), [1.0, -2.0]), P)
        ctrl.step(z0, ref, ref, np.zeros(2))
        if with_bad_tick:
            assert ctrl.step(bad, ref, ref, np.zeros(2)).u_r.tolist() == [1.0, -2.0]  # the inner step, nothing added
        return ctrl.step(z1, ref, ref, np.zeros(2)).u_r

    np.testing.assert_array_equal(efforts(True), efforts(False))
