"""The real-time predictor: fresh, shifted, stale-to-fallback, non-finite, never blocking."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from coassist.control import Fault
from coassist.intent import train_model
from coassist.intent.realtime import RealtimeConfig, RealtimePredictor


@pytest.fixture(scope="module")
def model():
    from .conftest import TINY, labeled

    return train_model(labeled(4), TINY, TINY.train)


def samples(model, n):
    rng = np.random.default_rng(0)
    return rng.normal(scale=0.01, size=(n, 4 * model.n_dof))


def nominal(model, value=7.0):
    return np.full((model.horizon, model.n_dof), value)


def test_inline_predictions_equal_the_model_and_warm_up_falls_back(model):
    x = samples(model, model.history + 3)
    with RealtimePredictor(model, RealtimeConfig(threaded=False)) as rt:
        for k in range(model.history - 1):
            out = rt.tick(x[k], nominal(model))
            assert out.fault == Fault.PREDICTION_FALLBACK and np.all(out.positions == 7.0)
        for k in range(model.history - 1, len(x)):
            out = rt.tick(x[k], nominal(model))
            assert out.fault == Fault.NONE and out.age == 0
            assert np.array_equal(out.positions, model.predict(x[k - model.history + 1 : k + 1]))


def test_slow_network_is_shifted_then_falls_back(model):
    gate = threading.Event()
    calls = []

    def runner(window):
        calls.append(window)
        if len(calls) > 1:
            gate.wait(5.0)  # the second prediction is "late"
        return np.arange(model.horizon * model.n_dof, dtype=float).reshape(model.horizon, model.n_dof)

    x = samples(model, model.history + 20)
    with RealtimePredictor(model, RealtimeConfig(max_age=3), runner=runner) as rt:
        for k in range(model.history):
            rt.tick(x[k], nominal(model))
        rt.wait_idle()
        first = rt.tick(x[model.history], nominal(model))  # the worker now blocks on this window
        assert first.fault == Fault.PREDICTION_STALE and first.age == 1
        fresh = np.arange(model.horizon * model.n_dof, dtype=float).reshape(model.horizon, model.n_dof)
        assert np.array_equal(first.positions[:-1], fresh[1:]) and np.array_equal(first.positions[-1], fresh[-1])
        t0 = time.perf_counter()
        ages = [rt.tick(x[model.history + 1 + i], nominal(model)) for i in range(4)]
        assert time.perf_counter() - t0 < 0.5  # never waited for the blocked worker
        assert [a.age for a in ages[:2]] == [2, 3] and all(a.fault == Fault.PREDICTION_STALE for a in ages[:2])
        assert ages[2].fault == Fault.PREDICTION_FALLBACK and np.all(ages[2].positions == 7.0)
        gate.set()


def test_non_finite_or_failing_prediction_falls_back(model):
    def bad(window):
        return np.full((model.horizon, model.n_dof), np.nan)

    x = samples(model, model.history + 2)
    with RealtimePredictor(model, RealtimeConfig(threaded=False), runner=bad) as rt:
        outs = [rt.tick(s, nominal(model)) for s in x]
    assert all(o.fault == Fault.PREDICTION_FALLBACK for o in outs) and rt.errors == 3

    def boom(window):
        raise RuntimeError("network died")

    with RealtimePredictor(model, RealtimeConfig(threaded=False), runner=boom) as rt:
        assert all(rt.tick(s, nominal(model)).fault == Fault.PREDICTION_FALLBACK for s in x)


def test_threaded_worker_catches_up(model):
    x = samples(model, model.history + 5)
    with RealtimePredictor(model, RealtimeConfig(threaded=True)) as rt:
        for s in x:
            rt.tick(s, nominal(model))
            rt.wait_idle()
        out = rt.tick(x[-1], nominal(model))
        assert out.fault in (Fault.NONE, Fault.PREDICTION_STALE) and out.age <= 1


def test_config_errors_name_the_field(model):
    with pytest.raises(ValueError, match="realtime.backend"):
        RealtimeConfig(backend="tensorrt")
    with pytest.raises(ValueError, match="realtime.max_age"):
        RealtimePredictor(model, RealtimeConfig(max_age=model.horizon, threaded=False))


def test_a_model_drives_the_simulated_loop(tmp_path):
    """A model folder as the world's intent source: the logged prediction at tick k is
    the model's prediction on the logged feature rows k − history + 1 … k."""
    from coassist.intent import ModelIntent, Preset, TrainConfig, WindowConfig, load_intent_source, save_model
    from coassist.intent.model import ModelMismatchError
    from coassist.sim import TrialSpec, run_spec

    from .conftest import labeled

    preset = Preset("h50", WindowConfig(history=30, decimation=3, horizon=50, input_frame="relative", target="residual"),
                    lstm_layers=1, hidden=8, fc=(8,), train=TrainConfig(epochs=1, batch_size=64, threads=1, train_stride=4))
    save_model(train_model(labeled(3, n=200), preset, preset.train), tmp_path / "M")
    source = load_intent_source(str(tmp_path / "M"))
    assert isinstance(source, ModelIntent) and source.model_id.startswith("M@") and len(source.model_id) == 14
    trial = run_spec(TrialSpec(task="linear", seed=3, intent=str(tmp_path / "M")))
    assert trial.meta.model_id == source.model_id
    assert not np.any(trial.fault & int(Fault.PREDICTION_FALLBACK))
    feats = np.column_stack([trial.pose, trial.velocity, trial.wrench, trial.reference])
    for k in (30, 31, 200, trial.n_samples - 1):
        expected = source.model.predict(feats[k - 29 : k + 1])
        np.testing.assert_allclose(trial.prediction[k], expected, rtol=0, atol=1e-12)

    class Context:  # what the world hands reset(); only dt is read
        dt = 0.004

    with pytest.raises(ModelMismatchError, match="dt"):
        source.reset(Context())


