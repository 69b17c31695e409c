"""The closed loop: robot (impedance plant), controller, intent source, operator, sensor.

Every tick k (t = k·dt, dt = the controller model's, 0.008 s in the presets):

1. the robot reads its tip pose x(k), velocity v(k) and the force sensor's latest
   reading w(k) (the force transmitted through the object, see
   :mod:`coassist.scenario.objects`); the planner gives the nominal reference;
2. the intent source predicts the operator's positions for k+1 … k+H from the last
   ``history`` samples of [pose, velocity, wrench, reference]
   (:mod:`coassist.scenario.intent_source`), and the world turns them into ref_h;
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
other world; this module builds the world (:class:`PointMassWorld`) and the batches.

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

import contextlib
import functools
import math
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass

import numpy as np

from coassist._checks import check_int
from coassist._progress import progress_bar
from coassist.config import THESIS_EVALUATION
from coassist.control.presets import CONTROLLER_KINDS, get_preset, make_controller
from coassist.data import Trial, TrialMeta
from coassist.interfaces import NETWORK_BACKENDS, IntentSource
from coassist.model.impedance import ImpedanceModel
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
from coassist.runtime.lockstep import run_loops
from coassist.runtime.loop import LoopLog
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.world import Command, RobotState
from coassist.runtime.wrench import WrenchPipeline
from coassist.scenario.intent_registry import NAMED_INTENTS, shared_intent_source
from coassist.scenario.objects import CarriedObject, ForceSensor, get_object
from coassist.scenario.operator import OperatorArm, OperatorProfile, intent_trajectory, motor_noise, operator_profile
from coassist.scenario.reference_intents import NominalIntent
from coassist.scenario.seeds import trial_rngs
from coassist.scenario.tasks import OBSTACLES, TASK_KINDS, Task, task_for_seed
from coassist.sim.lockstep import fast_path_eligible, run_point_mass_lockstep


def _diag2(matrix: np.ndarray, name: str) -> None:
    if matrix.shape != (2, 2) or matrix[0, 1] != 0.0 or matrix[1, 0] != 0.0:
        raise ValueError(f"the simulator needs a 2-DOF (x-y) plant with diagonal {name}, got {matrix.tolist()}")


class PointMassWorld:
    """The 2-D point-mass world: the thesis' robot as an ideal admittance, with object, sensor and operator.

    An ``effort`` world (:mod:`coassist.runtime.world`): it renders the impedance model
    physically, (M + m) a + D v = u_h + u_r + n_s + b_res (module docstring, step 5),
    so the tick sends it the robot's effort u_r. It owns time (tick k), the operator's
    arm (:class:`~coassist.scenario.operator.OperatorArm`, called inside :meth:`apply`), the
    board's yaw and the force sensor. All randomness comes from ``seed`` exactly as
    before this world was split out of the loop, so trials are bit-identical.
    """

    command_space = "effort"
    n_joints = 0
    realtime = False

    def __init__(self, task: Task, operator: OperatorProfile, obj: CarriedObject, model: ImpedanceModel, seed: int,
                 n_max: int, n_grid: int, sensor: ForceSensor) -> None:  # fmt: skip
        dt = float(model.dt)
        self.dt = dt
        rng_intent, rng_motor, rng_sensor = trial_rngs(seed, 3)
        self.intent = intent_trajectory(task, operator, rng_intent, n_grid, dt)
        noise_h = motor_noise(operator, rng_motor, n_max, dt)
        self.raw_bias = sensor.raw_bias(obj, rng_sensor)
        residual = self.raw_bias - sensor.zero(self.raw_bias, rng_sensor)  # what zeroing leaves behind
        self.residual = residual
        noise_s = rng_sensor.normal(0.0, sensor.noise, (n_max + 1, 2))
        self._fresh = sensor.sample_ticks(n_max + 1, dt).tolist()
        self._sat = sensor.saturation
        # plant: per-axis exact ZOH of (M + m) a + D v = f
        eff = ImpedanceModel(np.diag(np.diag(model.M) + obj.mass), model.D, np.zeros((2, 2)), dt)
        Ad, Bd = eff.Ad, eff.Bd
        self._axv = (float(Ad[0, 2]), float(Ad[1, 3]))
        self._avv = (float(Ad[2, 2]), float(Ad[3, 3]))
        self._bx = (float(Bd[0, 0]), float(Bd[1, 1]))
        self._bv = (float(Bd[2, 0]), float(Bd[3, 1]))
        self._m = obj.mass
        self._yaw = obj.has_yaw
        self._rh = obj.grasp_offset
        self._rc = obj.center_offset
        self._k_th, self._c_th = obj.yaw_stiffness, obj.yaw_damping
        self._I_c = obj.yaw_inertia if obj.has_yaw else 1.0
        self._arm = OperatorArm(operator, self.intent.positions, dt, noise_h)
        sat = self._sat
        self._nsx, self._nsy = noise_s[:, 0].tolist(), noise_s[:, 1].tolist()
        self._bres = (float(residual[0]), float(residual[1]))
        x0 = task.start
        self.x, self.y = float(x0[0]), float(x0[1])
        self.vx = self.vy = 0.0
        self._th = self._thd = self._thdd = 0.0
        self._ax_prev = self._ay_prev = 0.0
        self.wx = float(np.clip(residual[0] + noise_s[0, 0], -sat, sat))
        self.wy = float(np.clip(residual[1] + noise_s[0, 1], -sat, sat))
        self._seq = 0
        self.k = 0
        self._fh = (0.0, 0.0)
        self._stopped = False

    def read(self) -> RobotState:
        return RobotState(
            t=self.k * self.dt, q=_NO_JOINTS, qd=_NO_JOINTS,
            tool_pose=np.array((self.x, self.y, 0.0, 0.0, 0.0, 0.0)),
            tool_twist=np.array((self.vx, self.vy, 0.0, 0.0, 0.0, 0.0)),
            wrench=np.array((self.wx, self.wy, 0.0, 0.0, 0.0, 0.0)), sensor_rotation=_SENSOR_ROTATION,
            wrench_seq=self._seq,
        )  # fmt: skip

    def hand_force(self) -> tuple[float, float]:
        """The operator's force u_h(k) [N] applied during the last period."""
        return self._fh

    def apply(self, command: Command) -> None:
        """One period: the operator's arm, the plant under u_h + u_r, the sensor's next reading."""
        k = self.k
        dt = self.dt
        effort = command.effort
        if command.stop or self._stopped or effort is None:
            urx = ury = 0.0
        else:
            urx, ury = float(effort[0]), float(effort[1])
            if not (math.isfinite(urx) and math.isfinite(ury)):  # never integrate garbage
                urx = ury = 0.0
        x, y, vx, vy = self.x, self.y, self.vx, self.vy
        th, thd = self._th, self._thd
        # the operator (the hand point moves with the board's yaw)
        rhx, rhy = self._rh
        if self._yaw:
            px, py = x - th * rhy, y + th * rhx
            pvx, pvy = vx - thd * rhy, vy + thd * rhx
        else:
            px, py, pvx, pvy = x, y, vx, vy
        fhx, fhy = self._arm.force(k, px, py, pvx, pvy)
        self._fh = (fhx, fhy)
        # plant and sensor
        m = self._m
        nsx, nsy = self._nsx[k + 1], self._nsy[k + 1]
        bres_x, bres_y = self._bres
        cx = cy = 0.0
        if self._yaw:
            rcx, rcy = self._rc
            tau = rhx * fhy - rhy * fhx - m * (rcx * self._ay_prev - rcy * self._ax_prev)
            thdd = (tau - self._k_th * th - self._c_th * thd) / self._I_c
            thd += thdd * dt
            th += thd * dt
            self._thdd, self._thd, self._th = thdd, thd, th
            cx, cy = m * thdd * rcy, -m * thdd * rcx  # −m θ̈ J r_c
        fx = fhx + urx + nsx + bres_x + cx
        fy = fhy + ury + nsy + bres_y + cy
        if command.stop or self._stopped:
            # a stopped robot brakes: the tool holds where it is, whatever the hand does
            self._stopped = True
            vx_new = vy_new = 0.0
            x_new, y_new = x, y
        else:
            vx_new = self._avv[0] * vx + self._bv[0] * fx
            vy_new = self._avv[1] * vy + self._bv[1] * fy
            x_new = x + self._axv[0] * vx + self._bx[0] * fx
            y_new = y + self._axv[1] * vy + self._bx[1] * fy
        inv_dt = 1.0 / dt
        self._ax_prev = (vx_new - vx) * inv_dt
        self._ay_prev = (vy_new - vy) * inv_dt
        if self._fresh[k + 1]:
            sat = self._sat
            sx = fhx - m * self._ax_prev + cx + nsx + bres_x
            sy = fhy - m * self._ay_prev + cy + nsy + bres_y
            self.wx = sat if sx > sat else (-sat if sx < -sat else sx)
            self.wy = sat if sy > sat else (-sat if sy < -sat else sy)
            self._seq += 1
        self.x, self.y, self.vx, self.vy = x_new, y_new, vx_new, vy_new
        self.k = k + 1

    def stop(self) -> None:
        self._stopped = True
        self.vx = self.vy = 0.0

    def close(self) -> None:
        pass


