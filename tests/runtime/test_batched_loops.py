"""Lockstep runs (coassist.runtime.batched_loops) against the per-trial loop, on the simulator's trials.

The reference is the per-trial path itself (``run_loop`` on the same episode): nominal,
oracle and any row-invariant batched source must give the same Trial bit for bit; a
model in float64 to 1e-12; a float32 model to its batched kernels' rounding (see
test_a_float32_model_agrees_to_its_rounding for the bound and why).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from coassist.control.presets import get_preset
from coassist.runtime.batched_loops import Loop, run_loops
from coassist.runtime.loop import run_loop
from coassist.scenario.constant_velocity import ConstantVelocityIntent
from coassist.sim.trial_runner import TrialSpec, run_spec, run_spec_lockstep, spec_episode

from ..intent.conftest import write_loop_model

PRESET = "thesis-evaluation-dm"
#: Trials of different lengths (so runs drop out of the batch at different ticks) and users.
CASES = (("linear", 3, 0), ("curved", 4, 1), ("sinusoidal", 5, 2))
HORIZON = get_preset(PRESET).game.horizon  # the key spec_episode caches sources under
FIELDS = ("pose", "velocity", "wrench", "prediction", "effort_h", "effort_r")


def _specs(intent: str, network: str = "auto") -> list[TrialSpec]:
    return [TrialSpec(task=t, seed=s, user=u, intent=intent, preset=PRESET, network=network) for t, s, u in CASES]


def _alone(specs, sources=None):
    out = []
    for spec in specs:
        ep = spec_episode(spec, None, sources)
        out.append(ep.finish(run_loop(*ep.loop)))
    return out


def _together(specs, sources=None):
    """In lockstep; the trials share their (stateless) controller, as run_spec_lockstep builds them,
    so one step_batch call serves them all every tick."""
    controllers: dict = {}
    eps = [spec_episode(spec, controllers, sources) for spec in specs]
    return [ep.finish(log) for ep, log in zip(eps, run_loops([ep.loop for ep in eps]))]


@pytest.fixture
def step_batch_rows(monkeypatch) -> list[int]:
    """The rows of every batched call a guarded controller (game, IMP, MG) serves: ``step_batch``
    (run_loops) or ``effort_batch`` (the point-mass array path)."""
    from coassist.control.controllers import _GuardedController

    rows: list[int] = []
    for name in ("step_batch", "effort_batch"):
        inner = getattr(_GuardedController, name)

        def counting(self, z, *args, _inner=inner):
            rows.append(z.shape[0])
            return _inner(self, z, *args)

        monkeypatch.setattr(_GuardedController, name, counting)
    return rows


def _one_call_per_tick(trials) -> list[int]:
    """The rows of one step_batch call per tick over every run still going (a run left alone
    steps its controller itself)."""
    lengths = [t.n_samples for t in trials]
    going = [sum(n > k for n in lengths) for k in range(max(lengths))]
    return [b for b in going if b > 1]


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory) -> str:
    return write_loop_model(tmp_path_factory.mktemp("model") / "tiny", HORIZON)


@pytest.mark.parametrize("intent", ["nominal", "oracle"])
def test_named_intents_run_in_lockstep_exactly_as_alone(intent):
    specs = _specs(intent)
    alone = [run_spec(spec) for spec in specs]
    together = run_spec_lockstep(specs)
    assert len({t.n_samples for t in alone}) == len(alone)  # they end at different ticks
    for a, b in zip(alone, together):
        assert a.equals(b)


class CountingBatched(ConstantVelocityIntent):
    """Constant velocity with a batcher: row b of the batch is computed exactly as predict() does
    (elementwise, no reduction), so lockstep must equal the per-trial path bit for bit."""

    model_id = "constant-velocity-batched"

    def __init__(self, horizon: int, fail: bool = False) -> None:
        super().__init__(horizon)
        self.calls: list[int] = []
        self.fail = fail

    @property
    def batcher(self):
        return self

    def predict_batch(self, windows: np.ndarray) -> np.ndarray:
        self.calls.append(windows.shape[0])
        if self.fail:
            raise RuntimeError("batched call failed")
        return np.stack([self.predict(w) for w in windows])


@pytest.mark.parametrize("fail", [False, True])
def test_one_batched_call_per_tick_and_the_same_trials(fail):
    specs = _specs("constant-velocity")
    src = CountingBatched(HORIZON, fail=fail)  # shared; every trial's tick.reset resets it (dt only)
    sources = {("constant-velocity", HORIZON, "auto"): src}  # spec_episode's cache key: (intent, horizon, network)
    alone = _alone(specs, sources)
    src.calls.clear()
    together = _together(specs, sources)
    for a, b in zip(alone, together):
        assert a.equals(b)
    # one call per tick while any run goes on; each run drops out of the batch when it ends
    lengths = sorted(t.n_samples for t in together)
    assert len(src.calls) == lengths[-1]
    expected = [sum(n > k for n in lengths) for k in range(lengths[-1])]
    assert src.calls == expected


def test_a_model_in_float64_agrees_to_1e12(tiny_model, step_batch_rows):
    from coassist.intent import load_model_intent

    specs = _specs(tiny_model, network="torch")
    src = load_model_intent(tiny_model, backend="torch")
    src.model.net.double()  # float64 network: batched and batch-1 kernels differ only at 1e-16
    sources = {(tiny_model, HORIZON, "torch"): src}
    alone = _alone(specs, sources)
    step_batch_rows.clear()
    together = _together(specs, sources)
    for a, b in zip(alone, together):
        assert a.n_samples == b.n_samples and a.meta.model_id == b.meta.model_id
        for name in FIELDS:
            np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=0, atol=1e-12, err_msg=name)
    assert step_batch_rows == _one_call_per_tick(together)  # the shared game served them all each tick


@pytest.mark.parametrize("controller", ["impedance", "manual", "cooperative-arbitrated"])
def test_every_controller_kind_runs_in_lockstep_exactly_as_alone(controller, step_batch_rows):
    """IMP and MG are shared (one step_batch per tick, row for row their step); the online-α
    arbitration keeps state between ticks, so each run steps its own, as alone."""
    specs = [replace(s, controller=controller) for s in _specs("oracle")]
    alone = [run_spec(spec) for spec in specs]
    step_batch_rows.clear()
    together = run_spec_lockstep(specs)
    for a, b in zip(alone, together):
        assert a.equals(b)
    assert step_batch_rows == ([] if controller == "cooperative-arbitrated" else _one_call_per_tick(together))


def test_online_alpha_runs_step_their_controllers_in_one_call_a_tick_exactly_as_alone(monkeypatch):
    """run_loops (the reference path, MuJoCo drives in lockstep): the online-α runs, each its own
    controller and arbiter, are stepped by one arbitrated_step_batch a tick (row for row each run's
    step), and give the trials they give alone, bit for bit."""
    from coassist.runtime import batched_loops

    specs = [replace(s, controller="cooperative-arbitrated") for s in _specs("oracle")]
    alone = [run_spec(spec) for spec in specs]
    rows: list[int] = []
    batched = batched_loops.arbitrated_step_batch

    def counting(controllers, *args):
        rows.append(len(controllers))
        return batched(controllers, *args)

    monkeypatch.setattr(batched_loops, "arbitrated_step_batch", counting)
    together = run_spec_lockstep(specs, arrays=False)  # each run its own controller (it keeps state)
    for a, b in zip(alone, together):
        assert a.equals(b)
    assert rows == _one_call_per_tick(together)


def test_arbitrated_groups_take_own_controllers_on_own_games_with_one_guard():
    from coassist.control.arbitration import ArbitratedController
    from coassist.runtime.batched_loops import arbitrated_groups

    eps = [spec_episode(replace(s, controller="cooperative-arbitrated"), None) for s in _specs("nominal")]
    ticks = [ep.loop.tick for ep in eps]
    assert all(type(t.controller) is ArbitratedController for t in ticks)
    assert len({id(t.controller.game) for t in ticks}) == 3
    assert arbitrated_groups(ticks) == [0, 0, 0]
    assert arbitrated_groups(ticks[:1]) == [None]  # alone: its own step
    shared = spec_episode(replace(_specs("nominal")[0], controller="manual"), None).loop.tick
    assert arbitrated_groups([ticks[0], shared, ticks[1]]) == [0, None, 0]
    # the same controller twice (or two on one game) cannot be advanced twice in one call
    assert arbitrated_groups([ticks[0], ticks[0]]) == [None, None]


@pytest.mark.parametrize("network", ["torch", "onnx"])
def test_a_float32_model_agrees_to_its_rounding(tiny_model, network):
    # torch's CPU kernels round a row differently at batch 1 and in a batch (MKL takes other
    # paths: measured up to ~3e-8 on an LSTM output, ~1e-6 on a 200-input linear layer at
    # O(1) inputs). The network's outputs are scaled to [−1, 1]; a few float32 ulps (6e-8)
    # times the target scaler's span (centimetres) is ~1e-8 m on a prediction. The loop's
    # gain from ref_h to the pose over a trial is below 1 (the pose moved ~1e-10 m for
    # ~3e-8 m predictions with the lstm preset), so 1e-6 m and 1e-7 m bound both with margin
    # while a real bookkeeping error (a wrong row, a tick late) moves them by millimetres.
    # ONNX Runtime's kernels (coassist.intent.onnx_network) round within the same bounds.
    if network == "onnx":
        pytest.importorskip("onnxruntime", reason="the onnx extra is not installed")
    specs = _specs(tiny_model, network)
    alone = [run_spec(spec) for spec in specs]
    together = run_spec_lockstep(specs)
    for a, b in zip(alone, together):
        assert a.n_samples == b.n_samples and a.meta.extra["ended"] == b.meta.extra["ended"]
        np.testing.assert_array_equal(a.fault, b.fault)
        np.testing.assert_allclose(b.prediction, a.prediction, rtol=0, atol=1e-6)
        np.testing.assert_allclose(b.pose, a.pose, rtol=0, atol=1e-7)
        np.testing.assert_allclose(b.effort_r, a.effort_r, rtol=0, atol=1e-4)


def test_the_network_backends_give_the_same_trials_to_float32_rounding(tiny_model):
    """torch and ONNX Runtime evaluate the same float32 network (bounds as in the test above);
    each trial records which one ran."""
    pytest.importorskip("onnxruntime", reason="the onnx extra is not installed")
    with_torch = run_spec_lockstep(_specs(tiny_model, "torch"))
    with_onnx = run_spec_lockstep(_specs(tiny_model, "onnx"))
    for a, b in zip(with_torch, with_onnx):
        assert a.meta.extra["network"].startswith("torch ") and b.meta.extra["network"].startswith("onnxruntime ")
        assert a.n_samples == b.n_samples and a.meta.extra["ended"] == b.meta.extra["ended"]
        np.testing.assert_array_equal(a.fault, b.fault)
        np.testing.assert_allclose(b.prediction, a.prediction, rtol=0, atol=1e-6)
        np.testing.assert_allclose(b.pose, a.pose, rtol=0, atol=1e-7)
        np.testing.assert_allclose(b.effort_r, a.effort_r, rtol=0, atol=1e-4)
    with pytest.raises(ValueError, match="TrialSpec.network"):
        TrialSpec(task="linear", intent=tiny_model, network="tensorrt")


def test_a_model_on_onnx_runtime_runs_in_lockstep_bit_for_bit_as_alone(tiny_model):
    """ONNX Runtime's CPU kernels give a row the same bits at any batch size (measured on the
    project's machines; checked first here, skipped where it does not hold): then a lockstep
    group's trials with a float32 model in the loop are bit for bit the per-trial ones."""
    pytest.importorskip("onnxruntime", reason="the onnx extra is not installed")
    from coassist.intent import load_model_intent

    src = load_model_intent(tiny_model, backend="onnx")
    windows = np.random.default_rng(5).normal(scale=0.05, size=(9, src.history, 8))
    if not np.array_equal(src.batcher.predict_batch(windows), np.stack([src.predict(w) for w in windows])):
        pytest.skip("ONNX Runtime's kernels are not batch-invariant on this CPU: lockstep agrees to float32 rounding")
    specs = _specs(tiny_model, "onnx")
    alone = [run_spec(spec) for spec in specs]
    for a, b in zip(alone, run_spec_lockstep(specs), strict=True):
        assert a.equals(b)


