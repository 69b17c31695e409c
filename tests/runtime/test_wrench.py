"""The wrench pipeline, stage by stage, on synthetic signals with a known answer."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from coassist.interfaces import Fault
from coassist.runtime.wrench import WrenchConfig, WrenchPipeline, WrenchReading, payload_wrench

G = 9.81
# A config with every smoothing stage off, so an output can be compared exactly.
PLAIN = dict(cutoff_hz=None, deadband_force=0.0, deadband_torque=0.0)


def run(pipe, raws, rotations=None, seqs=None, dt=0.008, t0=0.0):
    """Feed one raw sample per tick (a new seq every tick unless given); stack the readings."""
    raws = np.asarray(raws, dtype=float)
    n = len(raws)
    if rotations is None:
        rotations = np.broadcast_to(np.eye(3), (n, 3, 3))
    if seqs is None:
        seqs = range(1, n + 1)
    out = [pipe.update(raws[k], rotations[k], int(seqs[k]), t0 + k * dt) for k in range(n)]
    hand = np.array([r.hand for r in out])
    fault = np.array([int(r.fault) for r in out])
    fresh = np.array([r.fresh for r in out])
    return hand, fault, fresh


def rot_x(deg):
    return Rotation.from_euler("x", deg, degrees=True).as_matrix()


# ---------------------------------------------------------------- payload_wrench


def test_payload_wrench_hand_computed_cases():
    # Sensor level, z up (R = I): a 2 kg tool's weight presses along −z_sensor.
    np.testing.assert_allclose(
        payload_wrench(2.0, (0, 0, 0.1), (0, 0, -G), np.eye(3)), [0, 0, -2 * G, 0, 0, 0], atol=1e-12
    )
    # Tool hanging straight down (sensor turned 180° about x: z_sensor = −z_base): the
    # weight pulls along +z_sensor; a CoM offset along x_sensor twists it about −y_sensor:
    # τ = c × F = (0.05, 0, 0.1) × (0, 0, 2g) = (0, −0.05·2g, 0).
    np.testing.assert_allclose(
        payload_wrench(2.0, (0.05, 0, 0.1), (0, 0, -G), rot_x(180)), [0, 0, 2 * G, 0, -0.1 * G, 0], atol=1e-12
    )
    # Turned 90° about x: z_sensor = −y_base, y_sensor = +z_base. Gravity in the sensor
    # frame is (0, −g, 0); the CoM 0.1 m along z_sensor gives τ = (0.1 g, 0, 0).
    np.testing.assert_allclose(
        payload_wrench(1.0, (0, 0, 0.1), (0, 0, -G), rot_x(90)), [0, -G, 0, 0.1 * G, 0, 0], atol=1e-12
    )
    # Same torque worked out in the base frame and turned back: r × F with r = R c.
    R = rot_x(90)
    tau_base = np.cross(R @ [0, 0, 0.1], [0, 0, -G])
    np.testing.assert_allclose(R.T @ tau_base, [0.1 * G, 0, 0], atol=1e-12)


def test_payload_wrench_accepts_a_stack_of_rotations():
    Rs = Rotation.random(5, random_state=3).as_matrix()
    stacked = payload_wrench(1.5, (0.01, 0.02, 0.03), (0, 0, -G), Rs)
    assert stacked.shape == (5, 6)
    for k in range(5):
        np.testing.assert_allclose(stacked[k], payload_wrench(1.5, (0.01, 0.02, 0.03), (0, 0, -G), Rs[k]), atol=1e-12)


# ---------------------------------------------------------------- bias, payload, frames


def test_bias_is_removed():
    bias = np.array([3.0, -2.0, 15.0, 0.2, -0.1, 0.05])
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    np.testing.assert_allclose(pipe.zero(np.tile(bias, (25, 1)), np.eye(3)), bias, atol=1e-12)
    np.testing.assert_allclose(pipe.bias, bias, atol=1e-12)
    hand = np.array([10.0, 5.0, -7.0, 0.3, 0.0, -0.4])
    out, fault, fresh = run(pipe, np.tile(bias + hand, (10, 1)))
    np.testing.assert_allclose(out, np.tile(hand, (10, 1)), atol=1e-12)
    assert not fault.any() and fresh.all()


def test_zero_with_a_payload_recovers_the_bias_from_any_orientations():
    cfg = WrenchConfig(tool_mass=1.2, tool_com=(0.01, -0.02, 0.08), **PLAIN)
    Rs = Rotation.random(30, random_state=7).as_matrix()
    bias = np.array([4.0, -6.0, 2.5, 0.3, 0.1, -0.2])
    raw = bias + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, Rs)
    pipe = WrenchPipeline(cfg, dt=0.008)
    np.testing.assert_allclose(pipe.zero(raw, Rs), bias, atol=1e-10)


def test_gravity_compensation_reads_zero_at_random_orientations():
    cfg = WrenchConfig(tool_mass=1.2, tool_com=(0.01, -0.02, 0.08), **PLAIN)
    bias = np.array([4.0, -6.0, 2.5, 0.3, 0.1, -0.2])
    pipe = WrenchPipeline(cfg, dt=0.008)
    pipe.zero(bias[None, :] + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, np.eye(3)), np.eye(3))
    # A slow tumble through random orientations (consecutive samples ≤ 2mg ≈ 24 N apart:
    # no spike), nobody touching the tool.
    Rs = Rotation.random(200, random_state=11).as_matrix()
    raw = bias + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, Rs)
    out, fault, _ = run(pipe, raw, Rs)
    assert not fault.any()
    np.testing.assert_allclose(out, 0.0, atol=1e-10)
    # Sensitivity check: without compensation the same readings would be ~mg off.
    uncompensated = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    uncompensated.zero(bias[None, :] + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, np.eye(3)), np.eye(3))
    out_u, _, _ = run(uncompensated, raw, Rs)
    assert np.abs(out_u[:, :3]).max() > 10.0


def test_known_hand_wrench_on_a_rotating_tool_is_recovered_in_the_base_frame():
    cfg = WrenchConfig(tool_mass=0.8, tool_com=(0.0, 0.03, 0.12), **PLAIN)
    bias = np.array([-1.0, 2.0, 8.0, 0.05, -0.3, 0.02])
    pipe = WrenchPipeline(cfg, dt=0.002)
    pipe.zero(np.tile(bias, (5, 1)) + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, np.eye(3)), np.eye(3))
    hand_base = np.array([5.0, -3.0, 8.0, 0.4, -0.2, 0.1])
    Rs = Rotation.random(100, random_state=5).as_matrix()
    # What the sensor reads: the hand wrench turned into the sensor frame + weight + bias.
    hand_sensor = np.concatenate(
        [np.einsum("nji,j->ni", Rs, hand_base[:3]), np.einsum("nji,j->ni", Rs, hand_base[3:])], axis=1
    )
    raw = bias + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, Rs) + hand_sensor
    out, fault, _ = run(pipe, raw, Rs, dt=0.002)
    assert not fault.any()
    np.testing.assert_allclose(out, np.tile(hand_base, (100, 1)), atol=1e-10)


def test_rotation_into_the_base_frame():
    # Sensor turned +90° about z_base: x_sensor = +y_base, y_sensor = −x_base.
    R = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    reading = pipe.update(np.array([10.0, 0.0, 2.0, 1.0, 0.5, 0.0]), R, 1, 0.0)
    np.testing.assert_allclose(reading.hand, [0.0, 10.0, 2.0, -0.5, 1.0, 0.0], atol=1e-12)
    assert isinstance(reading, WrenchReading) and reading.fault == Fault.NONE and reading.fresh


# ---------------------------------------------------------------- low-pass, deadband


@pytest.mark.parametrize("dt", [0.002, 0.008])
def test_lowpass_step_response_matches_the_analytic_first_order_response(dt):
    fc = 15.0
    pipe = WrenchPipeline(WrenchConfig(cutoff_hz=fc, deadband_force=0.0, deadband_torque=0.0), dt=dt)
    n = 60
    raw = np.zeros((n, 6))
    raw[:, 0] = 20.0
    raw[:, 5] = -2.0
    out, fault, _ = run(pipe, raw, dt=dt)
    k = np.arange(n)
    expected = 1.0 - np.exp(-2.0 * np.pi * fc * (k + 1) * dt)  # the step, held over k+1 periods
    np.testing.assert_allclose(out[:, 0], 20.0 * expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[:, 5], -2.0 * expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[:, 1:5], 0.0, atol=1e-12)
    assert not fault.any()


def test_lowpass_runs_on_the_control_period_with_a_100hz_sensor_at_125hz():
    dt, fc, n = 0.008, 15.0, 40
    pipe = WrenchPipeline(WrenchConfig(cutoff_hz=fc, deadband_force=0.0, deadband_torque=0.0), dt=dt)
    seqs = [(k * 8) // 10 for k in range(n)]  # repeats one sample in five
    out, fault, fresh = run(pipe, np.tile([20.0, 0, 0, 0, 0, 0], (n, 1)), seqs=seqs, dt=dt)
    k = np.arange(n)
    np.testing.assert_allclose(out[:, 0], 20.0 * (1.0 - np.exp(-2.0 * np.pi * fc * (k + 1) * dt)), atol=1e-9)
    assert not fault.any()
    assert (~fresh).sum() == sum(seqs[i] == seqs[i - 1] for i in range(1, n))


def test_deadband_shrinks_the_norms_and_keeps_the_direction():
    pipe = WrenchPipeline(WrenchConfig(cutoff_hz=None, deadband_force=0.5, deadband_torque=0.05), dt=0.008)
    out = pipe.update(np.array([3.0, 4.0, 0.0, 0.0, 0.06, 0.08]), np.eye(3), 1, 0.0).hand
    np.testing.assert_allclose(out[:3], np.array([3.0, 4.0, 0.0]) * 4.5 / 5.0, atol=1e-12)  # ‖f‖ 5 → 4.5
    np.testing.assert_allclose(out[3:], np.array([0.0, 0.06, 0.08]) * 0.05 / 0.1, atol=1e-12)  # ‖τ‖ 0.1 → 0.05
    # Per-axis components below the deadband survive when the norm is above it.
    out = pipe.update(np.array([0.4, 0.4, 0.4, 0.0, 0.0, 0.0]), np.eye(3), 2, 0.008).hand
    n = math.sqrt(3) * 0.4
    np.testing.assert_allclose(out[:3], 0.4 * (n - 0.5) / n, atol=1e-12)
    # Inside, and exactly at, the deadband: zero. Just outside: continuous.
    for seq, f in enumerate([0.3, 0.5, 0.5 + 1e-6], start=3):
        out = pipe.update(np.array([0.0, f, 0.0, 0.0, 0.0, 0.04]), np.eye(3), seq, 0.008 * seq).hand
        np.testing.assert_allclose(out, [0.0, max(f - 0.5, 0.0), 0.0, 0.0, 0.0, 0.0], atol=1e-12)


def test_no_filter_and_no_deadband_pass_the_compensated_reading_through():
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    raw = np.random.default_rng(0).normal(0, 5, size=(50, 6)) * [1, 1, 1, 0.1, 0.1, 0.1]  # no jumps
    out, _, _ = run(pipe, raw)
    np.testing.assert_allclose(out, raw, atol=1e-12)


# ---------------------------------------------------------------- saturation, spikes


@pytest.mark.parametrize("channel, limit", [(0, 300.0), (2, -300.0), (4, 30.0), (5, -30.0)])
def test_saturation_is_flagged_and_the_last_good_wrench_held(channel, limit):
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    ramp = np.linspace(0.0, 0.97 * limit, 8)
    raw = np.zeros((12, 6))
    raw[:8, channel] = ramp
    raw[8:11, channel] = limit
    raw[11, channel] = 0.9 * limit
    out, fault, fresh = run(pipe, raw)
    assert not fault[:8].any()
    assert (fault[8:11] == Fault.SENSOR_SATURATED).all() and not fresh[8:11].any()
    np.testing.assert_allclose(out[8:11], np.tile(out[7], (3, 1)), atol=0)  # held
    assert fault[11] == 0 and fresh[11]
    assert out[11, channel] == pytest.approx(0.9 * limit)


def test_a_5kn_one_tick_spike_is_rejected_and_the_output_is_unchanged():
    cfg = WrenchConfig()  # default filter and deadband
    n, k_spike = 30, 15
    raw = np.tile([20.0, -5.0, 3.0, 0.5, 0.0, 0.1], (n, 1))
    spiky = raw.copy()
    spiky[k_spike, 0] = 5000.0
    out, fault, fresh = run(WrenchPipeline(cfg, 0.008), spiky)
    twin, _, _ = run(WrenchPipeline(cfg, 0.008), raw)
    assert fault[k_spike] == Fault.WRENCH_SPIKE and not fresh[k_spike]
    assert not np.delete(fault, k_spike).any()
    np.testing.assert_allclose(out, twin, atol=1e-12)  # as if the spike never came
    # Impossible values are never accepted, however long they last.
    stuck = raw.copy()
    stuck[k_spike:, 2] = -5000.0
    out, fault, _ = run(WrenchPipeline(WrenchConfig(**PLAIN), 0.008), stuck)
    assert (fault[k_spike:] == Fault.WRENCH_SPIKE).all()
    np.testing.assert_allclose(out[k_spike:], np.tile(raw[0], (n - k_spike, 1)), atol=1e-12)


@pytest.mark.parametrize("spike_hold", [1, 3, 5])
def test_a_persisting_real_step_is_accepted_after_spike_hold_samples(spike_hold):
    pipe = WrenchPipeline(WrenchConfig(spike_hold=spike_hold, **PLAIN), dt=0.008)
    raw = np.zeros((15, 6))
    raw[5:, 1] = 200.0  # a 200 N step: beyond spike_jump_force = 150 N
    raw[5:, 1] += np.random.default_rng(1).normal(0, 2, size=10)  # with noise
    out, fault, fresh = run(pipe, raw)
    first_ok = 5 + spike_hold - 1
    assert (fault[5:first_ok] == Fault.WRENCH_SPIKE).all()
    np.testing.assert_allclose(out[:first_ok], 0.0, atol=0)
    assert not fault[first_ok:].any() and fresh[first_ok:].all()
    np.testing.assert_allclose(out[first_ok:, 1], raw[first_ok:, 1], atol=1e-12)


def test_a_short_jump_that_returns_and_inconsistent_bursts_are_rejected():
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    raw = np.zeros((12, 6))
    raw[3, 0] = 200.0  # one sample, then back: a glitch
    raw[4:6, 3] = [20.0, 21.0]  # two torque samples (spike_hold − 1), then back
    raw[7:12, 2] = [200.0, -200.0, 200.0, -200.0, 200.0]  # a noise burst that never settles
    out, fault, _ = run(pipe, raw)
    assert list(np.flatnonzero(fault)) == [3, 4, 5, 7, 8, 9, 10, 11]
    assert (fault[fault != 0] == Fault.WRENCH_SPIKE).all()
    np.testing.assert_allclose(out, 0.0, atol=0)


# ---------------------------------------------------------------- stale sensor


@pytest.mark.parametrize("dt", [0.008, 0.002])
def test_a_100hz_sensor_is_never_stale_but_a_frozen_one_is(dt):
    cfg = WrenchConfig(**PLAIN)
    pipe = WrenchPipeline(cfg, dt=dt)
    n = round(2.0 / dt)
    ticks = np.arange(n)
    seqs = (ticks * round(dt * 1000)) // 10  # a 100 Hz counter read at the tick rate (integer ms)
    raw = np.tile([5.0, 0, 0, 0, 0, 0], (n, 1))
    out, fault, fresh = run(pipe, raw, seqs=seqs, dt=dt)
    assert not fault.any()
    assert 0 < (~fresh).sum() < n and np.all(out[:, 0] == 5.0)

    # Freeze the counter at tick n_freeze (the tick that first sees the frozen sample).
    n_freeze = next(k for k in range(n // 2, n) if seqs[k] != seqs[k - 1])
    frozen = seqs.copy()
    frozen[n_freeze:] = seqs[n_freeze]
    pipe = WrenchPipeline(cfg, dt=dt)
    out, fault, _ = run(pipe, raw, seqs=frozen, dt=dt)
    age = (ticks - n_freeze) * dt
    stale = (ticks >= n_freeze) & (age > cfg.max_sample_age + 1e-9)
    assert not fault[~stale].any()
    assert (fault[stale] == Fault.SENSOR_STALE).all()
    np.testing.assert_allclose(out[stale], 0.0, atol=0)
    first = np.flatnonzero(stale)[0]
    assert (first - n_freeze) * dt == pytest.approx(0.032)  # the first tick more than 30 ms on


@pytest.mark.parametrize("clock", ["stopped", "ran back 2 s", "runs backwards"])
def test_a_clock_that_does_not_go_forward_is_invalid_input_and_cannot_hide_a_stuck_sensor(clock):
    """The sample ages run on the tick clock t: a clock that stopped or ran back left a stuck sensor unflagged, and
    the arm followed its last push to the workspace's edge (440 mm; a review, 2026-12-07). Every such tick is
    INVALID_INPUT (zero wrench, the tick decelerates) and the ages run on from the latest t seen."""
    dt = 0.008
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=dt)
    for k in range(40):  # a live sensor on a live clock
        assert pipe.update([5.0, 0, 0, 0, 0, 0], np.eye(3), k, k * dt).fault == Fault.NONE
    t_stop = 39 * dt
    for k in range(40, 80):  # the counter stuck at 39 from here, and the clock:
        t = {"stopped": t_stop, "ran back 2 s": t_stop - 2.0 + (k - 40) * 1e-9, "runs backwards": t_stop - k * dt}[
            clock
        ]
        r = pipe.update([5.0, 0, 0, 0, 0, 0], np.eye(3), 39, t)
        assert r.fault & Fault.INVALID_INPUT and not r.hand.any(), k
    # the clock goes forward again (from where it stood): the stuck counter is stale from the latest t seen
    r = pipe.update([5.0, 0, 0, 0, 0, 0], np.eye(3), 39, t_stop + 0.04)
    assert r.fault == Fault.SENSOR_STALE
    pipe.reset()  # a new trial's clock starts again
    assert pipe.update([5.0, 0, 0, 0, 0, 0], np.eye(3), 0, 0.0).fault == Fault.NONE


def test_output_ramps_back_through_the_filter_when_a_stale_sensor_recovers():
    dt, fc = 0.008, 15.0
    pipe = WrenchPipeline(WrenchConfig(cutoff_hz=fc, deadband_force=0.0, deadband_torque=0.0), dt=dt)
    raw = np.tile([10.0, 0, 0, 0, 0, 0], (40, 1))
    seqs = list(range(10)) + [9] * 10 + list(range(10, 30))
    out, fault, _ = run(pipe, raw, seqs=seqs, dt=dt)
    assert fault[19] == Fault.SENSOR_STALE and out[19, 0] == 0.0
    assert not fault[20:].any()
    k = np.arange(20)
    np.testing.assert_allclose(out[20:, 0], 10.0 * (1.0 - np.exp(-2 * np.pi * fc * (k + 1) * dt)), atol=1e-9)


# ---------------------------------------------------------------- bad input never raises


@pytest.mark.parametrize(
    "raw, flag",
    [
        (np.array([1.0, np.nan, 0, 0, 0, 0]), Fault.NONFINITE_WRENCH),
        (np.array([np.inf, 0, 0, 0, 0, 0]), Fault.NONFINITE_WRENCH),
        (np.array([0, 0, 0, 0, 0, -np.inf]), Fault.NONFINITE_WRENCH),
        ([1.0, 2.0, float("nan"), 0.0, 0.0, 0.0], Fault.NONFINITE_WRENCH),
        (np.zeros(5), Fault.INVALID_INPUT),
        (np.zeros((6, 1)), Fault.INVALID_INPUT),
        (np.zeros((2, 3)), Fault.INVALID_INPUT),
        (np.zeros(0), Fault.INVALID_INPUT),
        ("abcdef", Fault.INVALID_INPUT),
        (b"abcdef", Fault.INVALID_INPUT),
        (["1", "2", "3", "4", "5", "6"], Fault.INVALID_INPUT),
        (None, Fault.INVALID_INPUT),
        (np.zeros(6, dtype=complex), Fault.INVALID_INPUT),
        (np.zeros(6, dtype=bool), Fault.INVALID_INPUT),
        (np.array([object()] * 6), Fault.INVALID_INPUT),
        ([1.0, [2.0, 3.0], 4.0, 5.0, 6.0, 7.0], Fault.INVALID_INPUT),
        ({"fx": 1.0}, Fault.INVALID_INPUT),
        (3.0, Fault.INVALID_INPUT),
    ],
)
def test_bad_readings_give_zero_and_a_flag_without_raising(raw, flag):
    pipe = WrenchPipeline(WrenchConfig(cutoff_hz=5.0), dt=0.008)
    run(pipe, np.tile([20.0, 0, 0, 0, 0, 0], (5, 1)))
    reading = pipe.update(raw, np.eye(3), 6, 0.04)
    assert reading.fault == flag and not reading.fresh
    assert reading.hand.shape == (6,) and np.all(reading.hand == 0.0)
    # The hand "let go": a good reading afterwards starts the filter from zero again.
    again = pipe.update(np.array([20.0, 0, 0, 0, 0, 0]), np.eye(3), 7, 0.048)
    assert again.fault == Fault.NONE
    assert again.hand[0] == pytest.approx(
        20.0 * (1.0 - math.exp(-2 * math.pi * 5.0 * 0.008)) - pipe.config.deadband_force
    )


@pytest.mark.parametrize(
    "rotation, seq, t",
    [
        (np.full((3, 3), np.nan), 1, 0.0),
        (np.eye(4), 1, 0.0),
        ("eye", 1, 0.0),
        (None, 1, 0.0),
        (np.eye(3) * 1j, 1, 0.0),
        (np.eye(3), None, 0.0),
        (np.eye(3), 1.5, 0.0),
        (np.eye(3), "1", 0.0),
        (np.eye(3), 1, float("nan")),
        (np.eye(3), 1, float("inf")),
        (np.eye(3), 1, None),
        (np.eye(3), 1, "0.0"),
    ],
)
def test_bad_rotation_seq_or_time_give_zero_and_invalid_input(rotation, seq, t):
    pipe = WrenchPipeline(WrenchConfig(), dt=0.008)
    reading = pipe.update(np.array([20.0, 0, 0, 0, 0, 0]), rotation, seq, t)
    assert reading.fault == Fault.INVALID_INPUT and np.all(reading.hand == 0.0) and not reading.fresh


def test_other_real_inputs_are_accepted():
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    r = pipe.update([1, 2, 3, 0, 0, 0], np.eye(3, dtype=int), np.int64(4), np.float32(0.5))
    assert r.fault == Fault.NONE
    np.testing.assert_allclose(r.hand, [1, 2, 3, 0, 0, 0])
    r = pipe.update(np.arange(6, dtype=np.float32), np.eye(3).T, 5, 1)  # non-contiguous R, int t
    assert r.fault == Fault.NONE
    np.testing.assert_allclose(r.hand, np.arange(6))


def test_an_internal_error_gives_zero_and_internal_error(monkeypatch):
    pipe = WrenchPipeline(WrenchConfig(), dt=0.008)
    run(pipe, np.tile([20.0, 0, 0, 0, 0, 0], (5, 1)))

    def boom(*args):
        raise RuntimeError("boom")

    monkeypatch.setattr(pipe, "_update", boom)
    r = pipe.update(np.zeros(6), np.eye(3), 6, 0.04)
    assert r.fault == Fault.INTERNAL_ERROR and np.all(r.hand == 0.0) and not r.fresh


def test_update_never_raises_on_random_garbage():
    rng = np.random.default_rng(0)
    choices = [
        lambda: rng.normal(0, 1e3, 6),
        lambda: rng.normal(0, 1e3, rng.integers(0, 9)),
        lambda: np.where(rng.random(6) < 0.3, np.nan, rng.normal(0, 100, 6)),
        lambda: [None, "x", 1.0, [], {}, object(), np.inf][rng.integers(0, 7)],
        lambda: rng.normal(0, 1, (3, 3)),
        lambda: np.eye(3),
    ]
    pipe = WrenchPipeline(WrenchConfig(tool_mass=1.0, tool_com=(0, 0, 0.1)), dt=0.008)
    for k in range(500):
        raw = choices[rng.integers(0, 4)]()
        R = choices[rng.integers(3, 6)]()
        seq = [k, k - 1, None, "s", np.int32(k)][rng.integers(0, 5)]
        r = pipe.update(raw, R, seq, k * 0.008 if rng.random() > 0.05 else float("nan"))
        assert r.hand.shape == (6,) and np.all(np.isfinite(r.hand))
        assert isinstance(r.fault, Fault)


# ---------------------------------------------------------------- zeroing, reset


def test_request_zero_measures_the_bias_from_the_next_accepted_samples():
    cfg = WrenchConfig(tool_mass=1.0, tool_com=(0.0, 0.0, 0.1), zero_samples=20, **PLAIN)
    pipe = WrenchPipeline(cfg, dt=0.008)
    bias = np.array([2.0, -1.0, 4.0, 0.1, 0.2, -0.3])
    Rs = Rotation.random(20, random_state=2).as_matrix()
    raw = bias + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, Rs)
    raw = np.insert(raw, 10, raw[9] + [0, 0, 500.0, 0, 0, 0], axis=0)  # a spike mid-zeroing: not counted
    Rs = np.insert(Rs, 10, Rs[9], axis=0)
    pipe.request_zero()
    assert pipe.zeroing
    out, fault, fresh = run(pipe, raw, Rs)
    np.testing.assert_allclose(out, 0.0, atol=0)
    assert not fresh.any()
    assert list(np.flatnonzero(fault)) == [10] and fault[10] == Fault.WRENCH_SPIKE
    assert not pipe.zeroing
    np.testing.assert_allclose(pipe.bias, bias, atol=1e-10)
    hand = np.array([0.0, 12.0, 0.0, 0.0, 0.0, 0.5])
    r = pipe.update(
        bias + payload_wrench(cfg.tool_mass, cfg.tool_com, cfg.gravity, np.eye(3)) + hand, np.eye(3), 100, 1.0
    )
    np.testing.assert_allclose(r.hand, hand, atol=1e-10)


def test_request_zero_sample_count_and_its_validation():
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    pipe.request_zero(3)
    run(pipe, np.tile([1.0, 2, 3, 4, 5, 6], (3, 1)))
    assert not pipe.zeroing
    np.testing.assert_allclose(pipe.bias, [1, 2, 3, 4, 5, 6])
    for bad in (0, -1, 2.5, True, "3"):
        with pytest.raises(ValueError, match="n must be"):
            pipe.request_zero(bad)


def test_zero_rejects_bad_samples():
    pipe = WrenchPipeline(WrenchConfig(), dt=0.008)
    with pytest.raises(ValueError, match="raw_samples"):
        pipe.zero(np.zeros((4, 5)), np.eye(3))
    with pytest.raises(ValueError, match="rotations"):
        pipe.zero(np.zeros((4, 6)), np.tile(np.eye(3), (3, 1, 1)))
    with pytest.raises(ValueError, match="finite"):
        pipe.zero(np.full((4, 6), np.nan), np.eye(3))
    with pytest.raises(ValueError, match="rotation matrices"):
        pipe.zero(np.zeros((4, 6)), 2 * np.eye(3))


def test_reset_keeps_the_bias_and_clears_the_rest():
    pipe = WrenchPipeline(WrenchConfig(), dt=0.008)
    pipe.zero(np.tile([1.0, 0, 0, 0, 0, 0], (3, 1)), np.eye(3))
    run(pipe, np.tile([30.0, 0, 0, 0, 0, 0], (20, 1)))
    pipe.request_zero()
    pipe.reset()
    assert not pipe.zeroing
    np.testing.assert_allclose(pipe.bias, [1, 0, 0, 0, 0, 0])
    # Seq 1 again is new after a reset; the filter starts from zero.
    r = pipe.update(np.array([1.0, 0, 0, 0, 0, 0]), np.eye(3), 1, 0.0)
    assert r.fault == Fault.NONE and r.fresh and np.all(r.hand == 0.0)


def test_each_reading_is_a_new_array():
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    a = pipe.update(np.ones(6), np.eye(3), 1, 0.0).hand
    b = pipe.update(np.ones(6), np.eye(3), 1, 0.008).hand
    assert a is not b
    a[:] = 99.0
    np.testing.assert_allclose(b, 1.0)


# ---------------------------------------------------------------- config


def test_config_defaults():
    c = WrenchConfig()
    assert (c.tool_mass, c.tool_com, c.gravity) == (0.0, (0.0, 0.0, 0.0), (0.0, 0.0, -9.81))
    assert (c.cutoff_hz, c.deadband_force, c.deadband_torque) == (15.0, 0.2, 0.05)
    assert (c.force_range, c.torque_range, c.max_sample_age) == (300.0, 30.0, 0.03)
    assert (c.spike_jump_force, c.spike_jump_torque, c.spike_hold, c.zero_samples) == (150.0, 15.0, 3, 25)
    c = WrenchConfig(tool_com=np.array([0, 0, 1]), gravity=[0, 0, -9.8])
    assert c.tool_com == (0.0, 0.0, 1.0) and isinstance(c.gravity, tuple)
    hash(c)


@pytest.mark.parametrize(
    "field, value",
    [
        ("tool_mass", -1.0),
        ("tool_mass", float("nan")),
        ("tool_mass", "1"),
        ("tool_com", (0.0, 0.1)),
        ("tool_com", "abc"),
        ("tool_com", (0.0, float("inf"), 0.0)),
        ("gravity", (0.0, 0.0, float("nan"))),
        ("gravity", None),
        ("cutoff_hz", 0.0),
        ("cutoff_hz", -5.0),
        ("cutoff_hz", float("inf")),
        ("deadband_force", -0.1),
        ("deadband_torque", -0.01),
        ("force_range", 0.0),
        ("torque_range", -30.0),
        ("max_sample_age", 0.0),
        ("spike_jump_force", 0.0),
        ("spike_jump_torque", float("nan")),
        ("spike_hold", 0),
        ("spike_hold", 2.0),
        ("spike_hold", True),
        ("zero_samples", 0),
    ],
)
def test_config_validation_names_the_field(field, value):
    with pytest.raises(ValueError, match=rf"WrenchConfig\.{field}\b"):
        WrenchConfig(**{field: value})


def test_pipeline_validation():
    with pytest.raises(ValueError, match=r"WrenchConfig\.max_sample_age"):
        WrenchPipeline(WrenchConfig(max_sample_age=0.001), dt=0.008)
    with pytest.raises(ValueError, match="dt"):
        WrenchPipeline(WrenchConfig(), dt=0.0)
    with pytest.raises(ValueError, match="config"):
        WrenchPipeline({"cutoff_hz": 15.0}, dt=0.008)


def test_the_batch_gives_each_pipelines_hand_force_on_every_clean_tick():
    """WrenchPipelineBatch.update row for row against each WrenchPipeline.update: planar readings
    through a tilted sensor with a bias; each tick a row gets a new sample, the same one again,
    or (now and then) a spike, a saturated or impossible value, a NaN, an exact repeat with the
    frozen check on, or a gap longer than max_sample_age. Where the batch says clean the
    pipeline flags nothing and gives the same force bit for bit; where the pipeline flags
    anything the batch is not clean (a row that is not clean leaves, as on the array path)."""
    from coassist.runtime.wrench import WrenchPipelineBatch

    rng = np.random.default_rng(11)
    dt = 0.008
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    configs = [
        WrenchConfig(**PLAIN, force_range=300.0),
        WrenchConfig(**PLAIN, force_range=12.0, spike_jump_force=20.0),
        WrenchConfig(**PLAIN, max_frozen_time=0.05),
    ]
    n_runs = 60
    pipes, twins = [], []
    for i in range(n_runs):
        for group in (pipes, twins):
            pipe = WrenchPipeline(configs[i % 3], dt)
            pipe.zero(np.array([[0.3 * i % 2.0, -0.5, 0.2, 0.0, 0.0, 0.0]]), R)  # a bias, sensor frame
            group.append(pipe)
    assert all(WrenchPipelineBatch.accepts(p) for p in twins)
    assert not WrenchPipelineBatch.accepts(WrenchPipeline(WrenchConfig(), dt))  # a filter: not for the batch
    batch = WrenchPipelineBatch(twins, R)
    seq = np.zeros(n_runs, dtype=np.int64)
    last = rng.normal(0.0, 5.0, (n_runs, 2))
    silent = np.zeros(n_runs, dtype=int)  # ticks a sensor still sends nothing new
    rows = np.arange(n_runs)
    kinds = {"held": 0, "clean": 0, "left": 0, "left_unflagged": 0}
    flags = Fault.NONE
    for k in range(150):
        t = k * dt
        raw = last[rows].copy()
        for j, i in enumerate(rows.tolist()):
            u = rng.random()
            if silent[i] > 0:  # a sensor gone quiet: the same sample, on and on
                silent[i] -= 1
            elif u < 0.6:  # a new sample near the last
                seq[i] += 1
                raw[j] += rng.normal(0.0, 1.0, 2)
            elif u < 0.985:  # the same sample again (a 100 Hz sensor read at 125 Hz)
                kinds["held"] += 1
            elif u < 0.99:  # no new sample for longer than max_sample_age
                silent[i] = 8
            else:  # a new sample that jumps, is saturated, impossible, NaN, or bit-identical to the last
                seq[i] += 1
                raw[j] = (
                    last[i] + [200.0, 0.0],
                    [configs[i % 3].force_range, 0.0],
                    [1e4, 1.0],
                    [np.nan, 0.0],
                    last[i],
                )[rng.integers(5)]  # a jump, saturated, impossible, NaN, a repeat
        hand, clean = batch.update(rows, raw, seq[rows], t)
        keep = []
        for j, i in enumerate(rows.tolist()):
            reading = pipes[i].update(np.array([raw[j, 0], raw[j, 1], 0.0, 0.0, 0.0, 0.0]), R, int(seq[i]), t)
            if clean[j]:
                assert reading.fault == Fault.NONE, (k, i, reading.fault)
                assert hand[j].tolist() == reading.hand[:3].tolist(), (k, i)
                kinds["clean"] += 1
                keep.append(j)
                last[i] = raw[j]
            else:
                kinds["left"] += 1
                kinds["left_unflagged"] += reading.fault == Fault.NONE  # a repeat the frozen check may yet allow
            if reading.fault:
                assert not clean[j], (k, i, reading.fault)
                flags |= reading.fault
        rows = rows[keep]
        if not rows.size:
            break
    assert kinds["clean"] > 1000 and kinds["held"] > 300 and kinds["left"] > 20 and kinds["left_unflagged"] > 0, kinds
    assert flags == Fault.SENSOR_STALE | Fault.WRENCH_SPIKE | Fault.SENSOR_SATURATED | Fault.NONFINITE_WRENCH


@pytest.mark.parametrize(
    "rotation",
    [np.zeros((3, 3)), 0.3 * np.eye(3), np.diag([1.0, 1.0, -1.0]), np.array([[1.0, 1.0, 0], [0, 1.0, 0], [0, 0, 1.0]])],
    ids=["zeros", "scaled", "mirrored", "sheared"],
)
def test_a_sensor_rotation_that_is_not_a_rotation_is_invalid_input(rotation):
    """The review of 3063e1e: a sensor rotation of zeros passed (every entry a cosine) and a 250 N push read 0 N, no
    contact stop, no flag; 0.3·I read it as 75 N. Not a rotation (RᵀR ≠ I or det < 0): INVALID_INPUT, zero hand."""
    pipe = WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008)
    reading = pipe.update(np.array([250.0, 0, 0, 0, 0, 0]), rotation, 1, 0.0)
    assert reading.fault == Fault.INVALID_INPUT and np.all(reading.hand == 0.0)
    turned = Rotation.from_rotvec([0.3, -1.1, 2.0]).as_matrix()  # a rotation, composed: passes, force turned
    ok = pipe.update(np.array([250.0, 0, 0, 0, 0, 0]), turned @ rot_x(33.0), 2, 0.008)
    assert ok.fault == Fault.NONE
    # the pipeline's float products against numpy's: a few ulps of 250 N, whatever the BLAS
    np.testing.assert_allclose(ok.hand[:3], turned @ rot_x(33.0) @ [250.0, 0, 0], rtol=0, atol=250.0 * 1e-13)


def test_the_batched_pipeline_refuses_a_rotation_its_pipelines_would_flag():
    """The review of the fix: WrenchPipelineBatch took a mirrored, scaled or zero "rotation" and called its rows clean,
    where each WrenchPipeline now flags them INVALID_INPUT (its docstring: a clean row is the pipeline's floats)."""
    from coassist.runtime.wrench import WrenchPipelineBatch

    pipes = [WrenchPipeline(WrenchConfig(**PLAIN), dt=0.008) for _ in range(2)]
    for bad in (np.diag([1.0, 1.0, -1.0]), 0.5 * np.eye(3), np.zeros((3, 3))):
        with pytest.raises(ValueError, match="rotation must be a rotation matrix"):
            WrenchPipelineBatch(pipes, bad)
    WrenchPipelineBatch(pipes, rot_x(30.0))  # a rotation: taken
