"""Point-mass trials as arrays (coassist.sim.array_runner) against the reference paths.

The references: every trial alone (``run_loop`` on its episode, :func:`run_spec`) and the
lockstep runner of per-trial objects (``run_loops``, ``run_spec_lockstep(arrays=False)``).
Named intents must give the same Trial bit for bit; a model in the loop the same bit for bit
as ``run_loops`` (the same batches) and, in float64, to 1e-12 as alone; a trial in which a
fault is raised must leave the array path and come back as the reference path's.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from coassist.control.presets import CONTROLLER_KINDS, get_preset
from coassist.interfaces import Fault
from coassist.runtime.batched_loops import Loop
from coassist.runtime.loop import run_loop
from coassist.runtime.safety_limits import SafetyLimits
from coassist.runtime.world import Command
from coassist.scenario.constant_velocity import ConstantVelocityIntent
from coassist.sim.array_runner import fast_path_eligible, run_point_mass_lockstep
from coassist.sim.trial_runner import TrialSpec, run_spec, run_spec_lockstep, spec_episode

from ..intent.conftest import write_loop_model

PRESET = "thesis-evaluation-dm"
HORIZON = get_preset(PRESET).game.horizon
FIELDS = ("pose", "velocity", "wrench", "reference", "prediction", "effort_h", "effort_r", "fault")
TASKS = ("linear", "curved", "sinusoidal", "z")


def _specs(intent: str, n: int = 8, objects=("handle", "board", "heavy")) -> list[TrialSpec]:
    """Every controller kind, the three objects (the board's yaw), three users, trials of different lengths."""
    return [
        TrialSpec(
            task=TASKS[i % 4],
            seed=40 + i,
            user=i % 3,
            object=objects[i % len(objects)],
            controller=CONTROLLER_KINDS[i % 4],
            intent=intent,
            preset=PRESET,
        )
        for i in range(n)
    ]


def _episodes(specs, sources=None):
    controllers: dict = {}
    eps = []
    for spec in specs:
        ep = spec_episode(spec, controllers, sources)
        if callable(getattr(ep.tick.controller, "reset", None)):
            controllers.pop((spec.controller, spec.preset), None)
        eps.append(ep)
    return eps


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory) -> str:
    return write_loop_model(tmp_path_factory.mktemp("model") / "tiny", HORIZON)


def test_named_intents_as_arrays_equal_every_trial_alone_bit_for_bit():
    """Nominal, oracle and constant velocity; every controller kind (the shared game, IMP and
    MG through one step_batch, the online-α arbitration stepping its own); the three objects."""
    intents = ("nominal", "oracle", "constant-velocity")
    specs = [replace(spec, intent=intents[i % 3]) for i, spec in enumerate(_specs("nominal", n=9))]
    eps = _episodes(specs)
    assert all(fast_path_eligible(ep.loop) for ep in eps)
    logs = run_point_mass_lockstep([ep.loop for ep in eps])
    assert all(log is not None for log in logs)  # none left the array path: it did the work
    arrays = [ep.finish(log) for ep, log in zip(eps, logs)]
    alone = [run_spec(spec) for spec in specs]
    assert len({t.n_samples for t in alone}) > 1  # runs drop out of the batch at different ticks
    assert all(np.abs(t.effort_r).max() > 0.5 for t in alone if t.meta.controller != "manual")  # the controllers act
    for spec, a, b in zip(specs, alone, arrays):
        assert a.equals(b), spec
        assert a.meta.to_dict() == b.meta.to_dict()
    # and through run_spec_lockstep, each delivered as it ends
    order: list[int] = []
    got: dict[int, object] = {}
    assert run_spec_lockstep(specs, on_result=lambda i, t: (order.append(i), got.__setitem__(i, t))) == []
    lengths = [t.n_samples for t in alone]
    assert sorted(order) == list(range(len(specs))) and [lengths[i] for i in order] == sorted(lengths)
    for i, a in enumerate(alone):
        assert a.equals(got[i])


