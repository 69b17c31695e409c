"""Many runs of the loop in lockstep: one batched network call per tick for all of them.

:func:`run_loops` runs every episode's loop as :func:`~coassist.runtime.loop.run_loop`
would, one period at a time for all of them together::

    for k = 0, 1, …:                                        every run still going
        row_i = run_i.sense(k)                              read, wrench, feature row
        windows of the runs whose intent shares a network → one predict_batch(B, history, 8)
        the other runs' intent stages alone                 (nominal, oracle, a real-time predictor)
        args_i = run_i.tick.control_inputs(intent_i)        z, ref_h, ref_r, w
        runs sharing a controller → one step_batch(B rows)  (the game's gains are shared)
        online-α runs of one guard → one arbitrated_step_batch (each run its own α)
        calibration runs (MG + probe) → one probed_steps     (each run its own probe)
        over_i = run_i.act(k, intent_i, control_i)          safety, command, log, end?

A run that ends (its termination rule, ``n_max``, a safety or robot stop, a lost link)
drops out of the batch at once. Runs whose intent stages share a ``batcher`` (the
:class:`~coassist.runtime.intent.WindowIntent` of a source with one, e.g. one loaded
model in the loop of many simulated trials) are served by one call per tick; distinct
batchers get one call each. Every other part of a tick is the per-trial code itself
(:class:`~coassist.runtime.loop.LoopRun`, :meth:`ControlTick.sense <coassist.runtime.tick.ControlTick.sense>`
/ ``decide``), so the two runners cannot drift.

Runs whose controller is one object without state between ticks (no ``reset``: the
game controller, IMP and MG of a batch; ``run_spec_lockstep`` and ``drive_lockstep`` share them) are stepped by
one ``step_batch`` call per tick, which gives row for row what ``step`` gives, bit for bit
(the guard's checks once over the batch, the game's three matrix-vector products per row:
a matrix-matrix product over the batch would round differently). The online-α runs, each with
a controller and arbiter of its own, are stepped by one ``arbitrated_step_batch`` per group
(:func:`arbitrated_groups`: one guard), row for row each run's ``step``, bit for bit. Any other
controller that keeps state is stepped by its own tick.

Exactness. Nominal and oracle intents, and any batcher whose rows do not depend on the
batch, give the per-trial logs bit for bit. A float32 network evaluated by BLAS does
depend on it: torch's CPU kernels (MKL) take other code paths for other batch sizes
(measured: an LSTM's row at batch 1 differs from the same row in any batch ≥ 2 by up to
~3e-8, a 200-input linear layer's by ~1e-6 between batches 1, 2–3 and ≥ 4), so a run's
predictions equal its per-trial ones to float32 rounding, and the trajectory follows
them to that rounding times the loop's gain from prediction to pose (tests/runtime/
test_batched_loops.py measures both; in float64 the runs agree to 1e-12). ONNX Runtime's
kernels (the simulated loop's default where the ``onnx`` extra is installed,
:mod:`coassist.intent.onnx_network`) give a row the same bits at every batch size on the
project's machines, so there a lockstep run is its per-trial run bit for bit (tested where
it holds). For the same episodes in the same order the result is deterministic.

If a batched call raises, that tick's windows are predicted one by one, as the
per-trial loop would (a failing row falls back alone, flagged).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from coassist.control.arbitration import ArbitratedController, arbitrated_step_batch, guard_key
from coassist.control.probe import probe_key, probed_steps
from coassist.runtime.loop import LINK_LOST, LoopLog, LoopRun, Termination
from coassist.runtime.tick import ControlTick
from coassist.runtime.world import World

__all__ = ["Loop", "arbitrated_groups", "intent_batcher", "probed_groups", "run_loops", "shared_controller"]


class Loop(NamedTuple):
    """What :func:`~coassist.runtime.loop.run_loop` takes for one run: a world, a tick that
    has been reset for this run, at most ``n_max`` periods, the termination rule."""

    world: World
    tick: ControlTick
    n_max: int
    termination: Termination | None = None


def run_loops(
    episodes: Sequence[Loop],
    clock: Callable[[], float] = time.perf_counter,
    on_end: Callable[[int, LoopLog], None] | None = None,
    after_tick: Callable[[], None] | None = None,
) -> list[LoopLog]:
    """Run every episode's loop in lockstep (module docstring); their logs, in order.

    Each log is what ``run_loop(*episode)`` gives (no deadline, no monitor: simulated
    worlds), up to the float rounding of batched network calls. ``compute`` is each
    tick's own work plus its share of the batched call. ``on_end(i, log)`` is called as
    run i ends, while the others go on (so a caller can write each trial at once).
    ``after_tick()`` is called after every period in which a run commanded its world, once
    all have (worlds stepped together: :class:`coassist.robot.mujoco_world.MujocoArmGroup`).
    """
    runs = []
    for i, ep in enumerate(episodes):
        if not isinstance(ep, Loop):
            raise ValueError(f"episodes[{i}] must be a Loop (world, tick, n_max, termination), got {type(ep).__name__}")
        runs.append(LoopRun(ep.world, ep.tick, ep.n_max, ep.termination, clock=clock, split=True))
    batchers = [intent_batcher(run.tick) for run in runs]
    steppers = [shared_controller(run.tick) for run in runs]
    arbitrated = arbitrated_groups([run.tick for run in runs])
    probed = probed_groups([run.tick for run in runs])
    active = [i for i, run in enumerate(runs) if run.n_max > 0]
    if on_end is not None:
        for i, run in enumerate(runs):
            if run.n_max <= 0:
                on_end(i, run.log())
    stacks = _Stacks()
    k = 0
    while active:
        answers: dict[int, Any] = {}
        groups: dict[int, tuple[Any, list[int], list[np.ndarray]]] = {}
        going = []
        for i in active:
            run = runs[i]
            row = run.sense(k)
            if row is LINK_LOST:
                if on_end is not None:
                    on_end(i, run.log())
                continue
            going.append(i)
            if row is None:
                answers[i] = None
                continue
            batcher = batchers[i]
            if batcher is None:
                t0 = clock()
                answers[i] = run.predict(k, row)
                run.charge(clock() - t0)
                continue
            _, members, windows = groups.setdefault(id(batcher), (batcher, [], []))
            members.append(i)
            windows.append(run.tick.intent.push(k, row))
        for batcher, members, windows in groups.values():
            t0 = clock()
            preds = _predict(batcher, windows, [runs[i].tick.intent for i in members], stacks)
            share = (clock() - t0) / len(members)
            for i, pred in zip(members, preds):
                runs[i].charge(share)
                answers[i] = runs[i].accept(pred)
        controls = _step_controllers(runs, going, answers, steppers, arbitrated, probed, clock, stacks)
        active = []
        for i in going:
            if not runs[i].act(k, answers[i], controls.get(i)) and k + 1 < runs[i].n_max:
                active.append(i)
            elif on_end is not None:
                on_end(i, runs[i].log())
        if after_tick is not None and going:
            after_tick()
        k += 1
    return [run.log() for run in runs]


def intent_batcher(tick: ControlTick) -> Any:
    """The tick's intent stage's batcher (``predict_batch``), or None where the stage is called
    alone (the nominal plan, a stage without ``push``/``accept``, a source without one).
    Runs whose batchers are one object share one call per tick."""
    intent = tick.intent
    if intent.nominal or not all(hasattr(intent, a) for a in ("push", "accept")):
        return None
    batcher = getattr(intent, "batcher", None)
    return batcher if callable(getattr(batcher, "predict_batch", None)) else None


class _Stacks:
    """``np.stack`` into arrays kept from tick to tick (one per key: a batcher's windows, a
    controller's arguments), so a tick allocates no batch. What :meth:`stack` returns is
    valid until the next call with its key, as a window from ``WindowIntent.push`` is."""

    def __init__(self) -> None:
        self._buffers: dict[Any, np.ndarray] = {}

    def stack(self, key: Any, arrays: Sequence[np.ndarray]) -> np.ndarray:
        first = arrays[0]
        dtype = getattr(first, "dtype", None)
        if not all(type(a) is np.ndarray and a.dtype == dtype for a in arrays):
            return np.stack(arrays)  # mixed types: np.stack's own promotion, no buffer (which would cast)
        buf = self._buffers.get(key)
        if buf is None or buf.shape[0] < len(arrays) or buf.shape[1:] != first.shape or buf.dtype != dtype:
            buf = self._buffers[key] = np.empty((len(arrays), *first.shape), dtype=dtype)
        out = buf[: len(arrays)]
        np.stack(arrays, out=out)  # equal shapes, or it raises as np.stack(arrays) would
        return out


def shared_controller(tick: ControlTick) -> Any:
    """The tick's controller where runs may share one ``step_batch`` call (it keeps no state
    between ticks: no ``reset``), else None (the tick steps it itself)."""
    controller = tick.controller
    if callable(getattr(controller, "reset", None)) or not callable(getattr(controller, "step_batch", None)):
        return None
    return controller


def probed_groups(ticks: Sequence[ControlTick]) -> list[int | None]:
    """Per tick, the group of calibration runs (:class:`~coassist.control.probe.ProbedGuidance`, each its own: the
    probe's clock and phases are the trial's) that one :func:`~coassist.control.probe.probed_steps` may step together
    (an index; None: the tick steps its controller itself): one :func:`~coassist.control.probe.probe_key` and horizon,
    two runs or more."""
    uses: dict[int, int] = {}
    for tick in ticks:
        c = tick.controller
        uses[id(c)] = uses.get(id(c), 0) + 1
    keys: dict[tuple, list[int]] = {}
    for i, tick in enumerate(ticks):
        key = probe_key(tick.controller)
        if key is not None and uses[id(tick.controller)] == 1:  # a controller two runs share keeps their order
            # the tick's horizon too: its arguments' rows, which one call stacks
            keys.setdefault((key, tick.H), []).append(i)
    out: list[int | None] = [None] * len(ticks)
    for g, members in enumerate(m for m in keys.values() if len(m) > 1):
        for i in members:
            out[i] = g
    return out


def arbitrated_groups(ticks: Sequence[ControlTick]) -> list[int | None]:
    """Per tick, the group of online-α runs whose controllers one :func:`~coassist.control.arbitration.arbitrated_step_batch`
    may step together (an index; None: the tick steps its controller itself): an
    :class:`~coassist.control.arbitration.ArbitratedController` of its own, on a game of its own, with
    the :func:`~coassist.control.arbitration.guard_key` of at least one other run's."""
    keys: dict[tuple, list[int]] = {}
    controllers, games = set(), set()
    for i, tick in enumerate(ticks):
        c = tick.controller
        if type(c) is ArbitratedController and id(c) not in controllers and id(c.game) not in games:
            controllers.add(id(c))
            games.add(id(c.game))
            keys.setdefault(guard_key(c), []).append(i)
    out: list[int | None] = [None] * len(ticks)
    for g, members in enumerate(keys.values()):
        if len(members) > 1:
            for i in members:
                out[i] = g
    return out


