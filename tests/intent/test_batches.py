"""Training batches cut on the device (issue 19) equal the NumPy batches bit for bit.

The reference is the NumPy path that fed training before (``training._numpy_batch``:
``WindowSet.raw_inputs`` / ``raw_targets``, mirroring, ``Scaler.transform``, a cast).
Equality is exact (``torch.equal``), not approximate: the device path does the same
IEEE-754 operations in the same order in float64, each correctly rounded, so any
difference would be a bug (a different order of operations), not rounding noise. And a
training fed from NumPy batches ends with the very same weights as one fed from the
device (same batches, same order, same network): compared exactly too.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from coassist.data import Trial, TrialMeta
from coassist.intent import TrainConfig, WindowConfig, WindowSet, train_model
from coassist.intent import training as training_module
from coassist.intent.batches import DeviceWindows
from coassist.intent.features import Scaler
from coassist.intent.training import _epoch_order, _numpy_batch

from .conftest import TINY, labeled

DT = 0.008


def _sim_trial(seed: int, n: int = 300) -> Trial:
    """A trial with everything every label needs: the rendered plant, u_r and the true intent."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    pose = np.stack([0.1 * t + 0.02 * np.sin(2 * t + seed), 0.03 * np.cos(3 * t)], axis=1)
    vel = np.gradient(pose, DT, axis=0)
    u_r = rng.normal(0.0, 2.0, (n, 2))
    intent = pose + rng.normal(0.0, 1e-3, (n, 2))
    extra = {"plant": {"M": [12.0, 13.5], "D": [100.0, 90.0], "K": [0.0, 0.0]}}
    meta = TrialMeta("user-0", "curved", "board", "cooperative", None, seed, "sim", DT, extra=extra)
    return Trial(
        meta=meta,
        time=t,
        pose=pose,
        velocity=vel,
        wrench=50 * vel + rng.normal(0, 0.3, (n, 2)),
        reference=pose + 0.01,
        intent=intent,
        effort_h=-u_r,
        effort_r=u_r,
    )


class _Model:
    """What ``_numpy_batch`` reads of a model: its scalers."""

    def __init__(self, input_scaler: Scaler, target_scaler: Scaler) -> None:
        self.input_scaler, self.target_scaler = input_scaler, target_scaler

    def scale_inputs(self, x: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(self.input_scaler.transform(x).astype(np.float32))


WINDOWS = [
    WindowConfig(
        history=20, decimation=2, horizon=10, input_frame="relative", target="residual", target_scaling="step"
    ),
    WindowConfig(history=20, decimation=4, horizon=8, input_frame="relative", target="relative", label="hand_alone"),
    WindowConfig(
        history=15,
        decimation=1,
        horizon=12,
        input_frame="relative",
        target="residual",
        label="intent",
        target_scaling="step",
    ),
    WindowConfig(history=25, decimation=5, horizon=10, input_frame="absolute", target="absolute"),  # the thesis' frame
]


@pytest.mark.parametrize("window", WINDOWS, ids=lambda w: f"{w.label}-{w.input_frame}-{w.target}-{w.target_scaling}")
@pytest.mark.parametrize("mirror", [False, True])
def test_device_windows_equal_the_numpy_windows_exactly(window, mirror):
    trials = [_sim_trial(s) for s in range(3)]
    ws = WindowSet(trials, window, DT, stride=3)
    in_s, out_s = ws.fit_scalers()
    dev = DeviceWindows(ws, in_s, out_s)
    rng = np.random.default_rng(1)
    for size in (1, 7, len(ws)):  # one window, a batch, every window
        sel = rng.permutation(len(ws))[:size]
        signs = rng.choice([-1.0, 1.0], size=(size, 2)) if mirror else None
        x_ref, y_ref = _numpy_batch(_Model(in_s, out_s), ws, sel, signs)
        x, y = dev.batch(torch.from_numpy(sel), None if signs is None else torch.from_numpy(signs))
        assert x.dtype == y.dtype == torch.float32 and x.shape == x_ref.shape and y.shape == y_ref.shape
        assert torch.equal(x, x_ref) and torch.equal(y, y_ref)
    if mirror:  # the mirror does something (the test would pass vacuously otherwise)
        ones = torch.ones(len(ws), 2, dtype=torch.float64)
        assert not torch.equal(dev.batch(torch.arange(len(ws)), -ones)[1], dev.batch(torch.arange(len(ws)), ones)[1])


def test_the_epoch_order_draws_what_the_per_batch_draws_drew():
    """Order and mirror signs drawn once per epoch are the permutation and the per-batch sign
    draws of before, and leave the generator in the same state (what a checkpoint saves)."""
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    n, bs, d = 103, 16, 2
    perm, signs = _epoch_order(a, n, bs, d)
    ref_perm = b.permutation(n)
    ref_signs = [b.choice([-1.0, 1.0], size=(ref_perm[s : s + bs].size, d)) for s in range(0, n, bs)]
    assert np.array_equal(perm.numpy(), ref_perm)
    assert signs is not None and np.array_equal(signs.numpy(), np.concatenate(ref_signs))
    assert a.bit_generator.state == b.bit_generator.state
    assert _epoch_order(a, n, bs, 0)[1] is None


class _NumpyWindows:
    """``DeviceWindows``' interface served by the NumPy reference path."""

    def __init__(self, ws, input_scaler, target_scaler, device="cpu") -> None:
        self.ws, self.model, self.device = ws, _Model(input_scaler, target_scaler), torch.device(device)

    def __len__(self) -> int:
        return len(self.ws)

    def batch(self, sel, signs=None):
        return _numpy_batch(self.model, self.ws, sel.numpy(), None if signs is None else signs.numpy())


@pytest.mark.parametrize("kind", ["mirror+frozen skip", "transfer"])
def test_training_from_device_windows_equals_training_from_numpy_batches(monkeypatch, tmp_path, kind):
    """Same seed, same batches in the same order through the same network: the weights and
    losses are bit-identical, whichever path cut the batches."""
    from coassist.intent import save_model

    preset = replace(TINY, skip=True, train=replace(TINY.train, mirror=True, freeze_skip=True, skip_alpha=0.1))
    trials = labeled(5)
    cfg = preset.train
    if kind == "transfer":
        save_model(train_model(trials, preset, cfg), tmp_path / "base")
        trials, cfg = labeled(4, prefix="U"), replace(cfg, init=f"transfer:{tmp_path / 'base'}")
    new = train_model(trials, preset, cfg)
    monkeypatch.setattr(training_module, "DeviceWindows", _NumpyWindows)
    old = train_model(trials, preset, cfg)
    a, b = new.net.state_dict(), old.net.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    strip = [{k: v for k, v in r.items() if k != "seconds"} for r in new.info["training_history"]]
    assert strip == [{k: v for k, v in r.items() if k != "seconds"} for r in old.info["training_history"]]


def test_device_windows_follow_the_requested_device():
    ws = WindowSet([_sim_trial(0)], WINDOWS[0], DT)
    dev = DeviceWindows(ws, *ws.fit_scalers(), device="meta")  # no data: shapes and placement only
    x, y = dev.batch(torch.arange(4, device="meta"))
    assert x.device.type == y.device.type == "meta" and x.shape == (4, 10, 8) and y.shape == (4, 20)
    assert TrainConfig(device="cpu").device == "cpu"
