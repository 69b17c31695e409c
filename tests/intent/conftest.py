"""Small synthetic trials for the intent tests (no simulator needed)."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.data import Trial, TrialMeta
from coassist.intent import LabeledTrial, Preset, TrainConfig, WindowConfig


def make_trial(seed: int, n: int = 260, d: int = 2, dt: float = 0.008, user: str = "user-t") -> Trial:
    """A smooth 'hand-guided' motion: a nominal line plus a random smooth deviation."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    ref = np.stack([0.1 * t + 0.01 * a for a in range(d)], axis=1)
    dev = np.stack(
        [rng.uniform(0.01, 0.05) * np.sin(rng.uniform(1, 4) * t + rng.uniform(0, 6)) for _ in range(d)], axis=1
    )
    pose = ref + dev
    vel = np.gradient(pose, dt, axis=0)
    wrench = 100.0 * vel + rng.normal(0, 0.1, size=pose.shape)
    meta = TrialMeta(
        user=user, task="linear", object="handle", controller="impedance", model_id=None, seed=seed, origin="sim", dt=dt
    )
    return Trial(meta=meta, time=t, pose=pose, velocity=vel, wrench=wrench, reference=ref)


def labeled(
    n_trials: int = 5, d: int = 2, dt: float = 0.008, n: int = 260, prefix: str = "T", first_seed: int = 0
) -> list[LabeledTrial]:
    """``n_trials`` of :func:`make_trial` (seeds ``first_seed`` on) named ``<prefix>/trial_<i>``: the same seeds under
    another prefix are copies of the same trials (a training knows them by their contents too)."""
    return [
        LabeledTrial(f"{prefix}/trial_{i:02d}", prefix, make_trial(first_seed + i, n=n, d=d, dt=dt))
        for i in range(n_trials)
    ]


TINY = Preset(
    "tiny",
    WindowConfig(history=20, decimation=2, horizon=10, input_frame="relative", target="residual"),
    lstm_layers=1,
    hidden=8,
    fc=(8,),
    train=TrainConfig(epochs=2, batch_size=32, lr=3e-3, threads=1, train_stride=2, eval_stride=4),
)


@pytest.fixture
def trials() -> list[LabeledTrial]:
    return labeled()


@pytest.fixture
def tiny() -> Preset:
    return TINY


def write_loop_model(folder, horizon: int) -> str:
    """The tiny network trained for one epoch on three labeled trials and written to ``folder``,
    predicting ``horizon`` ticks (a simulated loop needs at least its controller's horizon)."""
    from dataclasses import replace as _replace

    from coassist.intent.training import train_model, write_model

    preset = _replace(TINY, window=_replace(TINY.window, horizon=horizon))
    write_model(train_model(labeled(3), preset, _replace(TINY.train, epochs=1)), folder)
    return str(folder)