_NO_JOINTS = np.zeros(0)
_NO_JOINTS.setflags(write=False)
_SENSOR_ROTATION = np.eye(3)  # the sensor's frame is the base frame; one read-only array, not one per tick
_SENSOR_ROTATION.setflags(write=False)


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

    The :class:`PointMassWorld` runs under the same control tick as every other world
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
    return run_episode(build_trial(task, operator, obj, controller, intent_source, seed, sensor=sensor,
                                   arrive_radius=arrive_radius, dwell=dwell, time_limit=time_limit,
                                   preset_name=preset_name))  # fmt: skip


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
) -> Episode:
    """:func:`run_trial`'s trial built, not run (same parameters): the
    :class:`~coassist.runtime.episode.Episode` of the point-mass world, for
    :meth:`~coassist.runtime.episode.Episode.run` or :func:`~coassist.runtime.lockstep.run_loops`."""
    if not isinstance(task, Task):
        raise ValueError(f"task must be a Task, got {type(task).__name__}")
    if not isinstance(operator, OperatorProfile):
        raise ValueError(f"operator must be an OperatorProfile, got {type(operator).__name__}")
    if not isinstance(obj, CarriedObject):
        raise ValueError(f"obj must be a CarriedObject, got {type(obj).__name__}")
    seed = check_int(seed, "seed", 0)
    sensor = ForceSensor() if sensor is None else sensor
    model: ImpedanceModel = controller.model
    _diag2(model.M, "M")
    _diag2(model.D, "D")
    dt = float(model.dt)
    H = int(controller.horizon)
    source = NominalIntent(max(H, 2)) if intent_source is None else intent_source
    if not isinstance(source, IntentSource):
        raise ValueError(f"intent_source must implement IntentSource, got {type(source).__name__}")
    Hs = int(source.horizon)
    if Hs < H:
        raise ValueError(f"intent source horizon ({Hs}) must be >= the controller's ({H})")
    n_max = episode_ticks(task, dt, time_limit)
    ref_abs = plan_grid(task, dt, n_max, Hs)
    world = PointMassWorld(task, operator, obj, model, seed, n_max, ref_abs.shape[0], sensor)
    intent = world.intent
    x0 = np.array(task.start, dtype=float)
    return build_episode(
        world=world, controller=controller, intent=WindowIntent(source, H), wrench=WrenchPipeline(POINT_MASS_WRENCH, dt),
        safety=SafetyLayer(POINT_MASS_LIMITS, dt, 6), task=task, plan=ref_abs,
        start_pose=np.array((x0[0], x0[1], 0.0, 0.0, 0.0, 0.0)), n_max=n_max,
        labels=EpisodeLabels(user=operator.name, object=obj.name, seed=seed, source="sim", preset=preset_name,
                             model_id=source.model_id),
        true_intent=intent.positions, intent_end_time=intent.end_time, arrive_radius=arrive_radius, dwell=dwell,
        extra={
            "object": obj.to_extra(),
            "operator": operator.to_extra(),
            "intent_side": intent.side,
            "intent_amplitude": intent.amplitude,
            "intent_pace": intent.pace,
            "intent_end_time": intent.end_time,
            "sensor_raw_bias": [float(v) for v in world.raw_bias],
            "sensor_residual_bias": [float(v) for v in world.residual],
            # What the effort drives: (M + m) a + D v = u (the label 'hand_alone' removes u_r through it).
            "plant": {"M": [float(v) + obj.mass for v in np.diag(model.M)], "D": [float(v) for v in np.diag(model.D)],
                      "K": [0.0, 0.0]},
            # What evaluated a model's network (torch or ONNX Runtime, with its version): the two
            # agree to float32 rounding, which the trajectory carries (coassist.intent.onnx_network).
            **({"network": network} if isinstance(network := getattr(source, "network", None), str) else {}),
        },
    )  # fmt: skip


