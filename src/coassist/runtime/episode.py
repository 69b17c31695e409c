"""One trial in any world, assembled once: build, run, finish.

Every world (the point-mass simulator, MuJoCo, the UR5 over RTDE or ROS 2, the Franka,
the browser page) runs a trial of a :class:`~coassist.scenario.tasks.Task` the same way;
each keeps only how its world, wrench pipeline and safety limits are built:

1. **size** (:func:`episode_ticks`, :func:`plan_grid`): the run lasts at most
   ``n_max = ⌈T_limit / dt⌉`` ticks with the default time limit

       T_limit = 2 · t_end + 10 s              (t_end: when the planner's motion ends)

   and the plan [x, y, ẋ, ẏ] is sampled on ``n_max + max(H, H_s, 64) + 1`` ticks (the
   horizon's rows past the last tick; at least 64 so a predictor of a longer horizon
   than the controller's still finds the nominal rows it falls back to);
2. **build** (:func:`build_episode`): the :class:`~coassist.runtime.tick.ControlTick`
   from the world's stages, reset with the :class:`~coassist.runtime.tick.Plan` and the
   :class:`~coassist.interfaces.TrialContext`, and the termination rule
   :class:`~coassist.runtime.loop.TargetDwell`: the run may end once the plan's and the
   (simulated) operator's motion are over, when the tool has stayed within
   ``arrive_radius`` of the plan's end for ``dwell`` seconds;
3. **run**: :func:`coassist.runtime.loop.run_loop` on ``(world, tick, n_max, termination)``
   (an :class:`Episode` holds exactly these, so a runner of many loops at once can take them);
4. **finish** (:meth:`Episode.finish`): the :class:`~coassist.runtime.loop.LoopLog` as a
   :class:`~coassist.data.Trial`: time k·dt, the logged rows, the prediction (or the plan's
   next H_s rows where the source was the nominal plan, eq. 4.7), the true intent where a
   simulated operator had one, the columns of uncontrolled DOFs held at the start pose, and
   meta (the task's description, why the run ended, the preset, the target ball, the
   world's own fields). A logged row that is not finite (a sensor's NaN or a 1e300
   rotation that made the hand wrench infinite) is still written, never dropped with the
   run: the row holds the last finite one, its tick carries the column's flag
   (NONFINITE_WRENCH, NONFINITE_STATE, NONFINITE_EFFORT, NONFINITE_REFERENCE), and
   ``meta.extra["nonfinite_rows"]`` and ``["log_note"]`` say which columns and ticks.

:func:`run_episode` is build's result → run → finish. The seed scheme (task and trial
streams of one seed) is :mod:`coassist.scenario.seeds`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from coassist.data import Trial, TrialMeta
from coassist.interfaces import FEATURES, Fault, TrialContext
from coassist.runtime.batched_loops import Loop
from coassist.runtime.loop import LoopLog, TargetDwell, Termination, run_loop
from coassist.runtime.safety_limits import SafetyLimits
from coassist.runtime.tick import ControlTick, Plan, TickConfig
from coassist.runtime.world import RobotState, World, optional_member
from coassist.runtime.wrench import WrenchConfig
from coassist.scenario.tasks import Task
from coassist.spatial import unwrap_rotation_vectors

__all__ = [
    "ARRIVE_RADIUS",
    "DWELL",
    "MIN_LOOKAHEAD",
    "POINT_MASS_LIMITS",
    "POINT_MASS_WRENCH",
    "Episode",
    "EpisodeLabels",
    "build_episode",
    "default_time_limit",
    "episode_ticks",
    "plan_grid",
    "run_episode",
]

#: [m] the target ball that ends a trial (σ's ε, thesis eq. 5.11).
ARRIVE_RADIUS = 0.025
#: [s] time inside the ball that ends a trial (≥ σ's τ = 3 s so σ is computable).
DWELL = 5.0
#: Fewest plan rows past the last tick (module docstring, step 1).
MIN_LOOKAHEAD = 64

#: The point-mass worlds' (simulated and the page's) sensor reading is already zeroed and
#: carries no payload (the object's mass acts physically): their wrench pipeline only checks
#: (stale, spike, saturation, non-finite) and neither filters nor shrinks, so the thesis'
#: loop is kept.
POINT_MASS_WRENCH = WrenchConfig(
    cutoff_hz=None, deadband_force=0.0, deadband_torque=0.0, force_range=327.67, torque_range=30.0
)
#: A point-mass world is an ideal admittance robot, not an arm: no joints, and its
#: simulated operators move up to ~0.4 m/s, so its tool-speed limit is the UR's 1 m/s
#: (coassist's arm worlds default to 0.25 m/s).
POINT_MASS_LIMITS = SafetyLimits(tool_speed=1.0)


def default_time_limit(task: Task) -> float:
    """T_limit = 2 · t_end + 10 s [s], t_end when the task's planned motion ends."""
    return 2.0 * float(task.planner.end_time) + 10.0


