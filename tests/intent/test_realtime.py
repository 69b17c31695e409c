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
    gate, entered = threading.Event(), threading.Event()
    calls = []

    def runner(window):
        calls.append(window)
        if len(calls) > 1:
            entered.set()
            gate.wait(5.0)  # the second prediction is "late"
        return 1e-3 * np.arange(model.horizon * model.n_dof, dtype=float).reshape(model.horizon, model.n_dof)

    x = samples(model, model.history + 20)
    with RealtimePredictor(model, RealtimeConfig(max_age=3), runner=runner) as rt:
        for k in range(model.history):
            rt.tick(x[k], nominal(model))
        rt.wait_idle()
        first = rt.tick(x[model.history], nominal(model))  # the worker now blocks on this window
        assert first.fault == Fault.PREDICTION_STALE and first.age == 1
        fresh = 1e-3 * np.arange(model.horizon * model.n_dof, dtype=float).reshape(model.horizon, model.n_dof)
        assert np.array_equal(first.positions[:-1], fresh[1:]) and np.array_equal(first.positions[-1], fresh[-1])
        assert entered.wait(2.0)  # the worker is inside the network now
        ages = [rt.tick(x[model.history + 1 + i], nominal(model)) for i in range(4)]
        # the ticks returned while the worker was still blocked inside the network: never waited
        assert not gate.is_set() and rt.health().busy
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


def test_a_runner_that_reuses_its_output_buffer_never_changes_the_prediction_kept(model):
    """The review of 3063e1e: a runner writing into one buffer of its own (as a preallocated network runner does)
    had its good prediction kept by reference; its next, failed run wrote NaN into it, and the predictor served NaN
    rows flagged only stale. The prediction kept is a copy."""
    buf = np.zeros((model.horizon, model.n_dof))
    calls = []

    def runner(window):
        calls.append(1)
        buf[:] = window[-1, : model.n_dof] if len(calls) == 1 else np.nan
        return buf

    x = samples(model, model.history + 1)
    with RealtimePredictor(model, RealtimeConfig(threaded=False), runner=runner) as rt:
        outs = [rt.tick(s, nominal(model)) for s in x]
    assert rt.errors == 1 and outs[-1].fault == Fault.PREDICTION_STALE
    assert np.isfinite(outs[-1].positions).all()
    np.testing.assert_array_equal(outs[-2].positions, outs[-1].positions)


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
    from coassist.intent import ModelIntent, Preset, TrainConfig, WindowConfig, load_model_intent, save_model
    from coassist.intent.model import ModelMismatchError
    from coassist.sim import TrialSpec, run_spec

    from .conftest import labeled

    preset = Preset(
        "h50",
        WindowConfig(history=30, decimation=3, horizon=50, input_frame="relative", target="residual"),
        lstm_layers=1,
        hidden=8,
        fc=(8,),
        train=TrainConfig(epochs=1, batch_size=64, threads=1, train_stride=4),
    )
    save_model(train_model(labeled(3, n=200), preset, preset.train), tmp_path / "M")
    source = load_model_intent(str(tmp_path / "M"))
    assert isinstance(source, ModelIntent) and source.model_id.startswith("M@") and len(source.model_id) == 14
    trial = run_spec(TrialSpec(task="linear", seed=3, intent=str(tmp_path / "M")))
    assert trial.meta.model_id == source.model_id
    assert trial.meta.extra["network"] == source.network  # which backend evaluated the network
    assert not np.any(trial.fault & int(Fault.PREDICTION_FALLBACK))
    feats = np.column_stack([trial.pose, trial.velocity, trial.wrench, trial.reference])
    for k in (30, 31, 200, trial.n_samples - 1):
        expected = source.predict(feats[k - 29 : k + 1])  # the source's own backend, batch 1 as in the loop
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
        return np.full((model.horizon, model.n_dof), 0.1)

    x = samples(model, model.history + 1)
    with RealtimePredictor(model, RealtimeConfig(threaded=False), runner=once) as rt:
        for s in x[:-1]:
            out = rt.tick(s, nominal(model))
        assert out.fault == Fault.NONE
        out.positions[:] = 1e3  # the caller scribbles on what it got
        nxt = rt.tick(x[-1], nominal(model))
        assert nxt.fault == Fault.PREDICTION_STALE and np.all(nxt.positions == 0.1)


# ---------------------------------------------------------------------- bad predictions, bad samples


