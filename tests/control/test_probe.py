"""The calibration probe (coassist.control.probe): its signal against its formula, its draws, its guard."""

import math

import numpy as np
import pytest

from coassist.control.presets import PROBE, get_preset, make_controller
from coassist.control.probe import PROBE_BLOCK, ProbedGuidance, ProbeParameters, probe_phases, probe_signal
from coassist.interfaces import Fault, TrialContext
from coassist.scenario.seeds import robot_rng

DT = 0.008


def _context(seed):
    return TrialContext(
        dt=DT,
        horizon=50,
        start=np.zeros(2),
        target=np.ones(2),
        reference=np.zeros((10, 4)),
        task="linear",
        user="u",
        object="handle",
        seed=seed,
    )


def test_the_signal_is_the_multisine_of_the_docstring():
    params = ProbeParameters(rms=2.0, frequencies_x=(1.0, 3.0), frequencies_y=(2.0,), ramp_time=0.0)
    phases = (np.array([0.3, 1.1]), np.array([2.0]))
    t = np.arange(0.0, 10.0, DT)
    r = probe_signal(t, params, 2, phases)
    amp_x, amp_y = 2.0 * math.sqrt(2.0 / 2), 2.0 * math.sqrt(2.0 / 1)
    want_x = amp_x * (np.sin(2 * np.pi * 1.0 * t + 0.3) + np.sin(2 * np.pi * 3.0 * t + 1.1))
    np.testing.assert_allclose(r[:, 0], want_x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r[:, 1], amp_y * np.sin(2 * np.pi * 2.0 * t + 2.0), rtol=0, atol=1e-12)
    # over whole periods of every sine the RMS per axis is `rms` (the sines are orthogonal there)
    np.testing.assert_allclose(np.sqrt(np.mean(r**2, axis=0)), [2.0, 2.0], rtol=1e-9)
    # a third axis gets no push; the ramp scales linearly from 0
    assert np.all(probe_signal(t, params, 3, phases)[:, 2] == 0.0)
    ramped = probe_signal(
        t, ProbeParameters(rms=2.0, frequencies_x=(1.0, 3.0), frequencies_y=(2.0,), ramp_time=0.5), 2, phases
    )
    k = int(0.25 / DT)
    np.testing.assert_allclose(ramped[k], r[k] * (k * DT / 0.5), rtol=1e-12)
    np.testing.assert_array_equal(ramped[int(0.5 / DT) + 1 :], r[int(0.5 / DT) + 1 :])


def test_phases_come_from_the_trials_seed_on_the_robots_stream():
    px, py = probe_phases(PROBE, 1234)
    rng = robot_rng(1234)  # the seed scheme's robot stream (coassist.scenario.seeds)
    np.testing.assert_array_equal(px, rng.uniform(0.0, 2 * np.pi, len(PROBE.frequencies_x)))
    np.testing.assert_array_equal(py, rng.uniform(0.0, 2 * np.pi, len(PROBE.frequencies_y)))
    assert not np.array_equal(probe_phases(PROBE, 1235)[0], px)
    # outside a trial: Schroeder's phases, the same every time
    n = len(PROBE.frequencies_x)
    np.testing.assert_allclose(probe_phases(PROBE, None)[0], [-np.pi * j * (j - 1) / n for j in range(1, n + 1)])


def test_the_controller_is_manual_guidance_plus_the_trials_probe():
    ctrl = make_controller("manual-probe", get_preset("thesis-application-damped"))
    assert isinstance(ctrl, ProbedGuidance) and ctrl.params == PROBE
    z, ref, w = np.zeros(4), np.zeros((1, 4)), np.array([1.0, -2.0])
    ctrl.reset_for(_context(7))
    # past two of the blocks the controller computes the probe in (PROBE_BLOCK ticks each)
    n = 2 * PROBE_BLOCK + 50
    got = np.array([ctrl.step(z, ref, ref, w).u_r for _ in range(n)])
    t = np.arange(n) * DT
    np.testing.assert_array_equal(got, probe_signal(t, PROBE, 2, probe_phases(PROBE, 7)))
    # the same seed again: the same push; another trial mid-block: its own push from its tick 0
    ctrl.reset_for(_context(7))
    assert np.array_equal(ctrl.step(z, ref, ref, w).u_r, got[0])
    ctrl.reset_for(_context(8))
    assert np.array_equal(ctrl.step(z, ref, ref, w).u_r, probe_signal(np.zeros(1), PROBE, 2, probe_phases(PROBE, 8))[0])
    assert np.array_equal(
        ctrl.step(z, ref, ref, w).u_r, probe_signal(np.array([DT]), PROBE, 2, probe_phases(PROBE, 8))[0]
    )
    # a bad input: no push at all, flagged as MG flags it
    bad = ctrl.step(np.full(4, np.nan), ref, ref, w)
    assert np.all(bad.u_r == 0.0) and bad.fault & Fault.NONFINITE_STATE


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("rms", 6.0, "ProbeParameters.rms"),
        ("frequencies_x", (2.0, 1.0), "ProbeParameters.frequencies_x"),
        ("frequencies_y", (1.3,), "distinct frequencies"),
        ("frequencies_x", (), "ProbeParameters.frequencies_x"),
        ("ramp_time", -1.0, "ProbeParameters.ramp_time"),
    ],
)
def test_bad_parameters_name_the_field(field, value, match):
    with pytest.raises(ValueError, match=match):
        ProbeParameters(**{field: value})
