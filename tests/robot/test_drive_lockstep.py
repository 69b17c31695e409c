"""MuJoCo drives in lockstep (coassist.robot.drive.drive_lockstep) against drive() one by one.

The reference is :func:`drive` itself on the same configs: named intents must give the same
Trial bit for bit (nothing is batched); a float32 model in the loop agrees to its batched
kernels' rounding (tests/runtime/test_batched_loops.py explains the bound), and is loaded once
and called once per tick for every run.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")

from coassist.robot.drive import DriveConfig, drive, drive_lockstep  # noqa: E402
from coassist.scenario import intent_registry  # noqa: E402

from ..intent.conftest import TINY, labeled  # noqa: E402

#: Runs of different lengths (so they leave the batch at different ticks), users and controllers.
CASES = (
    ("linear", 1, 0, "cooperative", 1.2),
    ("curved", 2, 1, "cooperative-arbitrated", 1.6),
    ("sinusoidal", 3, 2, "cooperative", 1.0),
)


def _configs(intent: str) -> list[DriveConfig]:
    return [
        DriveConfig(world="mujoco", controller=c, task=t, seed=s, user=u, intent=intent, time_limit=tl)
        for t, s, u, c, tl in CASES
    ]


def test_named_intents_drive_in_lockstep_exactly_as_alone():
    configs = _configs("oracle")[:2] + [replace(_configs("nominal")[2], controller="manual")]
    together = drive_lockstep(configs)
    for config, b in zip(configs, together):
        a = drive(config)
        assert a.n_samples > 100 and a.equals(b), config


def test_drives_of_one_controller_kind_step_it_in_one_call_a_tick_exactly_as_alone(monkeypatch):
    """MG's drives share one controller (it keeps no state: one step_batch a tick); the online-α drives
    keep their own, stepped by one arbitrated_step_batch a tick (without the stability guard, as the
    ablation's cells drive); every trial is its drive() bit for bit."""
    from coassist.control.controllers import _GuardedController
    from coassist.runtime import batched_loops

    configs = [
        DriveConfig(
            world="mujoco", controller=c, task=t, seed=s, user=u, intent="oracle", time_limit=tl, stability=None
        )
        for c in ("manual", "cooperative-arbitrated")
        for t, s, u, tl in (("linear", 4, 0, 0.8), ("curved", 5, 1, 1.0))
    ]
    alone = [drive(c) for c in configs]
    calls: dict[str, list[int]] = {"step_batch": [], "arbitrated": []}
    step_batch, arbitrated = _GuardedController.step_batch, batched_loops.arbitrated_step_batch

    def counting_step_batch(self, z, *args):
        calls["step_batch"].append(z.shape[0])
        return step_batch(self, z, *args)

    def counting_arbitrated(controllers, *args):
        calls["arbitrated"].append(len(controllers))
        return arbitrated(controllers, *args)

    monkeypatch.setattr(_GuardedController, "step_batch", counting_step_batch)
    monkeypatch.setattr(batched_loops, "arbitrated_step_batch", counting_arbitrated)
    together = drive_lockstep(configs)
    for config, a, b in zip(configs, alone, together):
        assert a.n_samples > 90 and a.equals(b), config
    both = min(alone[0].n_samples, alone[1].n_samples)  # ticks both runs of a kind are going
    assert calls["step_batch"][:both] == [2] * both and calls["arbitrated"][:both] == [2] * both
    assert len(calls["step_batch"]) == len(calls["arbitrated"]) == both  # then each run left alone steps its own


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory) -> str:
    from coassist.intent.training import train_model, write_model

    out = tmp_path_factory.mktemp("model") / "tiny"
    # the loop needs the controller's horizon (the default preset's game, 50 ticks at 125 Hz)
    preset = replace(TINY, window=replace(TINY.window, horizon=50))
    write_model(train_model(labeled(3), preset, replace(TINY.train, epochs=1)), out)
    return str(out)


def test_a_model_drives_in_lockstep_to_its_rounding_with_one_call_per_tick(tiny_model, monkeypatch):
    configs = _configs(tiny_model)
    alone = [drive(c) for c in configs]
    loads, calls = [], []
    real_load = intent_registry.load_intent_source

    def counting_load(intent, horizon, network):
        src = real_load(intent, horizon=horizon, network=network)
        loads.append(intent)
        batch = src.batcher.predict_batch
        src.batcher.predict_batch = lambda windows: (calls.append(len(windows)), batch(windows))[1]
        return src

    monkeypatch.setattr(intent_registry, "load_intent_source", counting_load)
    together = drive_lockstep(configs)
    assert loads == [tiny_model]  # one model for the three runs
    lengths = sorted(t.n_samples for t in together)
    assert len(calls) == lengths[-1] and calls[0] == 3  # one call per tick, every run still going in it
    for a, b in zip(alone, together):
        assert a.n_samples == b.n_samples and a.meta.extra["ended"] == b.meta.extra["ended"]
        np.testing.assert_array_equal(a.fault, b.fault)
        # float32 rounding of batched kernels (tests/runtime/test_batched_loops.py), through the arm's loop
        np.testing.assert_allclose(b.prediction, a.prediction, rtol=0, atol=1e-6)
        np.testing.assert_allclose(b.pose, a.pose, rtol=0, atol=1e-7)


def test_lockstep_takes_simulated_drives_only():
    with pytest.raises(ValueError, match=r"configs\[1\] must be a DriveConfig of a simulated world \(mujoco\)"):
        drive_lockstep([DriveConfig(), DriveConfig(world="ur")])


@pytest.mark.parametrize("realtime", [False, True])
def test_a_model_of_another_rate_is_refused_naming_intent_and_rate(tiny_model, realtime):
    """A 125 Hz model driven at --rate 500 was refused with "intent source horizon (50) must be >= the controller's
    (200)", naming neither option nor the rates (the real-time path said the rates, not the options)."""
    config = DriveConfig(
        world="mujoco", controller="cooperative", intent=tiny_model, rate_hz=500, time_limit=0.5,
        realtime_intent=realtime,
    )  # fmt: skip
    with pytest.raises(ValueError) as err:
        drive(config)
    assert str(err.value) == (
        f"--intent {tiny_model}: the model was trained at 125 Hz (dt 0.008 s), this run is at --rate 500 (dt 0.002 s): "
        "drive at --rate 125, or train a model on trials of this rate"
    )