def episode_ticks(task: Task, dt: float, time_limit: float | None = None) -> int:
    """n_max = ⌈T_limit / dt⌉ (``time_limit`` [s], None: :func:`default_time_limit`); at least 2."""
    limit = default_time_limit(task) if time_limit is None else float(time_limit)
    n_max = int(math.ceil(limit / float(dt)))
    if n_max < 2:
        raise ValueError(f"time_limit must cover at least 2 ticks of {dt} s, got {time_limit!r}")
    return n_max


def plan_grid(task: Task, dt: float, n_max: int, horizon: int) -> np.ndarray:
    """(n_max + max(horizon, MIN_LOOKAHEAD) + 1, 4) the planner's [x, y, ẋ, ẏ] on the tick grid [m, m/s];
    ``horizon``: the most rows any stage reads ahead (the controller's, the intent source's)."""
    return task.planner.grid(int(n_max) + max(int(horizon), MIN_LOOKAHEAD) + 1, float(dt))


@dataclass(frozen=True)
class EpisodeLabels:
    """What a trial's meta says about who and what ran it (:class:`~coassist.data.TrialMeta`).

    user, object : names.  seed : the trial's seed.  origin : "sim", "mujoco", "ur5", … (TrialMeta.origin).
    preset : the control preset's name.  model_id : the intent source's (None: the nominal plan).
    """

    user: str
    object: str
    seed: int
    origin: str
    preset: str | None
    model_id: str | None


@dataclass(eq=False)
class Episode:
    """One trial ready to run: what :func:`~coassist.runtime.loop.run_loop` takes, and how to finish it.

    world, tick, n_max, termination : run_loop's arguments (the tick is reset for this run).
    task, plan : the task and its (n, 4) plan grid, absolute [m, m/s].  start_pose : (6,).
    true_intent : (≥ n, 2) the simulated operator's intent [m], or None.
    log_intent : whether the Trial keeps true_intent as its intent column (not where a person,
    not the simulated operator, held the handle).
    labels : :class:`EpisodeLabels`.  arrive_radius [m], dwell [s] : the termination's ball.
    context : what the tick's stages were reset with (the intent source is told its plan, path and obstacles
    from it and nothing else): the one record of what the robot was told, which the drive's one-line
    statement and the live view read.
    extra : the world's own meta fields.
    """

    world: World
    tick: ControlTick
    n_max: int
    termination: Termination
    task: Task
    plan: np.ndarray
    start_pose: np.ndarray
    true_intent: np.ndarray | None
    log_intent: bool
    labels: EpisodeLabels
    arrive_radius: float
    dwell: float
    context: TrialContext
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def loop(self) -> Loop:
        """run_loop's arguments, for :func:`~coassist.runtime.batched_loops.run_loops` (many episodes in lockstep)."""
        return Loop(self.world, self.tick, self.n_max, self.termination)

    def run(
        self, *, deadline: float | None = None, on_tick: Callable[[int, RobotState, object], None] | None = None
    ) -> LoopLog:
        """:func:`~coassist.runtime.loop.run_loop` on this episode (``deadline``, ``on_tick``: its own)."""
        return run_loop(self.world, self.tick, self.n_max, self.termination, deadline=deadline, on_tick=on_tick)

    def finish(self, log: LoopLog, extra: Mapping[str, Any] | None = None) -> Trial:
        """The run as a :class:`~coassist.data.Trial` (module docstring, step 4); ``extra``: more meta fields.

        Raises ``RuntimeError`` when the run ended before its first tick (nothing to keep).
        """
        n = log.n
        if n == 0:
            raise RuntimeError(f"the run ended before its first tick: {log.message or log.ended}")
        message = log.message
        detail = optional_member(self.world, "stop_detail")  # a world that knows why the robot stopped says so
        if detail and log.ended in ("robot_stop", "safety_stop"):
            message = log.message = detail
        tick = self.tick
        dofs = list(tick.config.dofs)
        d, dt = tick.d, tick.dt
        pred = log.prediction_or_plan(self.plan, tick.Hs)
        held = self.start_pose[dofs[2:]]  # the uncontrolled DOFs' columns: where they are held
        if d > 2:
            full = np.empty((n, pred.shape[1], d))
            full[:, :, :2] = pred
            full[:, :, 2:] = held
            pred = full
        intent = None
        if self.true_intent is not None and self.log_intent:
            intent = np.empty((n, d))
            intent[:, :2] = self.true_intent[:n]
            intent[:, 2:] = held
        columns, fault, nonfinite = _hold_nonfinite(log)
        pose = columns["pose"]
        if d == 6:  # rotation vectors continuous through ±π: a tool pointing down sits at |rv| ≈ π
            pose = pose.copy()
            pose[:, 3:6] = unwrap_rotation_vectors(pose[:, 3:6], self.start_pose[3:6])
        labels = self.labels
        meta_extra = self.task.to_extra()
        meta_extra.update(
            {
                "ended": log.ended,
                "stop_message": message,
                "preset": labels.preset,
                "arrive_radius": float(self.arrive_radius),
                "dwell": float(self.dwell),
                "features": list(FEATURES),
            }
        )
        meta_extra.update(self.extra)
        if extra:
            meta_extra.update(extra)
        if nonfinite:
            meta_extra["nonfinite_rows"] = nonfinite
            meta_extra["log_note"] = (
                "the log held non-finite values ("
                + ", ".join(
                    f"{name}: {v['ticks']} tick(s) from tick {v['first_tick']}" for name, v in nonfinite.items()
                )
                + "); those rows hold the last finite row and are flagged in the fault column"
            )
        meta = TrialMeta(
            user=labels.user,
            task=self.task.kind,
            object=labels.object,
            controller=tick.controller.name,
            model_id=labels.model_id,
            seed=labels.seed,
            origin=labels.origin,
            dt=dt,
            extra=meta_extra,
        )
        c = columns
        return Trial(
            meta=meta,
            time=np.arange(n) * dt,
            pose=pose,
            velocity=c["velocity"],
            wrench=c["wrench"],
            reference=c["reference"],
            prediction=pred,
            intent=intent,
            effort_h=c["effort_h"],
            effort_r=c["effort_r"],
            fault=fault,
            joints=c["joints"],
            joint_velocity=c["joint_velocity"],
            alpha=log.alpha,
        )


