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


def test_probes_stepped_together_are_each_probe_stepped_alone():
    """probed_steps (run_loops) and probed_efforts (the array path) against twins stepped one by one, 40 ticks of five
    trials of their own seeds: every row's effort, model and flags bit for bit, a row MG refuses (NaN, out of bounds)
    flagged as alone and its clock on as alone, probed_efforts' clean rows exactly the unflagged steps."""
    from coassist.control.probe import probe_key, probed_efforts, probed_steps

    preset = get_preset("thesis-application-damped")
    seeds = (3, 4, 5, 6, 7)

    def built():
        out = [make_controller("manual-probe", preset) for _ in seeds]
        for c, s in zip(out, seeds):
            c.reset_for(_context(s))
        return out

    alone, together, efforts = built(), built(), built()
    assert len({probe_key(c) for c in together}) == 1 and probe_key(object()) is None
    rng = np.random.default_rng(0)
    B = len(seeds)
    for k in range(40):
        z = rng.normal(0.0, 0.05, (B, 4))
        ref = rng.normal(0.0, 0.05, (B, 1, 4))
        w = rng.normal(0.0, 5.0, (B, 2))
        if k in (3, 17):
            z[1, 0] = np.nan  # a non-finite state: refused, no push
        if k == 9:
            w[4, 1] = 1e6  # beyond the guard's wrench bound: refused
        want = [c.step(z[b], ref[b], ref[b], w[b]) for b, c in enumerate(alone)]
        got = probed_steps(together, z, ref, ref, w)
        for a, b in zip(want, got, strict=True):
            assert np.array_equal(a.u_r, b.u_r) and np.array_equal(a.u_h_model, b.u_h_model) and a.fault == b.fault
        u, clean = probed_efforts(efforts, z, ref, ref, w)
        assert clean.tolist() == [s.fault == Fault.NONE for s in want]
        for b in range(B):
            if clean[b]:
                assert np.array_equal(u[b], want[b].u_r)
            else:  # not stepped: the caller steps that row itself (effort_batch's contract), which reports it
                s = efforts[b].step(z[b], ref[b], ref[b], w[b])
                assert np.array_equal(s.u_r, want[b].u_r) and s.fault == want[b].fault != Fault.NONE
        if k in (3, 9):
            assert not clean.all()
    assert [c._k for c in together] == [c._k for c in efforts] == [c._k for c in alone] == [40] * B


def test_calibration_runs_are_grouped_by_their_probe_and_a_shared_controller_is_left_alone():
    from types import SimpleNamespace

    from coassist.control.controllers import InputBounds, ManualGuidance
    from coassist.control.probe import ProbedGuidance
    from coassist.runtime.batched_loops import probed_groups

    preset = get_preset("thesis-application-damped")
    a, b, shared = (make_controller("manual-probe", preset) for _ in range(3))
    other = ProbedGuidance(a.model)
    other.guidance = ManualGuidance(a.model, bounds=InputBounds(wrench=50.0))  # another guard: not a's group
    lone = ProbedGuidance(a.model)
    mg = make_controller("manual", preset)
    longer = make_controller("manual-probe", preset)
    ticks = [SimpleNamespace(controller=c, H=50) for c in (a, mg, b, shared, shared, other, lone)]
    ticks.append(SimpleNamespace(controller=longer, H=60))
    # a, b and lone step together; MG, the controller two runs share (its clock is theirs in turn), the one of
    # another guard and the one of another horizon (its arguments do not stack with theirs) each step alone
    assert probed_groups(ticks) == [0, None, 0, None, None, None, 0, None]