def test_a_model_in_the_loop_as_arrays_equals_run_loops_bit_for_bit(tiny_model):
    """The same trials in the same batches as run_loops: the float32 network gets the same
    windows in the same batch, so every row is the same bit for bit."""
    specs = _specs(tiny_model, n=4)
    reference = run_spec_lockstep(specs, arrays=False)
    arrays = run_spec_lockstep(specs)
    for spec, a, b in zip(specs, reference, arrays, strict=True):
        assert a.equals(b), spec
        assert np.isfinite(b.prediction).all()


def test_a_model_in_float64_as_arrays_agrees_with_alone_to_1e12(tiny_model):
    from coassist.intent import load_model_intent

    specs = [replace(spec, network="torch") for spec in _specs(tiny_model, n=2)]
    src = load_model_intent(tiny_model, backend="torch")
    src.model.net.double()  # float64 network: batched and batch-1 kernels differ only at 1e-16
    sources = {(tiny_model, HORIZON, "torch"): src}
    alone = []
    for spec in specs:
        ep = spec_episode(spec, None, sources)
        alone.append(ep.finish(run_loop(*ep.loop)))
    eps = _episodes(specs, sources)
    logs = run_point_mass_lockstep([ep.loop for ep in eps])
    assert all(log is not None for log in logs)
    for a, ep, log in zip(alone, eps, logs):
        b = ep.finish(log)
        assert a.n_samples == b.n_samples and a.meta.extra["ended"] == b.meta.extra["ended"]
        for name in FIELDS:
            np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=0, atol=1e-12, err_msg=name)


def test_a_trial_with_a_fault_leaves_the_array_path_and_is_the_reference_paths(monkeypatch):
    """A tool-speed limit low enough that some trials hit it (TOOL_SPEED_LIMIT, the effort
    braked): those leave the array path at that tick and are run again on run_loops; the
    result is the reference path's, trial for trial."""
    from coassist.sim import trial_runner

    monkeypatch.setattr(trial_runner, "POINT_MASS_LIMITS", SafetyLimits(tool_speed=0.12))
    specs = _specs("oracle", n=8, objects=("handle",))
    reference = run_spec_lockstep(specs, arrays=False)
    flagged = [bool(np.any(t.fault & int(Fault.TOOL_SPEED_LIMIT))) for t in reference]
    assert any(flagged) and not all(flagged)  # the case mixes both kinds of trial
    eps = _episodes(specs)
    logs = run_point_mass_lockstep([ep.loop for ep in eps])
    assert [log is None for log in logs] == flagged  # exactly the trials with a fault left
    arrays = run_spec_lockstep(specs)
    for a, b in zip(reference, arrays, strict=True):
        assert a.equals(b)


class FailingBatched(ConstantVelocityIntent):
    """Constant velocity with a batcher that raises: the per-trial path falls back (flagged)."""

    model_id = "constant-velocity-failing"

    @property
    def batcher(self):
        return self

    def predict_batch(self, windows: np.ndarray) -> np.ndarray:
        raise RuntimeError("batched call failed")


def test_a_failing_batched_source_sends_its_trials_to_the_reference_path():
    specs = _specs("constant-velocity", n=3, objects=("handle",))
    sources = {("constant-velocity", HORIZON, "auto"): FailingBatched(HORIZON)}
    eps = _episodes(specs, sources)
    assert run_point_mass_lockstep([ep.loop for ep in eps]) == [None, None, None]


def test_only_fresh_point_mass_runs_take_the_array_path():
    ep = _episodes([TrialSpec(task="linear", seed=1, preset=PRESET)])[0]
    assert fast_path_eligible(ep.loop)
    assert not fast_path_eligible(Loop(ep.world, ep.tick, ep.n_max, lambda k, pose: False))  # another termination rule

    class Wrapped:  # any other world
        def __init__(self, world):
            self._w = world

        def __getattr__(self, name):
            return getattr(self._w, name)

    assert not fast_path_eligible(Loop(Wrapped(ep.world), ep.tick, ep.n_max, ep.termination))
    with pytest.raises(ValueError, match=r"loops\[1\]"):
        run_point_mass_lockstep([ep.loop, Loop(Wrapped(ep.world), ep.tick, ep.n_max, ep.termination)])
    ep.world.apply(Command(effort=np.zeros(2)))
    assert not fast_path_eligible(ep.loop)  # a world that has already run a period