#: The log's columns that must be finite, and the flag a row held over a non-finite value gets.
_FINITE_COLUMNS = (
    ("pose", Fault.NONFINITE_STATE),
    ("velocity", Fault.NONFINITE_STATE),
    ("wrench", Fault.NONFINITE_WRENCH),
    ("reference", Fault.NONFINITE_REFERENCE),
    ("effort_h", Fault.NONFINITE_WRENCH),
    ("effort_r", Fault.NONFINITE_EFFORT),
    ("joints", Fault.NONFINITE_STATE),
    ("joint_velocity", Fault.NONFINITE_EFFORT),
)


def _hold_nonfinite(log: LoopLog) -> tuple[dict[str, Any], np.ndarray, dict[str, dict[str, int]]]:
    """The log's columns with every non-finite row replaced by the last finite one before it
    (the first finite one after it at the start; zeros if none), the fault column with that
    column's flag on those ticks, and {column: {"first_tick", "ticks"}} of what was replaced.
    On a finite log: the columns and the fault column themselves (no copy)."""
    columns: dict[str, Any] = {name: getattr(log, name) for name, _ in _FINITE_COLUMNS}
    fault = log.fault
    held: dict[str, dict[str, int]] = {}
    for name, flag in _FINITE_COLUMNS:
        a = columns[name]
        if a is None:
            continue
        with np.errstate(all="ignore"):
            good = np.isfinite(a).all(axis=1)
        if good.all():
            continue
        bad = np.flatnonzero(~good)
        held[name] = {"first_tick": int(bad[0]), "ticks": int(bad.size)}
        a = a.copy()
        idx = np.where(good, np.arange(a.shape[0]), -1)
        np.maximum.accumulate(idx, out=idx)  # the last good row at or before each row
        first = int(np.argmax(good)) if good.any() else -1
        idx[idx < 0] = first
        if first < 0:
            a[:] = 0.0
        else:
            a[:] = a[idx]
        columns[name] = a
        if fault is log.fault:
            fault = fault.copy()
        fault[bad] |= int(flag)
    return columns, fault, held