class DropLink:
    """A world whose link drops at tick ``at`` (read), everything else the wrapped world's."""

    def __init__(self, world, at: int) -> None:
        self._w, self._at, self._k = world, at, 0

    def __getattr__(self, name):
        return getattr(self._w, name)

    def read(self):
        if self._k == self._at:
            raise ConnectionError("cable pulled")
        self._k += 1
        return self._w.read()


def test_a_lost_link_ends_only_its_run_as_alone():
    specs = _specs("oracle")
    logs_alone = []
    for i, spec in enumerate(specs):
        ep = spec_episode(spec)
        e = ep.loop
        if i == 1:
            e = Loop(DropLink(e.world, 40), e.tick, e.n_max, e.termination)
        logs_alone.append(run_loop(*e))
    eps = [spec_episode(s) for s in specs]
    episodes = [ep.loop for ep in eps]
    episodes[1] = Loop(DropLink(episodes[1].world, 40), *episodes[1][1:])
    logs = run_loops(episodes)
    assert logs[1].ended == "link_lost" and logs[1].n == 40 and "cable pulled" in logs[1].message
    for a, b in zip(logs_alone, logs):
        assert a.n == b.n and a.ended == b.ended
        np.testing.assert_array_equal(a.pose, b.pose)
        np.testing.assert_array_equal(a.fault, b.fault)