def _step_controllers(
    runs: list[LoopRun],
    going: list[int],
    answers: dict[int, Any],
    steppers: list[Any],
    arbitrated: list[int | None],
    probed: list[int | None],
    clock: Callable[[], float],
    stacks: _Stacks,
) -> dict[int, Any]:
    """Run i's controller step for this tick, for the runs whose controller is shared: one
    ``step_batch`` per controller (row for row its ``step``, bit for bit); for the online-α
    runs of one :func:`arbitrated_groups` group: one ``arbitrated_step_batch``, and for the calibration
    runs of one :func:`probed_groups` group one ``probed_steps`` (each row for row each run's ``step``,
    bit for bit). Each run is charged its inputs' time and its share of the call."""
    groups: dict[Any, tuple[Any, list[int], list[tuple[np.ndarray, ...]]]] = {}
    for i in going:
        controller = steppers[i]
        if controller is not None:
            key: Any = id(controller)
        elif arbitrated[i] is not None:
            key = ("arbitrated", arbitrated[i])
        elif probed[i] is not None:
            key = ("probed", probed[i])
        else:
            continue
        t0 = clock()
        try:
            inputs = runs[i].tick.control_inputs(answers[i])
        except Exception:  # noqa: BLE001 - a stage's bug: the run's own act() meets it again and stops that run alone
            continue
        runs[i].charge(clock() - t0)
        _, members, rows = groups.setdefault(key, (controller, [], []))
        members.append(i)
        rows.append(inputs)
    controls: dict[int, Any] = {}
    for key, (controller, members, rows) in groups.items():
        t0 = clock()
        if len(members) == 1:  # a controller of its own (a drive builds one per run): its step, the same rows
            steps = [runs[members[0]].tick.controller.step(*rows[0])]
        elif controller is None:  # the online-α or calibration runs of one group, each its own controller
            batch = arbitrated_step_batch if key[0] == "arbitrated" else probed_steps
            steps = batch(
                [runs[i].tick.controller for i in members],
                *(stacks.stack((key, j), column) for j, column in enumerate(zip(*rows))),
            )
        else:
            steps = controller.step_batch(
                *(stacks.stack((id(controller), j), column) for j, column in enumerate(zip(*rows)))
            )
        share = (clock() - t0) / len(members)
        for i, step in zip(members, steps):
            runs[i].charge(share)
            controls[i] = step
    return controls


def _predict(batcher: Any, windows: list[np.ndarray], intents: list[Any], stacks: _Stacks) -> list[Any]:
    """Row i's prediction (or None where the source raised) for every window."""
    try:
        out = batcher.predict_batch(stacks.stack(id(batcher), windows))
        if isinstance(out, np.ndarray) and out.ndim == 3 and out.shape[0] == len(windows):
            return list(out)
    except Exception:  # one row's fault must not fail the others: predict them alone
        pass
    preds: list[Any] = []
    for intent, window in zip(intents, windows):
        try:
            preds.append(intent.source.predict(window))
        except Exception:
            preds.append(None)
    return preds
