"""What a window's future is (issue 18): the tool, the hand alone, the true intent.

The hand-alone label is checked against an independent simulation of the same trial with
u_r = 0: scipy's own ZOH discretisation (``scipy.signal.cont2discrete``), not coassist's.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete

from coassist.data import Trial, TrialMeta
from coassist.intent import WindowConfig, WindowSet
from coassist.intent.features import free_response, robot_state
from coassist.model.impedance import ImpedanceModel

DT = 0.008
M, D = np.array([12.0, 13.5]), np.array([100.0, 90.0])  # plant inertia (robot + object) and damping


def _zoh():
    """Per-axis exact ZOH of M a + D v = u from scipy, state [x, v] per axis (block-diagonal)."""
    A = np.zeros((4, 4))
    B = np.zeros((4, 2))
    for a in range(2):
        A[a, 2 + a] = 1.0
        A[2 + a, 2 + a] = -D[a] / M[a]
        B[2 + a, a] = 1.0 / M[a]
    Ad, Bd, *_ = cont2discrete((A, B, np.eye(4), np.zeros((4, 2))), DT, method="zoh")
    return Ad, Bd


def _simulate(z0, u):
    Ad, Bd = _zoh()
    z = np.empty((len(u) + 1, 4))
    z[0] = z0
    for k in range(len(u)):
        z[k + 1] = Ad @ z[k] + Bd @ u[k]
    return z


def _trial(u_h, u_r, *, plant=True, intent=None):
    z = _simulate(np.array([0.1, -0.2, 0.0, 0.0]), u_h + u_r)[: len(u_h)]
    n = len(u_h)
    extra = {"plant": {"M": M.tolist(), "D": D.tolist(), "K": [0.0, 0.0]}} if plant else {}
    meta = TrialMeta("user-0", "curved", "board", "cooperative", None, 7, "sim", DT, extra=extra)
    return Trial(
        meta=meta,
        time=np.arange(n) * DT,
        pose=z[:, :2],
        velocity=z[:, 2:],
        wrench=u_h,
        reference=z[:, :2],
        intent=intent,
        effort_h=u_h,
        effort_r=u_r,
    )


def _smooth_forces(rng, n, scale):
    white = rng.normal(0.0, scale, (n, 2))
    kernel = np.ones(25) / 25.0
    return np.stack([np.convolve(white[:, a], kernel, mode="same") for a in range(2)], axis=1) * 5.0


def test_hand_alone_equals_a_simulation_without_the_robot_effort():
    rng = np.random.default_rng(0)
    n, H = 400, 50
    u_h, u_r = _smooth_forces(rng, n, 10.0), _smooth_forces(rng, n, 20.0)
    trial = _trial(u_h, u_r)
    window = WindowConfig(history=20, horizon=H, label="hand_alone")
    ws = WindowSet([trial], window, DT)
    futures = ws.future(np.arange(len(ws)))
    z_all = _simulate(np.array([0.1, -0.2, 0.0, 0.0]), u_h + u_r)
    worst = 0.0
    for row, k in enumerate(ws.ends):
        # The same trial from tick k on, the hand's force only: u_r = 0.
        alone = _simulate(z_all[k], u_h[k : k + H])[1:, :2]
        worst = max(worst, float(np.abs(futures[row] - alone).max()))
    # Both sides sum ≤ 50 terms of O(0.1 m) in float64: rounding is ~1e-15 m, far below 1e-9.
    assert worst < 1e-9
    # ... and the robot's effort did move the tool: the label is not the measured pose.
    tool = WindowSet([trial], WindowConfig(history=20, horizon=H), DT).future(np.arange(len(ws)))
    assert np.abs(tool - futures).max() > 1e-3


def test_hand_alone_is_the_tool_under_manual_guidance():
    rng = np.random.default_rng(1)
    u_h = _smooth_forces(rng, 200, 10.0)
    trial = _trial(u_h, np.zeros_like(u_h))
    sel = np.arange(100)
    alone = WindowSet([trial], WindowConfig(history=10, horizon=30, label="hand_alone"), DT).future(sel)
    tool = WindowSet([trial], WindowConfig(history=10, horizon=30), DT).future(sel)
    assert np.array_equal(alone, tool)


def test_robot_state_is_the_impulse_response_by_hand():
    # One axis, M = 2 kg, D = 4 N·s/m, dt = 0.1 s: a unit effort over the first tick from rest
    # moves the tool by (1/D)(dt − (M/D)(1 − a)), a = e^{−D dt/M}, at speed (1 − a)/D; then
    # the speed decays by a per tick and each tick adds v (M/D)(1 − a) of travel.
    model = ImpedanceModel(np.diag([2.0]), np.diag([4.0]), np.diag([0.0]), 0.1)
    z = robot_state(model, np.array([[1.0], [0.0], [0.0], [0.0]]))
    a = np.exp(-4.0 * 0.1 / 2.0)
    x1, v1 = (0.1 - 0.5 * (1.0 - a)) / 4.0, (1.0 - a) / 4.0
    travel = v1 * 0.5 * (1.0 - a)
    np.testing.assert_allclose(z[:, 0], [0.0, x1, x1 + travel, x1 + travel * (1.0 + a)], rtol=1e-12, atol=0)
    np.testing.assert_allclose(z[:, 1], [0.0, v1, v1 * a, v1 * a * a], rtol=1e-12, atol=0)
    # The free response carries a state forward with no input: [x, v] -> x + v (M/D)(1 − a^i).
    F = free_response(model, 3)
    for i in range(3):
        assert F[i, 0] @ [0.3, 2.0] == pytest.approx(0.3 + 2.0 * 0.5 * (1.0 - a ** (i + 1)), rel=1e-12)


def test_intent_label_is_the_true_intent_ahead():
    rng = np.random.default_rng(2)
    u_h = _smooth_forces(rng, 120, 10.0)
    intent = np.cumsum(rng.normal(0.0, 1e-3, (120, 2)), axis=0)
    trial = _trial(u_h, np.zeros_like(u_h), intent=intent)
    ws = WindowSet([trial], WindowConfig(history=10, horizon=5, label="intent"), DT)
    got = ws.future(np.array([0, 3]))
    k0, k3 = ws.ends[0], ws.ends[3]
    assert np.array_equal(got[0], intent[k0 + 1 : k0 + 6])
    assert np.array_equal(got[1], intent[k3 + 1 : k3 + 6])


def test_labels_say_what_they_need():
    rng = np.random.default_rng(3)
    u_h = _smooth_forces(rng, 100, 10.0)
    no_plant = _trial(u_h, np.zeros_like(u_h), plant=False)
    with pytest.raises(ValueError, match=r"hand_alone.*meta.extra\['plant'\]"):
        WindowSet([no_plant], WindowConfig(history=10, horizon=5, label="hand_alone"), DT)
    with pytest.raises(ValueError, match="label 'intent' needs the operator's true intent") as err:
        WindowSet([no_plant], WindowConfig(history=10, horizon=5, label="intent"), DT)
    # the trial as the other window errors name it (its person and recording or seed), and the option
    assert "but the trial " in str(err.value) and " samples) has no intent" in str(err.value)
    assert str(err.value).endswith("(coassist train --label)")
    with pytest.raises(ValueError, match="window.label must be one of"):
        WindowConfig(label="future")
    # Windows for prediction only (no future) need no label data.
    assert len(WindowSet([no_plant], WindowConfig(history=10, horizon=5, label="intent"), DT, need_future=False)) > 0


def test_point_mass_trials_record_the_plant_their_effort_drives():
    from coassist.sim import TrialSpec, run_spec

    trial = run_spec(TrialSpec(task="linear", object="heavy", controller="cooperative", seed=4))
    plant = trial.meta.extra["plant"]
    from coassist.scenario.objects import get_object

    assert list(plant["M"]) == [10.0 + get_object("heavy").mass] * 2  # the meta holds tuples, read-only
    assert list(plant["D"]) == [100.0, 100.0]


def _intent_trials(n_trials=4, n=260):
    from coassist.intent import LabeledTrial

    from .conftest import make_trial

    out = []
    for i in range(n_trials):
        t = make_trial(i, n=n)
        # An "intent" a few ticks ahead of the pose, as a simulated operator's would be.
        intent = np.concatenate([t.pose[5:], np.repeat(t.pose[-1:], 5, axis=0)])
        out.append(
            LabeledTrial(
                f"S/trial_{i:02d}",
                "S",
                Trial(
                    meta=t.meta,
                    time=t.time,
                    pose=t.pose,
                    velocity=t.velocity,
                    wrench=t.wrench,
                    reference=t.reference,
                    intent=intent,
                ),
            )
        )
    return out


def test_a_model_says_what_it_predicts_and_keeps_it_through_its_init_modes(tmp_path):
    import json
    from dataclasses import replace

    from coassist.intent import load_model, train_model
    from coassist.intent.training import write_model

    from .conftest import TINY, labeled

    preset = replace(TINY, window=replace(TINY.window, label="intent"))
    model = train_model(_intent_trials(), preset, preset.train)
    write_model(model, tmp_path / "m")
    side = json.loads((tmp_path / "m" / "model.json").read_text())
    assert side["window"]["label"] == "intent" and "true intended positions" in side["predicts"]
    assert load_model(tmp_path / "m").window.label == "intent"
    # resume keeps the label; transfer onto trials with no intent says what is missing
    resumed = train_model(_intent_trials(), preset, replace(preset.train, init=f"resume:{tmp_path / 'm'}", epochs=3))
    assert resumed.window.label == "intent"
    with pytest.raises(ValueError, match="label 'intent' needs the operator's true intent"):
        train_model(labeled(3), TINY, replace(TINY.train, init=f"transfer:{tmp_path / 'm'}"))
    # A model file from before labels existed (no window.label) reads as predicting the tool's future;
    # load_model builds its window the same way (WindowConfig(**meta["window"])).
    legacy = {k: v for k, v in side["window"].items() if k != "label"}
    assert WindowConfig(**legacy).label == "tool"