# --------------------------------------------------------------------------- batches


@dataclass(frozen=True)
class TrialSpec:
    """One trial to run, small enough to send to a worker process.

    task : one of :data:`~coassist.scenario.tasks.TASK_KINDS`. user : operator index (0 = the
    author). object : "handle" | "board" | "heavy". controller : one of
    :data:`~coassist.control.presets.CONTROLLER_KINDS`. preset : a name of :data:`coassist.config.CONTROL_PRESETS`. seed : int ≥ 0.
    intent : one of :data:`~coassist.interfaces.NAMED_INTENTS` or a model path (loaded in the worker).
    population_seed : which population the user is drawn from.
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

    def __post_init__(self) -> None:
        if self.network not in NETWORK_BACKENDS:
            raise ValueError(f"TrialSpec.network must be one of {NETWORK_BACKENDS}, got {self.network!r}")
        if self.obstacle not in OBSTACLES:
            raise ValueError(f"TrialSpec.obstacle must be one of {tuple(OBSTACLES)}, got {self.obstacle!r}")
        if self.task not in TASK_KINDS:
            raise ValueError(f"TrialSpec.task must be one of {TASK_KINDS}, got {self.task!r}")
        object.__setattr__(self, "user", check_int(self.user, "TrialSpec.user", 0))
        get_object(self.object)
        if self.controller not in CONTROLLER_KINDS:
            raise ValueError(f"TrialSpec.controller must be one of {CONTROLLER_KINDS}, got {self.controller!r}")
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
        task, operator_profile(spec.user, spec.population_seed), get_object(spec.object), controller,
        source, spec.seed, preset_name=preset.name,
    )


def run_spec_lockstep(specs: Sequence[TrialSpec], on_result: Callable[[int, Trial], None] | None = None, *,
                      arrays: bool = True) -> list[Trial]:  # fmt: skip
    """The trials of ``specs``, run in lockstep (:func:`coassist.runtime.lockstep.run_loops`):
    one network call per tick for all the trials with the same model in the loop.

    Each trial equals its :func:`run_spec` bit for bit with a named intent (nominal,
    oracle, constant-velocity) and to the network's float32 rounding with a model
    (batched kernels round differently; see :mod:`coassist.runtime.lockstep`).
    Controllers that keep state between ticks (``reset``: the online-α arbitration) are
    built per trial; the others are shared, like :func:`run_spec`'s cache.

    ``on_result(i, trial)`` is called as trial i ends, while the others go on; the trials
    are then not kept and the list returned is empty.

    ``arrays``: run the trials that can as arrays (:mod:`coassist.sim.lockstep`: every stage
    of the tick for all of them at once, the same trials bit for bit); a trial in which
    something unusual happens (any fault flag) leaves that path and runs again here on
    :func:`~coassist.runtime.lockstep.run_loops`. False: every trial on ``run_loops``.
    """
    controllers: dict = {}
    sources: dict = {}

    def build(spec: TrialSpec) -> Episode:
        episode = spec_episode(spec, controllers, sources)
        if callable(getattr(episode.tick.controller, "reset", None)):  # state between ticks: this trial's alone
            controllers.pop((spec.controller, spec.preset), None)
        return episode

    episodes = [build(spec) for spec in specs]
    trials: list[Trial | None] = [None] * len(specs)

    def keep(i: int, trial: Trial) -> None:
        if on_result is not None:
            on_result(i, trial)
        else:
            trials[i] = trial

    fast = [i for i, ep in enumerate(episodes) if arrays and fast_path_eligible(ep.loop)]
    rest = sorted(set(range(len(specs))) - set(fast))
    by_dt: dict[float, list[int]] = {}  # one array batch per period (the presets share one: one batch)
    for i in fast:
        by_dt.setdefault(float(episodes[i].world.dt), []).append(i)
    for batch in by_dt.values():

        def done(j: int, log: LoopLog, batch: list[int] = batch) -> None:
            keep(batch[j], episodes[batch[j]].finish(log))

        for i, log in zip(batch, run_point_mass_lockstep([episodes[i].loop for i in batch], on_end=done)):
            if log is None:  # it left the array path (something unusual happened): the reference path, afresh
                episodes[i] = build(specs[i])
                rest.append(i)
    rest.sort()
    if rest:
        run_loops([episodes[i].loop for i in rest], on_end=lambda j, log: keep(rest[j], episodes[rest[j]].finish(log)))
    return [] if on_result is not None else [t for t in trials if t is not None]


def _to_payload(trial: Trial) -> tuple[dict, dict]:
    # TrialMeta holds read-only mapping proxies, which do not pickle: ship plain data.
    arrays = {
        name: getattr(trial, name)
        for name in ("time", "pose", "velocity", "wrench", "reference", "prediction", "intent", "effort_h", "effort_r", "fault")
    }
    return trial.meta.to_dict(), arrays


def _from_payload(payload: tuple[dict, dict]) -> Trial:
    meta, arrays = payload
    return Trial(meta=TrialMeta.from_dict(meta), **arrays)


#: How often a worker process checks that its parent is alive [s].
PARENT_POLL = 0.2


def _watch_parent(parent: int) -> None:
    """Worker initializer: end this worker when the process that started it is gone.

    A killed ``collect`` (SIGKILL, or SIGTERM, which Python does not turn into a clean
    shutdown) cannot tell its pool to stop, and the workers, which hold the pool's
    queue themselves, would wait on it for good. A daemon thread polls the parent's pid
    every :data:`PARENT_POLL` seconds (an orphan is re-parented, so getppid() changes)
    and ends the worker at once; portable, unlike Linux's PR_SET_PDEATHSIG, which also
    fires when the *thread* that started the worker ends.
    """
    import threading

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_POLL)
        os._exit(1)  # no clean-up to do: the parent that would take the results is gone

    threading.Thread(target=watch, name="coassist-parent-watch", daemon=True).start()


def _run_batch(specs: list[TrialSpec]) -> list[tuple[dict, dict]]:
    """A worker process's batch. A model in the loop gets one torch thread: this process is
    one of one-per-core, and more threads would oversubscribe them."""
    if any(spec.intent not in NAMED_INTENTS for spec in specs):
        import torch

        torch.set_num_threads(1)
    controllers: dict = {}  # one game per (kind, preset) per batch
    return [_to_payload(run_spec(spec, controllers)) for spec in specs]


def _run_lockstep_batch(specs: list[TrialSpec]) -> list[tuple[dict, dict]]:
    """A worker process's lockstep group (:func:`run_spec_lockstep`), one torch thread as above."""
    if any(spec.intent not in NAMED_INTENTS for spec in specs):
        import torch

        torch.set_num_threads(1)
    return [_to_payload(trial) for trial in run_spec_lockstep(specs)]