class FailingInputs:
    """A tick whose controller inputs fail (a stage's bug) from tick ``at`` on; everything else the wrapped tick's."""

    def __init__(self, tick, at: int) -> None:
        self._t, self._at, self._k = tick, at, -1

    def __getattr__(self, name):
        return getattr(self._t, name)

    def sense(self, k, *args):
        self._k = k
        return self._t.sense(k, *args)

    def control_inputs(self, intent):
        if self._k >= self._at:
            raise RuntimeError("a bug in a stage")
        return self._t.control_inputs(intent)

    def decide(self, intent):
        return self._t.finish(self._t.controller.step(*self.control_inputs(intent)))


@pytest.mark.parametrize("controller", ["manual", "cooperative-arbitrated"])
def test_a_stage_that_fails_in_a_batched_tick_stops_only_its_run(controller):
    """A run whose controller inputs raise leaves the tick's batched controller call (shared MG, online-α
    group) and is stopped by its own act(), as alone; the others go on as they would alone."""
    specs = [replace(s, controller=controller) for s in _specs("oracle")]
    n = 60  # ticks: the failure at 30, then the others on their own
    alone = [run_loop(*spec_episode(spec).loop._replace(n_max=n)) for spec in specs]
    controllers: dict = {}
    episodes = []
    for spec in specs:
        episodes.append(spec_episode(spec, controllers).loop._replace(n_max=n))
        if callable(getattr(episodes[-1].tick.controller, "reset", None)):
            controllers.clear()  # state between ticks: each run its own, as run_spec_lockstep builds them
    episodes[1] = episodes[1]._replace(tick=FailingInputs(episodes[1].tick, 30))
    logs = run_loops(episodes)
    assert logs[1].ended == "internal_error" and logs[1].n == 30 and "a bug in a stage" in logs[1].message
    for i in (0, 2):
        assert logs[i].n == n and logs[i].ended == alone[i].ended == "time_limit"
        np.testing.assert_array_equal(logs[i].pose, alone[i].pose)
        np.testing.assert_array_equal(logs[i].effort_r, alone[i].effort_r)
        np.testing.assert_array_equal(logs[i].fault, alone[i].fault)


