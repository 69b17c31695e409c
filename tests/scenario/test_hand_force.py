"""The hand's own force u_h = w + m·â (coassist.scenario.hand_force.HandForce), against a closed form."""

import math

import numpy as np
import pytest

from coassist.scenario.hand_force import HandForce
from coassist.scenario.objects import get_object


def test_under_a_constant_acceleration_the_filter_approaches_it_geometrically():
    """v = a·k·dt: every finite difference is a, so â_k = a (1 − (1 − g)^(k−1)) after k ticks (the first tick has
    no previous velocity: â stays 0) and u_h = w + m·â_k; step (components) and the call (arrays) agree."""
    dt, tau = 0.008, 0.03
    mass = get_object("heavy").mass
    g = 1.0 - math.exp(-dt / tau)
    a, w = np.array([0.4, -0.25]), np.array([2.0, 1.0])
    arrays, parts = HandForce(dt, tau, "heavy"), HandForce(dt, tau, "heavy")
    for k in range(1, 60):
        v = a * k * dt
        u = arrays(v, w)
        ux, uy = parts.step(float(v[0]), float(v[1]), float(w[0]), float(w[1]))
        expected = w + mass * a * (1.0 - (1.0 - g) ** (k - 1))
        # v's rounding (a few ulp of k·dt·a) over dt: a relative 1e-12 of a, times m
        np.testing.assert_allclose(u, expected, rtol=1e-9, atol=1e-9 * mass)
        assert (ux, uy) == tuple(u.tolist())
        assert parts.acceleration == pytest.approx(tuple((u - w) / mass), rel=1e-12, abs=1e-15)


def test_an_object_coassist_does_not_know_carries_no_mass_and_no_filter_means_the_last_difference():
    unknown = HandForce(0.008, 0.0, "a thing coassist does not know")
    assert unknown.mass == 0.0 and unknown.gain == 1.0
    unknown.step(0.0, 0.0, 1.0, 2.0)
    assert unknown.step(0.008, -0.004, 1.0, 2.0) == (1.0, 2.0)  # m = 0: the reading itself
    assert unknown.acceleration == pytest.approx((1.0, -0.5), rel=1e-12)  # g = 1: (v − v_prev)/dt