def test_absurd_or_jumping_predictions_are_rejected_and_counted(model):
    """A finite 1e6 m prediction, or one with a 1 m jump between two rows (125 m/s), is
    never served: the nominal goes out flagged, and health() counts it as implausible."""
    H, d = model.horizon, model.n_dof
    good = np.full((H, d), 0.02)
    jump = good.copy()
    jump[H // 2 :] += 0.45  # 0.45 m in one tick: within 0.5 m of the pose, far beyond 3 m/s
    outputs = iter([np.full((H, d), 1e6), jump, good])
    x = samples(model, model.history + 2)
    with RealtimePredictor(model, RealtimeConfig(threaded=False), runner=lambda w: next(outputs)) as rt:
        outs = [rt.tick(s, nominal(model, 0.0)) for s in x]
        health = rt.health()
    assert [o.fault for o in outs[-3:]] == [Fault.PREDICTION_FALLBACK, Fault.PREDICTION_FALLBACK, Fault.NONE]
    assert np.all(outs[-3].positions == 0.0) and np.all(outs[-2].positions == 0.0)
    assert np.array_equal(outs[-1].positions, good)
    assert (health.implausible, health.errors, health.predictions) == (2, 0, 1)


def test_plausibility_bounds_against_hand_computed_cases():
    from coassist.interfaces import PlausibilityLimits, prediction_plausible

    lim = PlausibilityLimits(max_distance=0.5, max_speed=3.0)
    pose = np.array([0.1, -0.2])
    line = pose + np.outer(np.arange(1, 51), [0.02, 0.0])  # 0.02 m per 8 ms = 2.5 m/s; ends 1.0 m away
    assert not prediction_plausible(line, pose, 0.008, lim)  # too far
    assert prediction_plausible(line[:25], pose, 0.008, lim)  # 0.5 m away exactly, 2.5 m/s
    fast = pose + np.outer(np.arange(1, 11), [0.025, 0.0])  # 3.125 m/s
    assert not prediction_plausible(fast, pose, 0.008, lim)
    assert prediction_plausible(fast, pose, 0.01, lim)  # 2.5 m/s at 100 Hz
    assert not prediction_plausible(np.full((3, 2), np.nan), pose, 0.008, lim)
    with pytest.raises(ValueError, match="PlausibilityLimits.max_speed"):
        PlausibilityLimits(max_speed=0.0)


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros(7),
        np.zeros((8, 1)),
        "0.1",
        np.ones(8, dtype=bool),
        [np.nan] * 8,
        np.array([10**400] * 8, dtype=object),
        None,
    ],
)
def test_a_bad_sample_is_held_flagged_and_never_raises(model, bad):
    """One bad sample costs nothing: it is replaced by the previous row, the tick is
    flagged INVALID_INPUT and the next prediction uses exactly that held window."""
    if model.n_dof != 2:
        pytest.skip("the parametrized shapes assume 2 DOFs")
    x = samples(model, model.history + 2)
    with RealtimePredictor(model, RealtimeConfig(threaded=False)) as rt:
        for s in x[: model.history]:
            rt.tick(s, nominal(model))
        out = rt.tick(bad, nominal(model))
        assert out.fault == Fault.INVALID_INPUT and out.age == 0 and out.positions.shape == (model.horizon, 2)
        held = np.vstack([x[1 : model.history], x[model.history - 1]])
        np.testing.assert_array_equal(out.positions, model.predict(held))
        assert rt.health().held_samples == 1


def test_a_long_sensor_gap_empties_the_history_then_predictions_resume(model):
    cfg = RealtimeConfig(threaded=False, max_hold=3)
    x = samples(model, 2 * model.history + 10)
    with RealtimePredictor(model, cfg) as rt:
        for s in x[: model.history]:
            rt.tick(s, nominal(model))
        gap = [rt.tick(np.full(4 * model.n_dof, np.nan), nominal(model)) for _ in range(5)]
        after = [rt.tick(s, nominal(model)) for s in x[model.history : 2 * model.history]]
        m = rt.max_age
    # samples 1-3 of the gap are held (fresh predictions); the 4th empties the history, so the
    # last prediction (made at gap[2]) ages: stale up to max_age, then the nominal until a
    # whole window of real samples has come in again.
    inv, stale = Fault.INVALID_INPUT, Fault.PREDICTION_STALE
    assert [g.fault for g in gap] == [inv, inv, inv, inv | stale, inv | stale]
    assert all(a.fault == stale and a.age == 3 + i for i, a in enumerate(after[: m - 2]))
    assert all(a.fault == Fault.PREDICTION_FALLBACK for a in after[m - 2 : model.history - 1])
    assert after[model.history - 1].fault == Fault.NONE and after[model.history - 1].age == 0


def test_the_fallback_always_has_the_prediction_shape(model):
    H, d = model.horizon, model.n_dof
    x = samples(model, 2)
    with RealtimePredictor(model, RealtimeConfig(threaded=False)) as rt:
        long = rt.tick(x[0], np.arange((H + 5) * d, dtype=float).reshape(H + 5, d) * 1e-3)
        short = rt.tick(x[1], np.array([[0.1] * d, [0.2] * d]))
        junk = rt.tick(x[1], "not a reference")
    assert long.positions.shape == short.positions.shape == junk.positions.shape == (H, d)
    assert np.allclose(long.positions[-1], np.arange((H - 1) * d, H * d) * 1e-3)
    assert np.all(short.positions[1:] == 0.2) and np.all(np.isnan(junk.positions))
    assert junk.fault & Fault.INVALID_INPUT and long.fault == Fault.PREDICTION_FALLBACK