def test_run_loops_refuses_what_is_not_a_loop():
    with pytest.raises(ValueError, match=r"episodes\[0\] must be a Loop"):
        run_loops([(1, 2, 3, None)])


def test_collect_per_trial_and_lockstep_options(tiny_model, tmp_path):
    """`coassist collect --per-trial` writes the per-trial path's trials bit for bit; the default
    writes the lockstep path's (the same specs, one group)."""
    from typer.testing import CliRunner

    from coassist.cli import app
    from coassist.data import read_dataset
    from coassist.sim.collect import dataset_specs

    common = [
        "--tasks",
        "linear,curved",
        "--trials",
        "1",
        "--seed",
        "7",
        "--preset",
        PRESET,
        "--intent",
        tiny_model,
        "--workers",
        "1",
    ]
    specs = dataset_specs(
        controller="cooperative",
        users=[0],
        objects=["handle"],
        tasks=["linear", "curved"],
        trials=1,
        seed=7,
        preset=PRESET,
        intent=tiny_model,
    )
    expected = {"--per-trial": [run_spec(s) for s in specs], "--lockstep": run_spec_lockstep(specs)}
    for flag, trials in expected.items():
        out = tmp_path / flag.strip("-")
        res = CliRunner().invoke(app, ["collect", "--out", str(out), flag, *common])
        assert res.exit_code == 0, res.output
        got = sorted(read_dataset(out).trials, key=lambda t: t.meta.seed)
        for a, b in zip(sorted(trials, key=lambda t: t.meta.seed), got, strict=True):
            for name in FIELDS:
                np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=f"{flag} {name}")


def test_stacks_reuse_their_arrays_and_never_cast():
    from coassist.runtime.batched_loops import _Stacks

    stacks = _Stacks()
    rng = np.random.default_rng(0)
    rows = [rng.normal(size=(5, 8)) for _ in range(4)]
    first = stacks.stack("w", rows)
    np.testing.assert_array_equal(first, np.stack(rows))
    fewer = stacks.stack("w", rows[:2])  # a run ended: the same array, fewer rows
    assert np.shares_memory(first, fewer) and fewer.shape == (2, 5, 8)
    np.testing.assert_array_equal(fewer, np.stack(rows[:2]))
    mixed = [rows[0], rows[1].astype(np.float32)]  # promoted as np.stack promotes, not cast into the buffer
    out = stacks.stack("w", mixed)
    assert out.dtype == np.float64 and not np.shares_memory(out, first)
    np.testing.assert_array_equal(out, np.stack(mixed))
    with pytest.raises(ValueError):
        stacks.stack("w", [rows[0], rows[1][:3]])
