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