def build_episode(
    *,
    world: World,
    controller: Any,
    intent: Any,
    wrench: Any,
    safety: Any,
    task: Task,
    plan: np.ndarray,
    start_pose: np.ndarray,
    n_max: int,
    labels: EpisodeLabels,
    target: np.ndarray | None = None,
    true_intent: np.ndarray | None = None,
    intent_end_time: float | None = None,
    log_intent: bool = True,
    arrive_radius: float = ARRIVE_RADIUS,
    dwell: float = DWELL,
    kinematics: Any = None,
    tick_config: TickConfig | None = None,
    extra: Mapping[str, Any] | None = None,
    tell_obstacles: bool = True,
    told_obstacles: Sequence[tuple[tuple[float, float], tuple[float, float]]] | None = None,
) -> Episode:
    """The tick of ``world``'s stages reset for ``task`` and the termination rule (module docstring, step 2).

    controller, intent, wrench, safety : the tick's stages (:class:`~coassist.runtime.tick.ControlTick`);
    the command space is the world's.  plan : (≥ n_max + H_s + 1, 4) from :func:`plan_grid`,
    moved wherever the world lays the task out.  start_pose : (6,) the TCP pose the run starts from.
    target : (2,) [m] where the plan ends; None: the task's target.  true_intent : the simulated
    operator's (n, 2) intent (the oracle reads it from the context), and intent_end_time [s] when its
    motion ends (the run may not end before); log_intent: keep it as the Trial's intent column.
    kinematics, tick_config : for joint-velocity worlds.  extra : the world's meta fields.
    tell_obstacles : whether the intent source is told where the task's obstacle is
    (:attr:`TrialContext.obstacles <coassist.interfaces.TrialContext>`); the operator sees it either way.
    told_obstacles : the boxes the robot is told of instead (a lab's scene file,
    :mod:`coassist.scenario.scene`), each ((x, y) centre, (width, depth) size) [m] already in the plan's
    frame (an arm's base frame); None: as ``tell_obstacles`` says.
    """
    tick = ControlTick(
        controller, intent, wrench, safety, command_space=world.command_space, kinematics=kinematics, config=tick_config
    )
    dt = tick.dt
    start_pose = np.array(start_pose, dtype=float)
    target = np.array(task.target if target is None else target, dtype=float)
    # What the robot is told of the scene, in the plan's frame (worlds move the task by a translation).
    shift = np.asarray(plan[0, :2], dtype=float) - np.asarray(task.start, dtype=float)
    told: tuple[tuple[tuple[float, ...], tuple[float, ...]], ...] = (
        ((tuple(float(c) for c in np.asarray(task.obstacle.center) + shift), tuple(task.obstacle.size)),)
        if tell_obstacles
        else ()
    )
    if told_obstacles is not None:
        told = tuple(((float(c[0]), float(c[1])), (float(z[0]), float(z[1]))) for c, z in told_obstacles)
    context = TrialContext(
        dt=dt,
        horizon=tick.H,
        start=start_pose[:2].copy(),
        target=target.copy(),
        reference=plan,
        task=task.kind,
        user=labels.user,
        object=labels.object,
        # only a source that says it reads the simulated operator's intent gets it (the oracle): no source
        # that may run on an arm can come to depend on what an arm never measures
        true_intent=true_intent if getattr(intent, "reads_true_intent", False) is True else None,
        path=task.path.points + shift,
        obstacles=told,  # type: ignore[arg-type]
        seed=labels.seed,
    )
    tick.reset(Plan(plan, start_pose), context)
    t_done = float(task.planner.end_time) if intent_end_time is None else max(task.planner.end_time, intent_end_time)
    termination = TargetDwell(target, arrive_radius, int(math.ceil(float(dwell) / dt)), int(math.ceil(t_done / dt)))
    return Episode(
        world=world,
        tick=tick,
        n_max=int(n_max),
        termination=termination,
        task=task,
        plan=plan,
        start_pose=start_pose,
        true_intent=true_intent,
        log_intent=bool(log_intent),
        labels=labels,
        arrive_radius=float(arrive_radius),
        dwell=float(dwell),
        context=context,
        extra=dict(extra or {}),
    )


def run_episode(
    episode: Episode, *, deadline: float | None = None, on_tick: Callable[[int, RobotState, object], None] | None = None
) -> Trial:
    """Run ``episode`` to its end and return it as a Trial: :meth:`Episode.run` then :meth:`Episode.finish`."""
    return episode.finish(episode.run(deadline=deadline, on_tick=on_tick))