def test_onnx_backend_matches_eager_torch(model):
    pytest.importorskip("onnxruntime", reason="the onnx extra is not installed")
    pytest.importorskip("onnx", reason="the onnx extra is not installed")
    from coassist.intent.realtime import make_runner

    onnx_run = make_runner(model, "onnx", 1)
    for seed in range(3):
        window = np.random.default_rng(seed).normal(scale=0.05, size=(model.history, 4 * model.n_dof))
        np.testing.assert_allclose(onnx_run(window), model.predict(window), rtol=0, atol=1e-6)


def test_a_prediction_from_before_reset_is_never_served(model):
    """The worker finishes a window of the old trial after reset(): its result is dropped,
    and the new trial's ticks fall back instead of serving (or crashing on) old data."""
    gate, started = threading.Event(), threading.Event()

    def runner(window):
        started.set()
        gate.wait(5.0)
        return np.zeros((model.horizon, model.n_dof))

    x = samples(model, 3 * model.history)
    with RealtimePredictor(model, RealtimeConfig(max_age=5), runner=runner) as rt:
        for s in x[: 2 * model.history]:
            rt.tick(s, nominal(model))
        assert started.wait(2.0)  # the worker is inside the network on an old-trial window
        rt.reset()
        gate.set()
        rt.wait_idle()
        outs = [rt.tick(s, nominal(model)) for s in x[: model.history - 1]]
        assert all(o.fault == Fault.PREDICTION_FALLBACK and np.all(o.positions == 7.0) for o in outs)


def test_fresh_prediction_is_a_copy(model):
    calls = []

    def once(window):  # one good prediction, then the network fails: the next tick shifts it
        calls.append(1)
        if len(calls) > 1:
            raise RuntimeError("network died")
        return np.ones((model.horizon, model.n_dof))

    x = samples(model, model.history + 1)
    with RealtimePredictor(model, RealtimeConfig(threaded=False), runner=once) as rt:
        for s in x[:-1]:
            out = rt.tick(s, nominal(model))
        assert out.fault == Fault.NONE
        out.positions[:] = 1e3  # the caller scribbles on what it got
        nxt = rt.tick(x[-1], nominal(model))
        assert nxt.fault == Fault.PREDICTION_STALE and np.all(nxt.positions == 1.0)
