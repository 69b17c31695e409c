"""The point-mass plant step against the impedance model's matrices and the closed-form mass-damper."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coassist.model import ImpedanceModel, PointMassPlant, plant_step

DT = 0.008


def test_the_plant_is_the_impedance_models_zoh_with_the_added_mass():
    """Per-axis coefficients = the entries of A_d, B_d of (M + m, D, K = 0); one step equals
    A_d z + B_d u of that model to rounding (the off-diagonal entries are exact zeros)."""
    model = ImpedanceModel(np.diag([4.0, 7.0]), np.diag([30.0, 55.0]), np.diag([100.0, 0.0]), DT)
    plant = PointMassPlant.free(model, added_mass=2.5)
    free = ImpedanceModel(np.diag([6.5, 9.5]), np.diag([30.0, 55.0]), np.zeros((2, 2)), DT)
    assert plant.n_dof == 2
    assert plant.a_xv == (free.Ad[0, 2], free.Ad[1, 3]) and plant.a_vv == (free.Ad[2, 2], free.Ad[3, 3])
    assert plant.b_x == (free.Bd[0, 0], free.Bd[1, 1]) and plant.b_v == (free.Bd[2, 0], free.Bd[3, 1])
    rng = np.random.default_rng(0)
    for _ in range(20):
        z, u = rng.normal(0.0, 1.0, 4), rng.normal(0.0, 10.0, 2)
        x, v = plant_step(
            z[:2], z[2:], u, np.array(plant.a_xv), np.array(plant.a_vv), np.array(plant.b_x), np.array(plant.b_v)
        )
        np.testing.assert_allclose(np.concatenate([x, v]), free.step(z, u), rtol=1e-13, atol=1e-15)


def test_a_constant_force_follows_the_closed_form():
    # (M + m) v' + D v = F from rest: v(t) = F/D (1 − e^{−t D/(M+m)}), x(t) = F/D (t − (M+m)/D (1 − e^{−t D/(M+m)}))
    model = ImpedanceModel(np.diag([5.0, 5.0]), np.diag([40.0, 40.0]), np.zeros((2, 2)), DT)
    plant = PointMassPlant.free(model, added_mass=1.0)
    x = v = 0.0
    for _ in range(400):
        x, v = plant_step(x, v, 12.0, plant.a_xv[0], plant.a_vv[0], plant.b_x[0], plant.b_v[0])
    t, mass, d = 400 * DT, 6.0, 40.0
    e = math.exp(-t * d / mass)
    assert v == pytest.approx(12.0 / d * (1 - e), rel=1e-10)
    assert x == pytest.approx(12.0 / d * (t - mass / d * (1 - e)), rel=1e-10)


def test_rows_of_an_array_step_are_the_float_steps_bit_for_bit():
    """The one step serves floats (a per-trial world) and arrays (the array path): the same bits."""
    rng = np.random.default_rng(1)
    B = 50
    plants = [
        PointMassPlant.free(
            ImpedanceModel(np.diag(rng.uniform(1, 20, 2)), np.diag(rng.uniform(5, 80, 2)), np.zeros((2, 2)), DT),
            added_mass=float(rng.uniform(0, 8)),
        )
        for _ in range(B)
    ]
    coeffs = [np.array([getattr(p, name) for p in plants]) for name in ("a_xv", "a_vv", "b_x", "b_v")]
    x, v, f = rng.normal(0.0, 1.0, (B, 2)), rng.normal(0.0, 1.0, (B, 2)), rng.normal(0.0, 30.0, (B, 2))
    xa, va = plant_step(x, v, f, *coeffs)
    for b, p in enumerate(plants):
        for axis in range(2):
            xs, vs = plant_step(
                float(x[b, axis]),
                float(v[b, axis]),
                float(f[b, axis]),
                p.a_xv[axis],
                p.a_vv[axis],
                p.b_x[axis],
                p.b_v[axis],
            )
            assert (xs, vs) == (xa[b, axis], va[b, axis])


def test_the_plant_refuses_coupled_axes_and_a_negative_mass():
    coupled = ImpedanceModel(np.array([[4.0, 0.5], [0.5, 4.0]]), np.diag([30.0, 30.0]), np.zeros((2, 2)), DT)
    with pytest.raises(ValueError, match="diagonal M"):
        PointMassPlant.free(coupled)
    model = ImpedanceModel(np.diag([4.0, 4.0]), np.diag([30.0, 30.0]), np.zeros((2, 2)), DT)
    with pytest.raises(ValueError, match="added_mass"):
        PointMassPlant.free(model, added_mass=-1.0)
    with pytest.raises(ValueError, match="ImpedanceModel"):
        PointMassPlant.free("model")  # type: ignore[arg-type]