def worker_pool(workers: int) -> Executor:
    """``workers`` simulation processes to pass to :func:`run_trials` (``pool``) call after call.

    Each :func:`run_trials` without a pool starts its own processes, and a fresh
    interpreter importing numpy, scipy and torch costs seconds: a pipeline of many small
    collections (``coassist reproduce``: ~40) spends more time starting workers than
    simulating. One pool for the whole run pays it once. spawn: a clean interpreter per
    worker (no inherited threads, locks or torch state); callers' scripts need the usual
    ``if __name__ == "__main__":`` guard. Workers keep the parent's BLAS thread settings
    (inherited environment): the game's gains, and so every trial, are bit-identical
    only for the same BLAS thread count. Use it as a context manager (it shuts down).
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    workers = check_int(workers, "workers", 1)
    ctx = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_watch_parent,
                               initargs=(os.getpid(),))  # fmt: skip


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
    pool : the processes to run on (:func:`worker_pool`, kept by the caller across calls);
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
        return _run_ray(specs, ray_address, progress, on_result)
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
        with _pool_for(pool, workers) as executor:
            submit_trials(specs, executor, workers=workers, lockstep=lockstep, groups=groups).gather(deliver, progress)
    return [] if on_result else results  # type: ignore[return-value]


def _shifted(deliver: Callable[[int, Trial], None], start: int, j: int, trial: Trial) -> None:
    """``deliver(start + j, trial)``: trial j of a group that starts at ``start``."""
    deliver(start + j, trial)


def _has_model(specs: Sequence[TrialSpec]) -> bool:
    return any(spec.intent not in NAMED_INTENTS for spec in specs)


def _pool_for(pool: Executor | None, workers: int):
    """The caller's pool, left running, or a new one of ``workers`` processes, shut down after use."""
    return worker_pool(workers) if pool is None else contextlib.nullcontext(pool)


