"""The closed loop: robot (impedance plant), controller, intent source, operator, sensor.

Every tick k (t = k·dt, dt = the controller model's, 0.008 s in the presets):

1. the robot reads its tip pose x(k), velocity v(k) and the force sensor's latest
   reading w(k) (the force transmitted through the object, see
   :mod:`coassist.sim.objects`); the planner gives the nominal reference;
2. the intent source predicts the operator's positions for k+1 … k+H from the last
   ``history`` samples of [pose, velocity, wrench, reference]
   (:mod:`coassist.sim.intent_source`), and the world turns them into ref_h;
3. the controller gives the robot effort u_r(k) = ``controller.step(z, ref_h, ref_r, w)``
   with z = [x − x0; v], x0 the start point (refs are shifted the same way);
4. the operator's arm gives the hand force u_h(k) (eq. 4.1 with delay, adaptation and
   noise, :mod:`coassist.sim.operator`);
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

Determinism: every random draw comes from Generators spawned from the trial seed
(SeedSequence([seed, 1]) for the trial, SeedSequence([seed, 0]) for the task in
:func:`run_spec`), and the loop has no other source of variation: the same seed gives
the same Trial bit for bit, in any process with the same numpy/BLAS build and BLAS
thread count (the game's gains come from LAPACK/BLAS, whose rounding depends on how
the work is split between threads: OPENBLAS_NUM_THREADS=1 vs 2 differ in the last bits).

Speed: gains are fixed (LTI game); per tick the loop does scalar arithmetic on plain
floats, writes into preallocated arrays, and passes the controller contiguous views of
precomputed reference grids. See benchmarks/bench_sim.py.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from coassist.config import THESIS_APPLICATION, THESIS_EVALUATION, ControlPreset
from coassist.control.controllers import AssistiveController, Fault, ImpedanceControl, ManualGuidance
from coassist.control.game import cooperative_game
from coassist.data import Trial, TrialMeta
from coassist.model.impedance import ImpedanceModel
from coassist.sim.intent_source import (
    FEATURES,
    IntentSource,
    NominalIntent,
    TrialContext,
    load_intent_source,
)
from coassist.sim.objects import CarriedObject, ForceSensor, get_object
from coassist.sim.operator import OperatorArm, OperatorProfile, intent_trajectory, motor_noise, operator_profile
from coassist.sim.tasks import TASK_KINDS, Task, make_task

#: Controller kinds of :class:`TrialSpec`.
CONTROLLER_KINDS = ("cooperative", "impedance", "manual")
#: Spring of the IMP baseline toward the nominal reference [N/m] (eq. 5.4). The thesis
#: does not give it (its K_i = 0 would make IMP equal MG); 200 N/m pulls back with
#: 10 N at a 5 cm deviation, about what the operators push with.
IMPEDANCE_STIFFNESS = 200.0

_FALLBACK = int(Fault.PREDICTION_FALLBACK)


def scale_positions(preset: ControlPreset, scale: float, name: str) -> ControlPreset:
    """The preset with outputs in units of 1/scale m: every Q multiplied by scale².

    The thesis' weights in SI units make the robot's effort tiny (≈0.06 N per cm of
    error, see coassist.experiments.dmpc_study); in decimetres (scale 10) the robot
    assists with a few N per cm, like the thesis' figures.
    """
    g = preset.game
    s2 = float(scale) ** 2
    game = replace(g, **{q: tuple(s2 * v for v in getattr(g, q)) for q in ("Q_hh", "Q_hr", "Q_rh", "Q_rr")})
    return replace(preset, name=name, game=game)


#: Presets by name: the thesis' (SI units) and the same in decimetres ("-dm").
PRESETS: dict[str, ControlPreset] = {
    THESIS_EVALUATION.name: THESIS_EVALUATION,
    THESIS_APPLICATION.name: THESIS_APPLICATION,
    "thesis-evaluation-dm": scale_positions(THESIS_EVALUATION, 10.0, "thesis-evaluation-dm"),
    "thesis-application-dm": scale_positions(THESIS_APPLICATION, 10.0, "thesis-application-dm"),
}


def get_preset(name: str) -> ControlPreset:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"preset must be one of {tuple(PRESETS)}, got {name!r}") from None


def plant_model(preset: ControlPreset) -> ImpedanceModel:
    """The free plant M a + D v = u (K = 0) of a preset."""
    imp = preset.impedance
    return ImpedanceModel(np.diag(imp.M), np.diag(imp.D), np.zeros((imp.n_dof, imp.n_dof)), imp.dt)


def make_controller(kind: str, preset: ControlPreset):
    """A controller of ``kind`` (one of :data:`CONTROLLER_KINDS`) built from ``preset``."""
    model = plant_model(preset)
    if kind == "cooperative":
        return AssistiveController(cooperative_game(model, preset.game), effort_limit=preset.effort_limit)
    if kind == "impedance":
        return ImpedanceControl(model, IMPEDANCE_STIFFNESS * np.eye(model.n_dof), effort_limit=preset.effort_limit)
    if kind == "manual":
        return ManualGuidance(model)
    raise ValueError(f"controller must be one of {CONTROLLER_KINDS}, got {kind!r}")


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    return int(seed)


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
    arrive_radius: float = 0.025,
    dwell: float = 5.0,
    time_limit: float | None = None,
    preset_name: str | None = None,
) -> Trial:
    """Simulate one trial and return its log (module docstring for the loop).

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
    if not isinstance(task, Task):
        raise ValueError(f"task must be a Task, got {type(task).__name__}")
    if not isinstance(operator, OperatorProfile):
        raise ValueError(f"operator must be an OperatorProfile, got {type(operator).__name__}")
    if not isinstance(obj, CarriedObject):
        raise ValueError(f"obj must be a CarriedObject, got {type(obj).__name__}")
    seed = _check_seed(seed)
    sensor = ForceSensor() if sensor is None else sensor
    model: ImpedanceModel = controller.model
    _diag2(model.M, "M")
    _diag2(model.D, "D")
    dt = float(model.dt)
    H = int(controller.horizon)
    source = NominalIntent(max(H, 2)) if intent_source is None else intent_source
    if not isinstance(source, IntentSource):
        raise ValueError(f"intent_source must implement IntentSource, got {type(source).__name__}")
    Hs, L = int(source.horizon), int(source.history)
    if Hs < H:
        raise ValueError(f"intent source horizon ({Hs}) must be >= the controller's ({H})")
    if time_limit is None:
        time_limit = 2.0 * task.planner.end_time + 10.0
    n_max = int(math.ceil(float(time_limit) / dt))
    if n_max < 2:
        raise ValueError(f"time_limit must cover at least 2 ticks of {dt} s, got {time_limit!r}")

    rng_intent, rng_motor, rng_sensor = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 1]).spawn(3))

    # ---- precomputed grids (absolute frame), with H rows past the end for the horizon
    n_grid = n_max + Hs + 1
    x0 = np.array(task.start, dtype=float)
    ref_abs = task.planner.grid(n_grid, dt)  # (n_grid, 4)
    ref_ctrl = ref_abs.copy()
    ref_ctrl[:, :2] -= x0  # the controller's Δx frame
    intent = intent_trajectory(task, operator, rng_intent, n_grid, dt)
    noise_h = motor_noise(operator, rng_motor, n_max, dt)
    raw_bias = sensor.raw_bias(obj, rng_sensor)
    residual = raw_bias - sensor.zero(raw_bias, rng_sensor)  # what zeroing leaves behind
    noise_s = rng_sensor.normal(0.0, sensor.noise, (n_max + 1, 2))
    fresh = sensor.sample_ticks(n_max + 1, dt).tolist()
    sat = sensor.saturation

    nominal = isinstance(source, NominalIntent)
    context = TrialContext(
        dt=dt, horizon=H, start=x0.copy(), target=np.array(task.target, dtype=float), reference=ref_abs,
        task=task.kind, user=operator.name, object=obj.name, true_intent=intent.positions,
    )
    source.reset(context)

    # ---- plant: per-axis exact ZOH of (M + m) a + D v = f
    eff = ImpedanceModel(np.diag(np.diag(model.M) + obj.mass), model.D, np.zeros((2, 2)), dt)
    Ad, Bd = eff.Ad, eff.Bd
    axv_x, axv_y = float(Ad[0, 2]), float(Ad[1, 3])
    avv_x, avv_y = float(Ad[2, 2]), float(Ad[3, 3])
    bx_x, bx_y = float(Bd[0, 0]), float(Bd[1, 1])
    bv_x, bv_y = float(Bd[2, 0]), float(Bd[3, 1])
    m = obj.mass
    yaw = obj.has_yaw
    rhx, rhy = obj.grasp_offset
    rcx, rcy = obj.center_offset
    k_th, c_th = obj.yaw_stiffness, obj.yaw_damping
    I_c = obj.yaw_inertia if yaw else 1.0
    x0x, x0y = float(x0[0]), float(x0[1])
    tx, ty = float(task.target[0]), float(task.target[1])
    r2 = float(arrive_radius) ** 2
    dwell_ticks = int(math.ceil(float(dwell) / dt))
    t_done = max(task.planner.end_time, intent.end_time)
    k_done = int(math.ceil(t_done / dt))

    arm = OperatorArm(operator, intent.positions, dt, noise_h)

    # ---- preallocated buffers and logs
    z = np.zeros(4)
    wrench = np.zeros(2)
    ref_h_buf = np.zeros((Hs, 4))
    ref_h_view = ref_h_buf[:H]
    hist = np.zeros((2 * L, len(FEATURES))) if L > 0 else np.zeros((0, len(FEATURES)))
    empty_hist = hist[:0]
    empty_hist.setflags(write=False)
    log = np.empty((n_max, 10))  # x y vx vy wx wy uhx uhy urx ury
    faults = np.zeros(n_max, dtype=np.int64)
    pred_log = None if nominal else np.full((n_max, Hs, 2), np.nan)
    ref_pos = ref_abs[:, :2]
    step = controller.step

    # ---- state
    x, y = x0x, x0y
    vx = vy = 0.0
    th = thd = thdd = 0.0
    ax_prev = ay_prev = 0.0
    wx = float(np.clip(residual[0] + noise_s[0, 0], -sat, sat))
    wy = float(np.clip(residual[1] + noise_s[0, 1], -sat, sat))
    bres_x, bres_y = float(residual[0]), float(residual[1])
    nsx_all, nsy_all = noise_s[:, 0].tolist(), noise_s[:, 1].tolist()
    inside = 0
    ended = "time_limit"
    n = n_max
    inv_dt = 1.0 / dt

    for k in range(n_max):
        # 1-2. features and the intent prediction
        fault_extra = 0
        if L > 0:
            row = (x, y, vx, vy, wx, wy, ref_pos[k, 0], ref_pos[k, 1])
            if k == 0:
                hist[:] = row  # pad: the robot was at rest before tick 0
            i = k % L
            hist[i] = row
            hist[i + L] = row
            window = hist[i + 1 : i + 1 + L]
        else:
            window = empty_hist
        ref_r = ref_ctrl[k + 1 : k + 1 + H]
        if nominal:
            ref_h = ref_r
        else:
            try:
                pred = source.predict(window)
                ok = isinstance(pred, np.ndarray) and pred.ndim == 2 and pred.shape[0] >= H and pred.shape[1] == 2
                ok = ok and bool(np.isfinite(pred[:Hs]).all())
            except Exception:  # a failing predictor must not stop the loop
                ok = False
            if ok:
                p = pred[:Hs]
                pred_log[k, : p.shape[0]] = p
                np.subtract(p, x0, out=ref_h_buf[: p.shape[0], :2])
                if p.shape[0] >= 2:
                    np.subtract(p[1:], p[:-1], out=ref_h_buf[1 : p.shape[0], 2:])
                    ref_h_buf[1 : p.shape[0], 2:] *= inv_dt
                    ref_h_buf[0, 2:] = ref_h_buf[1, 2:]
                else:
                    ref_h_buf[0, 2:] = 0.0
                ref_h = ref_h_view
            else:
                fault_extra = _FALLBACK
                ref_h = ref_r
                pred_log[k] = ref_pos[k + 1 : k + 1 + Hs]
        # 3. controller
        z[0] = x - x0x
        z[1] = y - x0y
        z[2] = vx
        z[3] = vy
        wrench[0] = wx
        wrench[1] = wy
        u_r, _, fault = step(z, ref_h, ref_r, wrench)
        urx, ury = u_r.tolist()
        faults[k] = int(fault) | fault_extra
        # 4. operator (the hand point moves with the board's yaw)
        if yaw:
            px, py = x - th * rhy, y + th * rhx
            pvx, pvy = vx - thd * rhy, vy + thd * rhx
        else:
            px, py, pvx, pvy = x, y, vx, vy
        fhx, fhy = arm.force(k, px, py, pvx, pvy)
        # 5. plant and sensor
        nsx, nsy = nsx_all[k + 1], nsy_all[k + 1]
        cx = cy = 0.0
        if yaw:
            tau = rhx * fhy - rhy * fhx - m * (rcx * ay_prev - rcy * ax_prev)
            thdd = (tau - k_th * th - c_th * thd) / I_c
            thd += thdd * dt
            th += thd * dt
            cx, cy = m * thdd * rcy, -m * thdd * rcx  # −m θ̈ J r_c
        fx = fhx + urx + nsx + bres_x + cx
        fy = fhy + ury + nsy + bres_y + cy
        vx_new = avv_x * vx + bv_x * fx
        vy_new = avv_y * vy + bv_y * fy
        x_new = x + axv_x * vx + bx_x * fx
        y_new = y + axv_y * vy + bx_y * fy
        ax_prev = (vx_new - vx) * inv_dt
        ay_prev = (vy_new - vy) * inv_dt
        log[k] = (x, y, vx, vy, wx, wy, fhx, fhy, urx, ury)
        if fresh[k + 1]:
            sx = fhx - m * ax_prev + cx + nsx + bres_x
            sy = fhy - m * ay_prev + cy + nsy + bres_y
            wx = sat if sx > sat else (-sat if sx < -sat else sx)
            wy = sat if sy > sat else (-sat if sy < -sat else sy)
        x, y, vx, vy = x_new, y_new, vx_new, vy_new
        # end: the motion is over and the tip has settled at the target
        if k >= k_done:
            dx, dy = log[k, 0] - tx, log[k, 1] - ty
            if dx * dx + dy * dy < r2:
                inside += 1
                if inside >= dwell_ticks:
                    n = k + 1
                    ended = "target"
                    break
            else:
                inside = 0

    if nominal:
        windows = np.lib.stride_tricks.sliding_window_view(ref_pos[1 : n + Hs], Hs, axis=0)  # (n, 2, Hs)
        prediction = np.ascontiguousarray(windows.transpose(0, 2, 1))
    else:
        prediction = pred_log[:n]
    extra = task.to_extra()
    extra.update(
        {
            "ended": ended,
            "preset": preset_name,
            "object": obj.to_extra(),
            "operator": operator.to_extra(),
            "intent_side": intent.side,
            "intent_amplitude": intent.amplitude,
            "intent_pace": intent.pace,
            "intent_end_time": intent.end_time,
            "sensor_raw_bias": [float(v) for v in raw_bias],
            "sensor_residual_bias": [float(v) for v in residual],
            "arrive_radius": float(arrive_radius),
            "features": list(FEATURES),
        }
    )
    meta = TrialMeta(
        user=operator.name, task=task.kind, object=obj.name, controller=controller.name,
        model_id=source.model_id, seed=seed, source="sim", dt=dt, extra=extra,
    )
    return Trial(
        meta=meta,
        time=np.arange(n) * dt,
        pose=log[:n, 0:2],
        velocity=log[:n, 2:4],
        wrench=log[:n, 4:6],
        reference=ref_pos[:n],
        prediction=prediction,
        intent=intent.positions[:n],
        effort_h=log[:n, 6:8],
        effort_r=log[:n, 8:10],
        fault=faults[:n],
    )