def test_every_run_on_the_board_as_arrays_equals_every_trial_alone_bit_for_bit():
    """Only board trials: every row yaws and every sensor samples at once (the twins then take the
    rows as they are, no masked copies), runs leaving at different ticks."""
    specs = _specs("nominal", n=4, objects=("board",))
    eps = _episodes(specs)
    logs = run_point_mass_lockstep([ep.loop for ep in eps])
    assert all(log is not None for log in logs)
    alone = [run_spec(spec) for spec in specs]
    assert len({t.n_samples for t in alone}) > 1
    for spec, a, ep, log in zip(specs, alone, eps, logs):
        assert a.equals(ep.finish(log)), spec


class ComplexBatched(ConstantVelocityIntent):
    """Constant velocity answered as complex numbers (imaginary part 0), batched or one run at a time."""

    model_id = "constant-velocity-complex"

    def __init__(self, horizon: int, batched: bool) -> None:
        super().__init__(horizon)
        self.batched = batched

    @property
    def batcher(self):
        return self if self.batched else None

    def predict(self, history: np.ndarray) -> np.ndarray:
        return super().predict(history).astype(complex)

    def predict_batch(self, windows: np.ndarray) -> np.ndarray:
        return np.stack([super(ComplexBatched, self).predict(w) for w in windows]).astype(complex)


@pytest.mark.parametrize("batched", [True, False])
def test_a_complex_answer_sends_its_trials_to_the_reference_path_and_loses_none(batched):
    """Complex predictions are no positions: every trial leaves the array path at tick 0 (before, they passed as
    clean rows and human_reference raised out of run_point_mass_lockstep, losing every trial of the batch), and the
    reference path runs each to its end, its first tick flagged PREDICTION_FALLBACK."""
    specs = _specs("constant-velocity", n=3, objects=("handle",))
    sources = {("constant-velocity", HORIZON, "auto"): ComplexBatched(HORIZON, batched)}
    eps = _episodes(specs, sources)
    assert run_point_mass_lockstep([ep.loop for ep in eps]) == [None, None, None]
    eps = _episodes(specs, sources)
    from coassist.runtime.batched_loops import run_loops

    logs = run_loops([ep.loop for ep in eps])
    for log in logs:
        assert log.n > 0 and log.ended != "internal_error"
        assert int(log.fault[0]) == int(Fault.PREDICTION_FALLBACK)


def test_calibration_trials_in_lockstep_step_their_probes_together_and_equal_every_trial_alone(monkeypatch):
    """MG with the probe (each trial its own controller: the probe's clock and phases are the trial's): one
    probed_efforts a tick on the array path, one probed_steps in run_loops, and every trial alone's bit for bit."""
    from coassist.control import probe
    from coassist.runtime import batched_loops
    from coassist.sim import array_runner

    specs = [
        TrialSpec(
            task=TASKS[i % 4],
            seed=70 + i,
            user=i % 3,
            object=("handle", "heavy")[i % 2],
            controller="manual-probe",
            intent="nominal",
            preset=PRESET,
        )
        for i in range(5)
    ]
    calls = {"arrays": 0, "loops": 0}

    def spy(name, real):
        def counted(*args):
            calls[name] += 1
            return real(*args)

        return counted

    monkeypatch.setattr(array_runner, "probed_efforts", spy("arrays", probe.probed_efforts))
    monkeypatch.setattr(batched_loops, "probed_steps", spy("loops", probe.probed_steps))
    alone = [run_spec(spec) for spec in specs]
    assert len({t.n_samples for t in alone}) > 1 and all(np.abs(t.effort_r).max() > 0.5 for t in alone)  # pushed
    for arrays in (True, False):
        before = dict(calls)
        together = run_spec_lockstep(specs, arrays=arrays)
        for spec, a, b in zip(specs, alone, together, strict=True):
            assert a.equals(b), (arrays, spec)
        # one batched call a tick while two runs or more go on: the longest trial's second-longest length at least
        second = sorted(t.n_samples for t in alone)[-2]
        assert calls["arrays" if arrays else "loops"] - before["arrays" if arrays else "loops"] >= second - 1
    assert calls["arrays"] and calls["loops"]