@pytest.mark.parametrize("answer", [[[0.0, 0.0], [0.0], [0.0, 0.0]], [["a", "b"]] * 3, np.zeros((3, 3))])
def test_an_answer_that_is_no_positions_array_is_a_fallback_not_an_exception(answer):
    """RealtimeIntent turns a predictor's answer into an array: one that is ragged, of strings or of another shape
    falls back to the plan's rows, flagged (it once raised out of the loop's intent stage)."""
    from coassist.runtime.intent import RealtimeIntent

    class Predictor:  # a duck-typed predictor, as a lab's own may be
        horizon, history, errors = 3, 0, 0

        def reset(self, context):
            pass

        def tick(self, sample, nominal):
            return answer, 0, 0

    pred, flags = RealtimeIntent(Predictor()).update(0, (0.0,) * 8, np.zeros((3, 2)))
    assert pred is None and flags & Fault.PREDICTION_FALLBACK


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_a_dead_worker_thread_is_reported_and_stalls_the_loop_intent(model):
    from coassist.runtime.intent import RealtimeIntent

    def dies(window):
        raise SystemExit  # escapes the worker's `except Exception`: the thread ends

    x = samples(model, model.history + 3)
    rt = RealtimePredictor(model, RealtimeConfig(threaded=True), runner=dies)
    try:
        stage = RealtimeIntent(rt)
        for k, s in enumerate(x[: model.history]):
            stage.update(k, tuple(s), nominal(model))
        rt._worker.join(timeout=2.0)
        assert not rt.worker_alive and not rt.health().alive
        _, flags = stage.update(model.history, tuple(x[-1]), nominal(model))
        assert flags & Fault.PREDICTOR_STALLED
    finally:
        rt.close()


def test_health_shows_a_hung_network_while_it_hangs(model):
    gate = threading.Event()

    def hangs(window):
        gate.wait(5.0)
        return np.zeros((model.horizon, model.n_dof))

    x = samples(model, model.history)
    with RealtimePredictor(model, RealtimeConfig(threaded=True), runner=hangs) as rt:
        for s in x:
            rt.tick(s, nominal(model))
        time.sleep(0.15)
        h = rt.health()
        assert h.alive and h.busy and h.busy_s >= 0.1 and h.predictions == 0
        gate.set()
        rt.wait_idle()
        assert rt.health().predictions == 1 and not rt.health().busy


def test_process_backend_equals_the_model_and_reports_its_death(model):
    """The model in a worker process answers exactly what it answers in-process (same
    float64 bytes back); a killed process is reported dead and its calls fail."""
    from pathlib import Path

    from coassist.intent.realtime import ProcessRunner

    runner = ProcessRunner(model, threads=1)
    try:
        # the worker loaded its copy: nothing of it is left in /tmp should this process be killed
        assert not Path(runner._tmp.name).exists()
        for seed in range(3):
            window = np.random.default_rng(seed).normal(scale=0.05, size=(model.history, 4 * model.n_dof))
            np.testing.assert_allclose(runner(window), model.predict(window), rtol=0, atol=1e-9)
        assert runner.alive()
        runner._proc.kill()
        runner._proc.join(timeout=5.0)
        time.sleep(runner.liveness_interval)  # alive() asks the OS at most this often
        assert not runner.alive()
        with pytest.raises((EOFError, OSError, BrokenPipeError)):
            runner(np.zeros((model.history, 4 * model.n_dof)))
    finally:
        runner.close()


def test_the_torch_backends_worker_thread_takes_the_thread_count_it_was_built_with(model, monkeypatch):
    """A new thread's OpenMP team does not follow torch.set_num_threads of the thread that made it: in a worker thread
    that did not apply it a thesis-size network's call took a median of 29–43 ms (8–12 ms on the main thread) and
    single calls 3 s, and 75 % of a 125 Hz run's ticks fell back. The worker thread applies the count itself."""
    import torch

    from coassist.intent import realtime

    calls = []
    real = torch.set_num_threads
    monkeypatch.setattr(realtime.torch, "set_num_threads", lambda n: calls.append((threading.current_thread().name, n)))
    want = torch.get_num_threads()
    rt = RealtimePredictor(model, RealtimeConfig(threaded=True, backend="torch"))
    try:
        deadline = time.monotonic() + 5.0
        while not calls and time.monotonic() < deadline:
            time.sleep(0.01)
        assert calls == [("intent-predictor", want)]
    finally:
        rt.close()
        monkeypatch.setattr(realtime.torch, "set_num_threads", real)


def test_a_loaded_model_carries_the_digest_of_the_weights_it_was_loaded_from(model, tmp_path):
    """The id a run records is the digest load_model verified (a folder read again after loading, swapped meanwhile,
    named weights that never ran)."""
    import hashlib

    from coassist.intent.model import WEIGHTS, load_model, save_model

    folder = save_model(model, tmp_path / "m")
    loaded = load_model(folder)
    assert loaded.weights_sha256 == hashlib.sha256((folder / WEIGHTS).read_bytes()).hexdigest()
    assert model.weights_sha256 is None  # built in memory