# --------------------------------------------------------------------------- batches


@dataclass(frozen=True)
class TrialSpec:
    """One trial to run, small enough to send to a worker process.

    task : one of :data:`~coassist.sim.tasks.TASK_KINDS`. user : operator index (0 = the
    author). object : "handle" | "board" | "heavy". controller : one of
    :data:`CONTROLLER_KINDS`. preset : one of :data:`PRESETS`. seed : int ≥ 0.
    intent : "nominal" | "oracle" | a model path (loaded in the worker).
    population_seed : which population the user is drawn from.
    """

    task: str
    user: int = 0
    object: str = "handle"
    controller: str = "cooperative"
    preset: str = THESIS_EVALUATION.name
    seed: int = 0
    intent: str = "nominal"
    population_seed: int = 0

    def __post_init__(self) -> None:
        if self.task not in TASK_KINDS:
            raise ValueError(f"TrialSpec.task must be one of {TASK_KINDS}, got {self.task!r}")
        if isinstance(self.user, bool) or not isinstance(self.user, (int, np.integer)) or self.user < 0:
            raise ValueError(f"TrialSpec.user must be an int >= 0, got {self.user!r}")
        get_object(self.object)
        if self.controller not in CONTROLLER_KINDS:
            raise ValueError(f"TrialSpec.controller must be one of {CONTROLLER_KINDS}, got {self.controller!r}")
        get_preset(self.preset)
        for name in ("seed", "population_seed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"TrialSpec.{name} must be an int >= 0, got {v!r}")
        if not isinstance(self.intent, str) or not self.intent:
            raise ValueError(f"TrialSpec.intent must be 'nominal', 'oracle' or a model path, got {self.intent!r}")


def run_spec(spec: TrialSpec, _controllers: dict | None = None) -> Trial:
    """Build everything a spec names and run it: task from SeedSequence([seed, 0]), trial from [seed, 1].

    ``_controllers`` is a cache (controller kind, preset) → controller that batch
    runners pass to reuse the game's gains across trials (building them costs far more
    than a tick); the result does not depend on it.
    """
    task = make_task(spec.task, np.random.default_rng(np.random.SeedSequence([spec.seed, 0])))
    preset = get_preset(spec.preset)
    key = (spec.controller, spec.preset)
    if _controllers is not None and key in _controllers:
        controller = _controllers[key]
    else:
        controller = make_controller(spec.controller, preset)
        if _controllers is not None:
            _controllers[key] = controller
    source = load_intent_source(spec.intent, horizon=max(controller.horizon, preset.game.horizon))
    return run_trial(
        task, operator_profile(spec.user, spec.population_seed), get_object(spec.object), controller,
        source, spec.seed, preset_name=preset.name,
    )


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


def _run_batch(specs: list[TrialSpec]) -> list[tuple[dict, dict]]:
    controllers: dict = {}  # one game per (kind, preset) per batch
    return [_to_payload(run_spec(spec, controllers)) for spec in specs]


def _progress(enabled: bool, total: int):
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    progress = Progress(
        TextColumn("simulating"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
        disable=not enabled, transient=False,
    )
    return progress


def run_trials(
    specs: Sequence[TrialSpec],
    workers: int | None = None,
    progress: bool = True,
    ray_address: str | None = None,
) -> list[Trial]:
    """Run many trials; results in the order of ``specs``, identical to running them one by one.

    Parameters
    ----------
    specs : the trials.
    workers : local processes (default: the machine's CPU count, at most len(specs));
        1 runs in this process.
    progress : show a rich progress bar.
    ray_address : run on a Ray cluster instead (e.g. "auto" or "ray://host:10001");
        needs the optional extra ``pip install coassist[cluster]``.
    """
    specs = list(specs)
    for i, s in enumerate(specs):
        if not isinstance(s, TrialSpec):
            raise ValueError(f"specs[{i}] must be a TrialSpec, got {type(s).__name__}")
    if not specs:
        return []
    if ray_address is not None:
        return _run_ray(specs, ray_address, progress)
    if workers is None:
        workers = os.cpu_count() or 1
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    workers = min(int(workers), len(specs))
    results: list[Trial | None] = [None] * len(specs)
    if workers == 1:
        controllers: dict = {}
        with _progress(progress, len(specs)) as bar:
            task_id = bar.add_task("trials", total=len(specs))
            for i, spec in enumerate(specs):
                results[i] = run_spec(spec, controllers)
                bar.advance(task_id)
        return results  # type: ignore[return-value]

    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # Batches of a few trials: each worker builds a game once per batch, and results
    # stream back often enough for the progress bar.
    size = max(1, min(16, len(specs) // (4 * workers)))
    batches = [list(range(i, min(i + size, len(specs)))) for i in range(0, len(specs), size)]
    # spawn: a clean interpreter per worker (no inherited threads, locks or torch state);
    # callers' scripts need the usual `if __name__ == "__main__":` guard. Workers keep
    # the parent's BLAS thread settings (inherited environment): the game's gains, and
    # so every trial, are bit-identical only for the same BLAS thread count.
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = {pool.submit(_run_batch, [specs[i] for i in batch]): batch for batch in batches}
        with _progress(progress, len(specs)) as bar:
            task_id = bar.add_task("trials", total=len(specs))
            for fut in as_completed(futures):
                for i, payload in zip(futures[fut], fut.result()):
                    results[i] = _from_payload(payload)
                bar.advance(task_id, len(futures[fut]))
    return results  # type: ignore[return-value]


def _run_ray(specs: list[TrialSpec], address: str, progress: bool) -> list[Trial]:
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
    with _progress(progress, len(specs)) as bar:
        task_id = bar.add_task("trials", total=len(specs))
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                results[index[ref]] = _from_payload(ray.get(ref)[0])
                bar.advance(task_id)
    return results  # type: ignore[return-value]