@dataclass(eq=False)
class SubmittedTrials:
    """Trials running on a pool (:func:`submit_trials`): their specs, and per job the
    future of its payloads and the indices (into ``specs``) of the trials it runs.

    :meth:`gather` takes the jobs off this handle (``jobs`` is empty after it): a future
    holds its job's trials for as long as it is referenced.
    """

    specs: tuple[TrialSpec, ...]
    jobs: list[tuple[Future, tuple[int, ...]]]

    def gather(self, deliver: Callable[[int, Trial], None], progress: bool = False) -> None:
        """Wait for the jobs and call ``deliver(i, trial)`` for every trial as its job finishes (any order).

        Each job's future is let go as soon as its trials are delivered, so what this
        process holds is one job's trials, however many there are: held until the end,
        the futures kept every trial of a collection (2 MB for a nominal trial; 240
        trials made ``collect`` grow by about 1 GB).
        """
        from concurrent.futures import as_completed

        index = dict(self.jobs)
        self.jobs = []
        with progress_bar(progress) as bar:
            task_id = bar.add_task("simulating", total=len(self.specs))
            for fut in as_completed(index):
                members = index.pop(fut)
                payloads = fut.result()
                del fut  # as_completed keeps no reference to a future it has yielded
                for i, payload in zip(members, payloads):
                    deliver(i, _from_payload(payload))
                del payloads
                bar.advance(task_id, len(members))


