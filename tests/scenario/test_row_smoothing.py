"""RowSmoothing (coassist.scenario.row_smoothing) against the first-order filter's closed forms."""

import math

import numpy as np
import pytest

from coassist.scenario.row_smoothing import RowSmoothing

DT = 0.008
H = 50


def test_a_step_of_every_row_follows_the_discrete_first_order_response():
    """Rows that jump from 0 to 1 (after a first tick at 0): row i after k more ticks is 1 − (1 − g)^k, the
    closed form of R̄(t) = R̄(t − dt) + g (R − R̄) from R̄ = 0; the advance moves rows, not values."""
    tau = 0.08
    smooth = RowSmoothing(DT, tau, H)
    g = 1.0 - math.exp(-DT / tau)
    smooth(np.zeros((H, 2)))
    for k in range(1, 40):
        out = smooth(np.ones((H, 2)))
        # k steps of the recursion against one power: each step rounds once, so k ulps of 1 at most (a few)
        np.testing.assert_allclose(out, 1.0 - (1.0 - g) ** k, rtol=0, atol=4 * k * np.finfo(float).eps)


@pytest.mark.parametrize("tau", [0.04, 0.08, 0.12])
def test_rows_along_a_path_at_steady_speed_come_out_as_they_went_in(tau):
    """Rows of a tool moving at a steady 0.1 m/s: row i at tick t is x(t + (i + 1) dt). Once the transient is
    gone (many time constants) the filter lags by L = (1 − g)/g ticks and the advance m = round(L) gives it
    back: the output is the input to within |L − m| ticks of motion (≤ half a tick, 0.4 mm here)."""
    speed = np.array([0.1, 0.05])
    smooth = RowSmoothing(DT, tau, H)
    g = 1.0 - math.exp(-DT / tau)
    lag = (1.0 - g) / g
    assert smooth.advance == round(lag)
    rows = lambda t: (t + DT * np.arange(1, H + 1))[:, None] * speed  # noqa: E731
    for k in range(int(30 * tau / DT)):
        out = smooth(rows(k * DT))
    error = np.abs(out - rows(k * DT))
    expected = abs(lag - smooth.advance) * DT * np.abs(speed)  # the rounding of the lag, per axis
    np.testing.assert_allclose(error, np.broadcast_to(expected, error.shape), rtol=1e-6, atol=1e-12)
    # without the advance the rows would trail by the whole lag: several times the error left
    assert np.all(lag * DT * np.abs(speed) > 5 * expected)


def test_noise_from_tick_to_tick_is_cut_by_the_filters_variance_ratio():
    """White noise of variance 1 on every row. Each row's output is scipy.signal.lfilter's first-order
    recursion of its input (started at the first input), advanced by m rows, to rounding; and its variance
    is g/(2 − g) (the recursion's stationary variance). Over 200 000 ticks the variance estimate of an AR(1)
    series with ρ = 1 − g has a relative standard error sqrt(2 (1 + ρ²) / (N (1 − ρ²))) ≈ 1.0 % here; the
    bound is four of them."""
    from scipy.signal import lfilter

    tau, n, rows = 0.08, 200_000, 4
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 1.0, (n, rows, 2))
    smooth = RowSmoothing(DT, tau, rows)
    g, m = smooth.gain, smooth.advance
    assert m == rows - 2  # the advance kept to H − 2: row 0 is the filter's row 2
    out = np.array([smooth(x[k]) for k in range(n)])
    reference = lfilter([g], [1.0, -(1.0 - g)], x[:, m, :], axis=0, zi=(1.0 - g) * x[0:1, m, :])[0]
    np.testing.assert_allclose(out[:, 0, :], reference, rtol=0, atol=1e-12)
    rho = 1.0 - g
    se = math.sqrt(2.0 * (1.0 + rho**2) / (n * (1.0 - rho**2)))
    assert np.var(out[1000:, 0, :]) == pytest.approx(g / (2.0 - g), rel=4 * se)


def test_zero_time_constant_hands_the_rows_on_and_bad_values_name_the_field():
    rows = np.arange(2 * H, dtype=float).reshape(H, 2)
    smooth = RowSmoothing(DT, 0.0, H)
    assert smooth(rows) is rows and smooth.advance == 0
    assert RowSmoothing(DT, 0.08, 1).advance == 0  # one row: nothing to advance into
    assert RowSmoothing(DT, 0.08, 5).advance == 3  # at most H − 2
    for kwargs, field in (
        ({"dt": 0.0, "time_constant": 0.1, "horizon": H}, "dt"),
        ({"dt": DT, "time_constant": -0.1, "horizon": H}, "time_constant"),
        ({"dt": DT, "time_constant": 0.1, "horizon": 0}, "horizon"),
    ):
        with pytest.raises(ValueError, match=f"RowSmoothing.{field}"):
            RowSmoothing(**kwargs)


def test_reset_forgets_the_last_trial():
    smooth = RowSmoothing(DT, 0.08, H)
    smooth(np.ones((H, 2)))
    smooth.reset()
    np.testing.assert_array_equal(smooth(np.zeros((H, 2))), 0.0)
