"""The simulated trials' runner: point-mass trials by name, built and run one, a group or many at once.

A trial closes the loop of robot (impedance plant), controller, intent source, operator and
sensor. Every tick k (t = k·dt, dt = the controller model's, 0.008 s in the presets):

1. the robot reads its tip pose x(k), velocity v(k) and the force sensor's latest
   reading w(k) (the force transmitted through the object, see
   :mod:`coassist.scenario.objects`); the planner gives the nominal reference;
2. the intent source predicts the operator's positions for k+1 … k+H from the last
   ``history`` samples of [pose, velocity, wrench, reference]
   (:mod:`coassist.scenario.intent_registry`), and the world turns them into ref_h;
3. the controller gives the robot effort u_r(k) = ``controller.step(z, ref_h, ref_r, w)``
   with z = [x − x0; v], x0 the start point (refs are shifted the same way);
4. the operator's arm gives the hand force u_h(k) (eq. 4.1 with delay, adaptation and
   noise, :mod:`coassist.scenario.operator`);
5. the plant (M + m) a + D v = u_h + u_r + sensor noise + residual bias (the object's
   mass m adds to the rendered inertia) is integrated exactly over dt (zero-order hold);
   the sensor's next reading is u_h − m a (+ the board's yaw term) + noise + residual
   bias, held between the sensor's 100 Hz samples.

Logged row k (a :class:`~coassist.data.Trial`): time, pose x(k), velocity v(k), wrench
w(k), reference (nominal position at k), prediction (the (H, 2) positions in use at k),
intent (the operator's true desired position at k), effort_h = u_h(k), effort_r =
u_r(k), fault (controller flags | PREDICTION_FALLBACK).

The trial ends when both the planner and the operator's own motion are over and the
tip has stayed within ``arrive_radius`` of the target for ``dwell`` seconds, or at
the time limit (meta.extra["ended"] says which).

The trial is assembled, run and logged by :mod:`coassist.runtime.episode`, as in every
other world. This module holds the trials by name (:class:`TrialSpec`), their assembly
(:func:`build_trial`, :func:`spec_episode`) and their runs: one (:func:`run_trial`,
:func:`run_spec`), a lockstep group (:func:`run_spec_lockstep`, on the point-mass array
path of :mod:`coassist.sim.array_runner` where it can), many (:func:`run_trials`,
:func:`submit_trials`). The world itself (steps 4–5) is :mod:`coassist.sim.point_mass`; the
worker processes and Ray are :mod:`coassist.sim.pool` (:func:`~coassist.sim.pool.worker_pool`,
:class:`~coassist.sim.pool.SubmittedTrials`), each name imported from its own module.

Determinism: every random draw comes from Generators of the trial seed
(:mod:`coassist.scenario.seeds`: the trial's stream here, the task's in :func:`run_spec`), and the loop has no other source of variation: the same seed gives
the same Trial bit for bit, in any process with the same numpy/BLAS build and BLAS
thread count (the game's gains come from LAPACK/BLAS, whose rounding depends on how
the work is split between threads: OPENBLAS_NUM_THREADS=1 vs 2 differ in the last bits).

Speed: gains are fixed (LTI game); per tick the loop does scalar arithmetic on plain
floats, writes into preallocated arrays, and passes the controller contiguous views of
precomputed reference grids. See benchmarks/bench_sim.py.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from coassist._checks import check_int
from coassist._progress import progress_bar
from coassist.config import THESIS_EVALUATION
from coassist.control.presets import CONTROLLERS, get_preset, make_controller
from coassist.data import Trial
from coassist.interfaces import NETWORK_BACKENDS, IntentSource, missing_members
from coassist.model.impedance import ImpedanceModel
from coassist.runtime.batched_loops import run_loops
from coassist.runtime.episode import (
    ARRIVE_RADIUS,
    DWELL,
    POINT_MASS_LIMITS,
    POINT_MASS_WRENCH,
    Episode,
    EpisodeLabels,
    build_episode,
    episode_ticks,
    plan_grid,
    run_episode,
)
from coassist.runtime.intent import WindowIntent
from coassist.runtime.loop import LoopLog
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.wrench import WrenchPipeline
from coassist.scenario.intent_registry import INTENT_SOURCES, shared_intent_source
from coassist.scenario.objects import CarriedObject, ForceSensor, get_object
from coassist.scenario.operator import OperatorProfile, asked_to_go
from coassist.scenario.path_model import ASKED_WAY, check_way
from coassist.scenario.populations import POPULATIONS, population_profile
from coassist.scenario.reference_intents import NominalIntent
from coassist.scenario.tasks import OBSTACLES, TASKS, Task, task_for_seed
from coassist.sim.array_runner import fast_path_eligible, run_point_mass_lockstep
from coassist.sim.point_mass import PointMassWorld
from coassist.sim.pool import SubmittedTrials, payloads, pool_for, run_on_ray

__all__ = [
    "NAMED_GROUP",
    "TrialSpec",
    "build_trial",
    "run_episodes_lockstep",
    "run_spec",
    "run_spec_lockstep",
    "run_trial",
    "run_trials",
    "spec_episode",
    "submit_trials",
]


def _diag2(matrix: np.ndarray, name: str) -> None:
    if matrix.shape != (2, 2) or matrix[0, 1] != 0.0 or matrix[1, 0] != 0.0:
        raise ValueError(f"the simulator needs a 2-DOF (x-y) plant with diagonal {name}, got {matrix.tolist()}")


def run_trial(
    task: Task,
    operator: OperatorProfile,
    obj: CarriedObject,
    controller,
    intent_source: IntentSource | None = None,
    seed: int = 0,
    *,
    sensor: ForceSensor | None = None,
    arrive_radius: float = ARRIVE_RADIUS,
    dwell: float = DWELL,
    time_limit: float | None = None,
    preset_name: str | None = None,
) -> Trial:
    """Simulate one trial and return its log (module docstring for the loop).

    The :class:`~coassist.sim.point_mass.PointMassWorld` runs under the same control tick as every other world
    (:mod:`coassist.runtime.tick`, :func:`coassist.runtime.loop.run_loop`).

    Parameters
    ----------
    task : the task (path, timing, obstacle, target).
    operator : the operator's profile.
    obj : the object between hand and sensor.
    controller : an AssistiveController, ImpedanceControl or ManualGuidance on a
        2-DOF plant with diagonal M and D (anything with ``name``, ``model``,
        ``horizon`` and ``step``).
    intent_source : where ŷ_ref,h comes from; None: :class:`NominalIntent`.
    seed : int ≥ 0; all of the trial's randomness derives from it.
    sensor : the force sensor; default :class:`ForceSensor`.
    arrive_radius : [m] the target ball (σ's ε, thesis eq. 5.11).
    dwell : [s] time inside the ball that ends the trial (≥ σ's τ = 3 s so σ is computable).
    time_limit : [s]; default 2 × the planner's end time + 10 s.
    preset_name : recorded in meta.extra.
    """
    return run_episode(
        build_trial(
            task,
            operator,
            obj,
            controller,
            intent_source,
            seed,
            sensor=sensor,
            arrive_radius=arrive_radius,
            dwell=dwell,
            time_limit=time_limit,
            preset_name=preset_name,
        )
    )


def build_trial(
    task: Task,
    operator: OperatorProfile,
    obj: CarriedObject,
    controller,
    intent_source: IntentSource | None = None,
    seed: int = 0,
    *,
    sensor: ForceSensor | None = None,
    arrive_radius: float = ARRIVE_RADIUS,
    dwell: float = DWELL,
    time_limit: float | None = None,
    preset_name: str | None = None,
    asked_way: int = 0,
) -> Episode:
    """:func:`run_trial`'s trial built, not run (same parameters): the
    :class:`~coassist.runtime.episode.Episode` of the point-mass world, for
    :meth:`~coassist.runtime.episode.Episode.run` or :func:`~coassist.runtime.batched_loops.run_loops`.

    ``asked_way``: +1 / −1, the operator is asked to go round the obstacle on the left / right of the plan in this
    trial (a calibration that asks for a way shown too seldom; the operator's side draw is forced, everything else
    drawn as without it, and the trial's meta records it under :data:`~coassist.scenario.path_model.ASKED_WAY`);
    0: the operator chooses (their ``left_preference``)."""
    if not isinstance(task, Task):
        raise ValueError(f"task must be a Task, got {type(task).__name__}")
    if not isinstance(operator, OperatorProfile):
        raise ValueError(f"operator must be an OperatorProfile, got {type(operator).__name__}")
    if not isinstance(obj, CarriedObject):
        raise ValueError(f"obj must be a CarriedObject, got {type(obj).__name__}")
    seed = check_int(seed, "seed", 0)
    asked_way = check_way(asked_way, "asked_way")
    sensor = ForceSensor() if sensor is None else sensor
    model: ImpedanceModel = controller.model
    _diag2(model.M, "M")
    _diag2(model.D, "D")
    dt = float(model.dt)
    H = int(controller.horizon)
    source = NominalIntent(max(H, 2)) if intent_source is None else intent_source
    if not isinstance(source, IntentSource):
        raise ValueError(
            f"intent_source must implement IntentSource, got {type(source).__name__}, which lacks "
            f"{', '.join(missing_members(source, IntentSource))}"
        )
    Hs = int(source.horizon)
    if Hs < H:
        raise ValueError(f"intent source horizon ({Hs}) must be >= the controller's ({H})")
    n_max = episode_ticks(task, dt, time_limit)
    ref_abs = plan_grid(task, dt, n_max, Hs)
    world = PointMassWorld(task, asked_to_go(operator, asked_way), obj, model, seed, n_max, ref_abs.shape[0], sensor)
    intent = world.intent
    x0 = np.array(task.start, dtype=float)
    return build_episode(
        world=world,
        controller=controller,
        intent=WindowIntent(source, H),
        wrench=WrenchPipeline(POINT_MASS_WRENCH, dt),
        safety=SafetyLayer(POINT_MASS_LIMITS, dt, 6),
        task=task,
        plan=ref_abs,
        start_pose=np.array((x0[0], x0[1], 0.0, 0.0, 0.0, 0.0)),
        n_max=n_max,
        labels=EpisodeLabels(
            user=operator.name, object=obj.name, seed=seed, origin="sim", preset=preset_name, model_id=source.model_id
        ),
        true_intent=intent.positions,
        intent_end_time=intent.end_time,
        arrive_radius=arrive_radius,
        dwell=dwell,
        extra={
            "object": obj.to_extra(),
            "operator": operator.to_extra(),
            "intent_side": intent.side,
            **({ASKED_WAY: asked_way} if asked_way else {}),
            "intent_amplitude": intent.amplitude,
            "intent_pace": intent.pace,
            "intent_end_time": intent.end_time,
            # the trial's detour family and its jittered parameters (none for the thesis' bump: its record unchanged)
            **({} if intent.detour is None else {"intent_detour": intent.detour.to_extra()}),
            "sensor_raw_bias": [float(v) for v in world.raw_bias],
            "sensor_residual_bias": [float(v) for v in world.residual],
            # What the effort drives: (M + m) a + D v = u (the label 'hand_alone' removes u_r through it).
            "plant": {
                "M": [float(v) + obj.mass for v in np.diag(model.M)],
                "D": [float(v) for v in np.diag(model.D)],
                "K": [0.0, 0.0],
            },
            # What evaluated a model's network (torch or ONNX Runtime, with its version): the two
            # agree to float32 rounding, which the trajectory carries (coassist.intent.onnx_network).
            **({"network": network} if isinstance(network := getattr(source, "network", None), str) else {}),
        },
    )


# --------------------------------------------------------------------------- batches


@dataclass(frozen=True)
class TrialSpec:
    """One trial to run, small enough to send to a worker process.

    task : one of :data:`~coassist.scenario.tasks.TASKS`. user : operator index (0 = the
    author). object : "handle" | "board" | "heavy". controller : one of
    :data:`~coassist.control.presets.CONTROLLERS`. preset : a name of :data:`coassist.config.CONTROL_PRESETS`. seed : int ≥ 0.
    intent : a name of :data:`~coassist.scenario.intent_registry.INTENT_SOURCES` or a model path (loaded in the worker).
    population_seed : which population the user is drawn from.
    population : who the operators are, one of :data:`~coassist.scenario.populations.POPULATIONS`
    ("thesis": :func:`~coassist.scenario.operator.operator_profile`, the main job's).
    way : the way round the operator is asked to take (:func:`build_trial`'s ``asked_way``): +1 left, −1 right,
    0 their own choice.
    obstacle : a name of :data:`coassist.scenario.tasks.OBSTACLES` ("small": the evaluation's box).
    network : what evaluates a model path's network, one of :data:`~coassist.interfaces.NETWORK_BACKENDS`
    ("auto": ONNX Runtime where installed, else torch; they agree to float32 rounding).
    """

    task: str
    user: int = 0
    object: str = "handle"
    controller: str = "cooperative"
    preset: str = THESIS_EVALUATION.name
    seed: int = 0
    intent: str = "nominal"
    population_seed: int = 0
    obstacle: str = "small"
    network: str = "auto"
    population: str = "thesis"
    way: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "way", check_way(self.way, "TrialSpec.way"))
        if self.population not in POPULATIONS:
            raise ValueError(f"TrialSpec.population must be one of {POPULATIONS}, got {self.population!r}")
        if self.network not in NETWORK_BACKENDS:
            raise ValueError(f"TrialSpec.network must be one of {NETWORK_BACKENDS}, got {self.network!r}")
        if self.obstacle not in OBSTACLES:
            raise ValueError(f"TrialSpec.obstacle must be one of {tuple(OBSTACLES)}, got {self.obstacle!r}")
        if self.task not in TASKS:
            raise ValueError(f"TrialSpec.task must be one of {tuple(TASKS)}, got {self.task!r}")
        object.__setattr__(self, "user", check_int(self.user, "TrialSpec.user", 0))
        get_object(self.object)
        if self.controller not in CONTROLLERS:
            raise ValueError(f"TrialSpec.controller must be one of {tuple(CONTROLLERS)}, got {self.controller!r}")
        get_preset(self.preset)
        for name in ("seed", "population_seed"):
            object.__setattr__(self, name, check_int(getattr(self, name), f"TrialSpec.{name}", 0))
        if not isinstance(self.intent, str) or not self.intent:
            raise ValueError(f"TrialSpec.intent must be 'nominal', 'oracle' or a model path, got {self.intent!r}")


def run_spec(spec: TrialSpec, _controllers: dict | None = None) -> Trial:
    """Build everything a spec names and run it: task from SeedSequence([seed, 0]), trial from [seed, 1].

    ``_controllers`` is a cache (controller kind, preset) → controller that batch
    runners pass to reuse the game's gains across trials (building them costs far more
    than a tick); the result does not depend on it.
    """
    episode = spec_episode(spec, _controllers)
    return run_episode(episode)


def spec_episode(spec: TrialSpec, _controllers: dict | None = None, _sources: dict | None = None) -> Episode:
    """:func:`run_spec`'s trial built, not run (:func:`build_trial`).

    ``_sources``: a cache intent → source for the sources that trials may share (those
    with a ``batcher``, a loaded model: stateless), so a lockstep batch loads each model
    once and calls it once per tick (:func:`run_spec_lockstep`); the result does not
    depend on it.
    """
    task = task_for_seed(spec.task, spec.seed, obstacle=spec.obstacle)
    preset = get_preset(spec.preset)
    key = (spec.controller, spec.preset)
    if _controllers is not None and key in _controllers:
        controller = _controllers[key]
    else:
        controller = make_controller(spec.controller, preset)
        if _controllers is not None:
            _controllers[key] = controller
    horizon = max(controller.horizon, preset.game.horizon)
    source = shared_intent_source(spec.intent, horizon, _sources, spec.network)
    return build_trial(
        task,
        population_profile(spec.population, spec.user, spec.population_seed),
        get_object(spec.object),
        controller,
        source,
        spec.seed,
        preset_name=preset.name,
        asked_way=spec.way,
    )


def run_spec_lockstep(
    specs: Sequence[TrialSpec], on_result: Callable[[int, Trial], None] | None = None, *, arrays: bool = True
) -> list[Trial]:
    """The trials of ``specs``, run in lockstep (:func:`coassist.runtime.batched_loops.run_loops`):
    one network call per tick for all the trials with the same model in the loop.

    Each trial equals its :func:`run_spec` bit for bit with a named intent (nominal,
    oracle, constant-velocity) and to the network's float32 rounding with a model
    (batched kernels round differently; see :mod:`coassist.runtime.batched_loops`).
    Controllers that keep state between ticks (``reset``: the online-α arbitration) are
    built per trial; the others are shared, like :func:`run_spec`'s cache.

    ``on_result(i, trial)`` is called as trial i ends, while the others go on; the trials
    are then not kept and the list returned is empty.

    ``arrays``: run the trials that can as arrays (:mod:`coassist.sim.array_runner`: every stage
    of the tick for all of them at once, the same trials bit for bit); a trial in which
    something unusual happens (any fault flag) leaves that path and runs again here on
    :func:`~coassist.runtime.batched_loops.run_loops`. False: every trial on ``run_loops``.
    """
    controllers: dict = {}
    sources: dict = {}

    def build(spec: TrialSpec) -> Episode:
        episode = spec_episode(spec, controllers, sources)
        if callable(getattr(episode.tick.controller, "reset", None)):  # state between ticks: this trial's alone
            controllers.pop((spec.controller, spec.preset), None)
        return episode

    trials: list[Trial | None] = [None] * len(specs)

    def keep(i: int, trial: Trial) -> None:
        if on_result is not None:
            on_result(i, trial)
        else:
            trials[i] = trial

    run_episodes_lockstep([build(spec) for spec in specs], lambda i: build(specs[i]), keep, arrays=arrays)
    return [] if on_result is not None else [t for t in trials if t is not None]


def run_episodes_lockstep(
    episodes: Sequence[Episode],
    rebuild: Callable[[int], Episode],
    keep: Callable[[int, Trial], None],
    *,
    arrays: bool = True,
) -> None:
    """Run built episodes in lockstep, each trial i handed to ``keep(i, trial)`` as it ends (:func:`run_spec_lockstep`'s
    runner; a person's twin trials, :mod:`coassist.sim.person_twin`, are built otherwise and run here too).

    Those that can run as arrays (:mod:`coassist.sim.array_runner`, one batch per period); a trial that leaves that
    path is built again (``rebuild(i)``: episode i afresh) and runs, with those that could not take it, on
    :func:`~coassist.runtime.batched_loops.run_loops`: the same trials bit for bit either way. ``arrays`` False: every
    trial on ``run_loops``.

    Parameters
    ----------
    episodes : the episodes, none run yet.
    rebuild : episode i built again, from its start.
    keep : called with (i, the trial) as trial i ends.
    arrays : whether the array path is tried.
    """
    episodes = list(episodes)
    fast = [i for i, ep in enumerate(episodes) if arrays and fast_path_eligible(ep.loop)]
    rest = sorted(set(range(len(episodes))) - set(fast))
    by_dt: dict[float, list[int]] = {}  # one array batch per period (the presets share one: one batch)
    for i in fast:
        by_dt.setdefault(float(episodes[i].world.dt), []).append(i)
    for batch in by_dt.values():

        def done(j: int, log: LoopLog, batch: list[int] = batch) -> None:
            keep(batch[j], episodes[batch[j]].finish(log))

        for i, log in zip(batch, run_point_mass_lockstep([episodes[i].loop for i in batch], on_end=done)):
            if log is None:  # it left the array path (something unusual happened): the reference path, afresh
                episodes[i] = rebuild(i)
                rest.append(i)
    rest.sort()
    if rest:
        run_loops([episodes[i].loop for i in rest], on_end=lambda j, log: keep(rest[j], episodes[rest[j]].finish(log)))


def _run_batch(specs: list[TrialSpec]) -> list[tuple[dict, dict]]:
    """A worker process's batch. A model in the loop gets one torch thread: this process is
    one of one-per-core, and more threads would oversubscribe them."""
    if any(spec.intent not in INTENT_SOURCES for spec in specs):
        import torch

        torch.set_num_threads(1)
    controllers: dict = {}  # one game per (kind, preset) per batch
    return payloads([run_spec(spec, controllers) for spec in specs])


def _run_lockstep_batch(specs: list[TrialSpec]) -> list[tuple[dict, dict]]:
    """A worker process's lockstep group (:func:`run_spec_lockstep`), one torch thread as above."""
    if any(spec.intent not in INTENT_SOURCES for spec in specs):
        import torch

        torch.set_num_threads(1)
    return payloads(run_spec_lockstep(specs))


def run_trials(
    specs: Sequence[TrialSpec],
    workers: int | None = None,
    progress: bool = True,
    ray_address: str | None = None,
    on_result: Callable[[int, Trial], None] | None = None,
    lockstep: bool = True,
    pool: Executor | None = None,
    groups: int | None = None,
) -> list[Trial]:
    """Run many trials; results in the order of ``specs``, identical to running them one by one
    (with a model in the loop and ``lockstep``: to the network's float32 rounding, below).

    Parameters
    ----------
    specs : the trials.
    workers : local processes (default: the machine's CPU count, at most len(specs));
        1 runs in this process.
    progress : show a rich progress bar.
    ray_address : run on a Ray cluster instead (e.g. "auto" or "ray://host:10001");
        needs the optional extra ``pip install coassist[cluster]``.
    on_result : called as ``on_result(i, trial)`` as each trial finishes (any order), e.g.
        to write it at once; the trials are then not kept and the list returned is empty.
    lockstep : run the trials in lockstep groups (:func:`run_spec_lockstep`, see
        :func:`submit_trials`): one controller call per tick for a group's trials that share
        a controller and, with a model in the loop, one batched network call, instead of
        one of each per trial and tick (~6× faster with a model, ~2× with a named intent).
        With a model on torch a trial's numbers then equal its :func:`run_spec` to float32
        rounding of the network (~1e-8 m on the pose, set by which trials share its batch:
        deterministic for the same specs and workers, not bit for bit across other
        groupings); on ONNX Runtime (``TrialSpec.network``, the default where installed),
        whose kernels are batch-invariant on the project's machines, and with named intents
        only, bit for bit the same either way.
        False: every trial alone (the reference path). Ray runs trials alone.
    pool : the processes to run on (:func:`~coassist.sim.pool.worker_pool`, kept by the caller across calls);
        None: ``workers`` processes started for this call.
    groups : how many lockstep groups (jobs) the trials are split into on the processes
        (:func:`submit_trials`); None: its rule. Ignored with ``workers`` = 1 (here, one group
        with a model in the loop, else groups of at most :data:`NAMED_GROUP` one after another).
    """
    specs = list(specs)
    for i, s in enumerate(specs):
        if not isinstance(s, TrialSpec):
            raise ValueError(f"specs[{i}] must be a TrialSpec, got {type(s).__name__}")
    if not specs:
        return []
    if ray_address is not None:
        return run_on_ray(_run_batch, specs, ray_address, progress, on_result)
    if workers is None:
        workers = os.cpu_count() or 1
    workers = min(check_int(workers, "workers", 1), len(specs))
    results: list[Trial | None] = [None] * len(specs)

    def deliver(i: int, trial: Trial) -> None:
        if on_result is None:
            results[i] = trial
        else:
            on_result(i, trial)

    if workers == 1:  # in this process: one lockstep group, or trial by trial
        with progress_bar(progress) as bar:
            task_id = bar.add_task("simulating", total=len(specs))

            def each(i: int, trial: Trial) -> None:
                deliver(i, trial)
                bar.advance(task_id)

            if lockstep:  # each trial delivered as it ends, while the others go on
                # Named intents only (exact in any grouping): groups of at most NAMED_GROUP one
                # after another, as on a pool, so memory does not grow with the trial count (a
                # group holds its trials' inputs and logs, ~1-2 MB each, until it ends). With a
                # model, one group: the grouping sets the network's float32 rounding.
                size = len(specs) if _has_model(specs) else NAMED_GROUP
                for start in range(0, len(specs), size):
                    run_spec_lockstep(specs[start : start + size], on_result=functools.partial(_shifted, each, start))
            else:
                controllers: dict = {}  # one game per (kind, preset), as a worker's batch
                for i, spec in enumerate(specs):
                    each(i, run_spec(spec, controllers))
    else:
        with pool_for(pool, workers) as executor:
            submit_trials(specs, executor, workers=workers, lockstep=lockstep, groups=groups).gather(deliver, progress)
    return [] if on_result else results  # type: ignore[return-value]


def _shifted(deliver: Callable[[int, Trial], None], start: int, j: int, trial: Trial) -> None:
    """``deliver(start + j, trial)``: trial j of a group that starts at ``start``."""
    deliver(start + j, trial)


def _has_model(specs: Sequence[TrialSpec]) -> bool:
    return any(spec.intent not in INTENT_SOURCES for spec in specs)


#: The most trials in one lockstep job with named intents only (:func:`submit_trials`).
NAMED_GROUP = 32


def submit_trials(
    specs: Sequence[TrialSpec], pool: Executor, *, workers: int, lockstep: bool = True, groups: int | None = None
) -> SubmittedTrials:
    """Put the trials of ``specs`` on ``pool`` now, in the jobs :func:`run_trials` would run
    (the same grouping, so the same numbers), and return at once; :meth:`SubmittedTrials.gather`
    takes the results. Lets a caller start simulations that a later step needs while this
    one still computes: the pool runs jobs in the order they were submitted.

    With ``lockstep``, each job is a lockstep group run by :func:`run_spec_lockstep` in one
    process, group g holding specs g, g + n, … of n groups (the tasks mix, so the groups'
    lengths balance). With a model in the loop of some trial, n = ``workers``: one group per
    process, so the batched network call is as wide as it can be, and the grouping (which
    sets the float32 rounding) is fixed by ``workers``. With named intents only (exact in
    any grouping), n = ``workers`` groups, more where a group would hold over
    :data:`NAMED_GROUP` trials (a job's trials come back when it ends: a killed run loses
    the jobs in flight, and a progress bar or a writer hears of each job): a group's trials
    share one controller call per tick (measured, one process: 60 nominal trials cost 0.43×
    their per-trial CPU time in groups of 30, 0.46× in groups of 15, 0.69× in groups of 4).
    ``groups`` overrides n (at most one group per trial): a caller that keeps the pool busy
    with other collections at the same time (``Workspace.prefetch`` of the application's
    18-trial cells) asks for fewer, wider groups, each sharing a tick's fixed cost over more
    trials. Without ``lockstep``: batches of a few trials run one by one, each worker
    building a game once per batch.
    """
    specs = tuple(specs)
    workers = min(check_int(workers, "workers", 1), max(1, len(specs)))
    asked = None if groups is None else check_int(groups, "groups", 1)
    if lockstep:
        n = workers if _has_model(specs) else max(workers, math.ceil(len(specs) / NAMED_GROUP))
        n = min(n if asked is None else asked, max(1, len(specs)))
        members = [tuple(range(g, len(specs), n)) for g in range(n)]
        fn: Callable = _run_lockstep_batch
    else:
        size = max(1, min(16, len(specs) // (4 * workers)))
        members = [tuple(range(i, min(i + size, len(specs)))) for i in range(0, len(specs), size)]
        fn = _run_batch
    jobs = [(pool.submit(fn, [specs[i] for i in group]), group) for group in members if group]
    return SubmittedTrials(specs, jobs)
