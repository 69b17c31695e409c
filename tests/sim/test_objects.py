"""The carried objects and the force sensor (coassist.scenario.objects) against hand computation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coassist.control.presets import get_preset, make_controller, plant_model
from coassist.scenario import AUTHOR, ForceSensor, make_task
from coassist.scenario.objects import GRAVITY, OBJECTS, CarriedObject, get_object
from coassist.sim import run_trial

# ------------------------------------------------------------------ the three objects


def test_masses_are_the_materials_times_the_volumes():
    # §5.1: a 106 × 82 × 2 cm plywood board (450 kg/m³) and an 18 × 15.5 × 5 cm steel
    # block (7850 kg/m³); the 3D-printed handle is taken as massless.
    assert get_object("handle").mass == 0.0
    assert get_object("board").mass == pytest.approx(450.0 * 1.06 * 0.82 * 0.02, rel=1e-12)  # 7.8228 kg
    assert get_object("board").mass == pytest.approx(7.8228, abs=1e-4)
    assert get_object("heavy").mass == pytest.approx(7850.0 * 0.18 * 0.155 * 0.05, rel=1e-12)  # 10.95 kg
    assert get_object("heavy").mass == pytest.approx(10.950750, abs=1e-6)


def test_centres_and_grasps_are_where_the_thesis_holds_them():
    board = get_object("board")
    a, b = board.size
    assert (a, b) == (1.06, 0.82)
    # The cup is 0.2 m from the board's centre on the robot's side (+y of the centre)...
    assert board.center_offset == (0.0, -0.20)
    # ...and the operator holds the near edge: centre − b/2 along −y, 0.61 m from the cup.
    assert board.grasp_offset[0] == 0.0
    assert board.grasp_offset[1] == pytest.approx(board.center_offset[1] - b / 2, abs=1e-12)
    assert board.has_yaw
    # The handle and the block are held at the sensor axis: no lever, no yaw mode.
    for name in ("handle", "heavy"):
        obj = get_object(name)
        assert obj.center_offset == (0.0, 0.0) and obj.grasp_offset == (0.0, 0.0) and not obj.has_yaw


def _plate_inertia_by_quadrature(mass, size, center, n=400):
    """Σ m_i |r_i|² over an n × n grid of equal point masses covering the plate."""
    a, b = size
    xs = center[0] + (np.arange(n) + 0.5) / n * a - a / 2
    ys = center[1] + (np.arange(n) + 0.5) / n * b - b / 2
    X, Y = np.meshgrid(xs, ys)
    return float(np.sum(X * X + Y * Y) * mass / (n * n))


@pytest.mark.parametrize("name", ["board", "heavy"])
def test_yaw_inertia_about_the_cup_matches_quadrature(name):
    obj = get_object(name)
    reference = _plate_inertia_by_quadrature(obj.mass, obj.size, obj.center_offset)
    # the midpoint rule underestimates a²/12 by a factor (1 − 1/n²): 6e-6 at n = 400
    assert obj.yaw_inertia == pytest.approx(reference, rel=1e-5)


def test_board_yaw_inertia_by_hand():
    # I_c = m (a² + b²)/12 + m |r_c|² = 7.8228 (1.1236 + 0.6724)/12 + 7.8228 · 0.04
    m = 450.0 * 1.06 * 0.82 * 0.02
    assert get_object("board").yaw_inertia == pytest.approx(m * (1.7960 / 12 + 0.04), rel=1e-12)  # ≈ 1.4837 kg·m²
    assert get_object("board").yaw_inertia == pytest.approx(1.48373, abs=1e-5)
    assert get_object("handle").yaw_inertia == 0.0


def test_parallel_axis_shift():
    # Moving the cup by d from the centre adds m d² (Steiner), whatever the direction.
    centred = CarriedObject("plate", mass=2.0, size=(0.3, 0.4))
    for offset in [(0.1, 0.0), (0.0, -0.1), (0.06, 0.08)]:
        shifted = CarriedObject("plate", mass=2.0, size=(0.3, 0.4), center_offset=offset)
        assert shifted.yaw_inertia == pytest.approx(centred.yaw_inertia + 2.0 * 0.1**2, rel=1e-12)
    assert centred.yaw_inertia == pytest.approx(2.0 * (0.09 + 0.16) / 12, rel=1e-12)


def test_an_object_survives_its_json_form():
    for obj in OBJECTS.values():
        assert CarriedObject(**obj.to_extra()) == obj


@pytest.mark.parametrize(
    "kwargs, culprit",
    [
        (dict(name=""), "CarriedObject.name"),
        (dict(name="x", mass=-1.0), "CarriedObject.mass"),
        (dict(name="x", mass=float("nan")), "CarriedObject.mass"),
        (dict(name="x", mass="heavy"), "CarriedObject.mass"),
        (dict(name="x", size=(1.0, 2.0, 3.0)), "CarriedObject.size"),
        (dict(name="x", center_offset=(0.0, math.inf)), "CarriedObject.center_offset"),
        (dict(name="x", yaw_stiffness=10.0), "CarriedObject.mass must be > 0 when yaw_stiffness"),
        (dict(name="x", mass=1.0, yaw_damping=-1.0), "CarriedObject.yaw_damping"),
    ],
)
def test_bad_objects_name_the_field(kwargs, culprit):
    with pytest.raises(ValueError, match=culprit):
        CarriedObject(**kwargs)


def test_unknown_object_lists_the_known_ones():
    with pytest.raises(ValueError, match=r"object must be one of \('handle', 'board', 'heavy'\), got 'piano'"):
        get_object("piano")


# ------------------------------------------------------------------ the sensor


def test_sample_ticks_at_100_hz_on_a_125_hz_loop():
    # Sample index floor(0.8 k): the tick after each whole 5-tick block (k ≡ 1 mod 5)
    # sees the previous sample again, so 4 ticks in 5 are fresh: 1000 samples in 10 s.
    fresh = ForceSensor(rate_hz=100.0).sample_ticks(1250, 0.008)
    k = np.arange(1250)
    np.testing.assert_array_equal(fresh, k % 5 != 1)
    assert fresh.sum() == 1000
    assert ForceSensor(rate_hz=None).sample_ticks(7, 0.008).all()


def test_weight_leaks_through_the_tilt_in_proportion_to_the_mass():
    # With no offset the raw bias is m g sin(tilt), tilt ~ N(0, σ): its spread is
    # m g σ (to first order), and the massless handle shows none at all.
    sensor = ForceSensor(offset=0.0, tilt=0.02)
    rng = np.random.default_rng(7)
    board = get_object("board")
    biases = np.array([sensor.raw_bias(board, rng) for _ in range(20000)])
    expected = board.mass * GRAVITY * 0.02  # 1.535 N
    np.testing.assert_allclose(biases.std(axis=0), expected, rtol=0.03)
    np.testing.assert_allclose(biases.mean(axis=0), 0.0, atol=0.05)
    assert not np.any(sensor.raw_bias(get_object("handle"), rng))


def test_zeroing_leaves_the_mean_of_the_rest_noise():
    # The estimate averages zero_samples readings: its error has σ/√n per axis.
    sensor = ForceSensor(noise=0.5, zero_samples=25)
    rng = np.random.default_rng(3)
    bias = np.array([2.0, -1.0])
    residual = np.array([bias - sensor.zero(bias, rng) for _ in range(20000)])
    np.testing.assert_allclose(residual.std(axis=0), 0.5 / 5.0, rtol=0.03)
    np.testing.assert_allclose(residual.mean(axis=0), 0.0, atol=0.005)


@pytest.mark.parametrize(
    "kwargs, culprit",
    [
        (dict(noise=-0.1), "ForceSensor.noise"),
        (dict(rate_hz=0.0), "ForceSensor.rate_hz"),
        (dict(zero_samples=0), "ForceSensor.zero_samples"),
        (dict(zero_samples=True), "ForceSensor.zero_samples"),
        (dict(saturation=-1.0), "ForceSensor.saturation"),
    ],
)
def test_bad_sensors_name_the_field(kwargs, culprit):
    with pytest.raises(ValueError, match=culprit):
        ForceSensor(**kwargs)


# ------------------------------------------------------------------ the object in the loop


IDEAL = ForceSensor(noise=0.0, offset=0.0, tilt=0.0, rate_hz=None)  # reads F_s exactly, every tick


def _trial(name):
    preset = get_preset("thesis-evaluation")
    task = make_task("linear", np.random.default_rng(0))
    trial = run_trial(task, AUTHOR, get_object(name), make_controller("impedance", preset), seed=3, sensor=IDEAL)
    model = plant_model(preset)
    return trial, np.diag(model.M), np.diag(model.D)


def _zoh_velocity(v, force, mass, damping, dt):
    """Exact ZOH of m v̇ + d v = f per axis: v⁺ = e v + (1 − e) f / d, e = exp(−d dt / m)."""
    e = np.exp(-damping * dt / mass)
    return e * v + (1.0 - e) * force / damping


@pytest.mark.parametrize("name", ["handle", "heavy"])
def test_the_object_adds_its_mass_to_the_rendered_inertia(name):
    # (M + m) a + D v = u_h + u_r and F_s = u_h − m a, from the logged rows alone.
    trial, M, D = _trial(name)
    m, dt = get_object(name).mass, trial.meta.dt
    v, uh, ur = trial.velocity, trial.effort_h, trial.effort_r
    np.testing.assert_allclose(v[1:], _zoh_velocity(v[:-1], uh[:-1] + ur[:-1], M + m, D, dt), rtol=0, atol=1e-12)
    accel = np.diff(v, axis=0) / dt
    np.testing.assert_allclose(trial.wrench[1:], uh[:-1] - m * accel, rtol=0, atol=1e-9)
    if m > 0:  # and the mass matters: without it the velocity would be off
        wrong = _zoh_velocity(v[:-1], uh[:-1] + ur[:-1], M, D, dt)
        assert np.abs(v[1:] - wrong).max() > 1e-3


def test_the_board_yaws_about_the_cup_with_its_inertia():
    # The board's centre is r_c = (0, −0.2) from the cup, so its angular acceleration θ̈
    # adds −m θ̈ J r_c = (−0.2 m θ̈, 0) to both the sensor and the tip (module docstring).
    # Recover θ̈ from the sensor's x residual, check the tip saw the same term, and that θ̈
    # obeys I_c θ̈ = r_h × F_h − m r_c × a − k_θ θ − c_θ θ̇ with I_c computed by hand.
    trial, M, D = _trial("board")
    board = get_object("board")
    m, dt = board.mass, trial.meta.dt
    v, uh, ur = trial.velocity, trial.effort_h, trial.effort_r
    accel = np.diff(v, axis=0) / dt
    lever = trial.wrench[1:] - (uh[:-1] - m * accel)  # the yaw term seen by the sensor
    np.testing.assert_allclose(lever[:, 1], 0.0, atol=1e-9)  # r_c has no x part: nothing along y
    free = _zoh_velocity(v[:-1], uh[:-1] + ur[:-1], M + m, D, dt)
    e = np.exp(-D * dt / (M + m))
    lever_tip = (v[1:] - free) * D / (1.0 - e)  # the same term, seen through the plant
    np.testing.assert_allclose(lever_tip, lever, rtol=0, atol=1e-8)
    thdd = lever[:, 0] / (-0.2 * m)
    assert np.abs(thdd).max() > 0.1  # the board does yaw

    # The torque balance, integrated as the world does (semi-implicit Euler), with
    # I_c = m (a² + b²)/12 + m |r_c|², r_h = (0, −0.61): r_h × F_h = 0.61 F_h,x and
    # m r_c × a = 0.2 m a_x (a from the previous tick).
    inertia = m * (1.06**2 + 0.82**2) / 12 + m * 0.2**2
    residual = np.empty_like(thdd)
    th = thd = 0.0
    ax_prev = 0.0
    for k in range(len(thdd)):
        torque = 0.61 * uh[k, 0] - 0.2 * m * ax_prev - 150.0 * th - 8.0 * thd
        residual[k] = thdd[k] - torque / inertia
        thd += thdd[k] * dt
        th += thd * dt
        ax_prev = accel[k, 0]
    # (I_c without the parallel-axis term m |r_c|² leaves residuals of 0.2 rad/s² here)
    assert np.abs(residual).max() < 1e-9