#: The most trials in one lockstep job with named intents only (:func:`submit_trials`).
NAMED_GROUP = 32


def submit_trials(specs: Sequence[TrialSpec], pool: Executor, *, workers: int, lockstep: bool = True,
                  groups: int | None = None) -> SubmittedTrials:  # fmt: skip
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


def _run_ray(specs: list[TrialSpec], address: str, progress: bool,
             on_result: Callable[[int, Trial], None] | None = None) -> list[Trial]:  # fmt: skip
    try:
        import ray  # optional extra
    except ImportError:
        raise RuntimeError(
            "run_trials(ray_address=...) needs Ray, an optional extra: pip install coassist[cluster]"
        ) from None
    if not ray.is_initialized():
        ray.init(address=address)
    remote = ray.remote(_run_batch)
    refs = [remote.remote([spec]) for spec in specs]
    index = {ref: i for i, ref in enumerate(refs)}
    results: list[Trial | None] = [None] * len(specs)
    pending = list(refs)
    with progress_bar(progress) as bar:
        task_id = bar.add_task("simulating", total=len(specs))
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                trial = _from_payload(ray.get(ref)[0])
                if on_result is None:
                    results[index[ref]] = trial
                else:
                    on_result(index[ref], trial)
                bar.advance(task_id)
    return [] if on_result else results  # type: ignore[return-value]
