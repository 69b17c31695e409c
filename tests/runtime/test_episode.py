"""The episode assembly (runtime/episode.py): one trial built, run and finished the same way in every world.

The references are independent of the module: the point-mass trial is re-assembled here by
hand from the loop's own parts (world, ControlTick, Plan, TrialContext, TargetDwell,
run_loop, the log's columns), as run_trial did before the assembly was shared, and must
match run_trial bit for bit; the sizing rule is computed by hand; the finished Trial's
held DOFs and unwrapped rotations are checked against the start pose and a hand unwrap.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from coassist.control.controllers import ManualGuidance
from coassist.control.presets import get_preset, make_controller
from coassist.interfaces import TrialContext
from coassist.model.impedance import ImpedanceModel
from coassist.runtime.episode import (
    MIN_LOOKAHEAD,
    POINT_MASS_LIMITS,
    POINT_MASS_WRENCH,
    EpisodeLabels,
    build_episode,
    default_time_limit,
    episode_ticks,
    plan_grid,
    run_episode,
)
from coassist.runtime.intent import WindowIntent
from coassist.runtime.loop import LoopLog, TargetDwell, run_loop
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.safety_limits import SafetyLimits
from coassist.runtime.tick import ControlTick, Plan, TickConfig
from coassist.runtime.wrench import WrenchConfig, WrenchPipeline
from coassist.scenario import ForceSensor, get_object, load_intent_source, operator_profile, task_for_seed
from coassist.sim import TrialSpec, run_spec, run_trial
from coassist.sim.point_mass import PointMassWorld

from .fakes import DT, NominalStage, ScriptedEffortWorld

COLUMNS = ("time", "pose", "velocity", "wrench", "reference", "prediction", "intent", "effort_h", "effort_r", "fault")


def _by_hand(task, operator, obj, controller, source, seed: int):
    """The point-mass trial assembled inline from the loop's parts (run_trial before runtime/episode.py)."""
    model = controller.model
    dt, H, Hs = float(model.dt), int(controller.horizon), int(source.horizon)
    n_max = int(math.ceil((2.0 * task.planner.end_time + 10.0) / dt))
    n_grid = n_max + Hs + 1  # the old grid: the horizon's rows only (the episode's is longer; prefixes agree)
    ref_abs = task.planner.grid(n_grid, dt)
    x0 = np.array(task.start, dtype=float)
    world = PointMassWorld(task, operator, obj, model, seed, n_max, n_grid, ForceSensor())
    context = TrialContext(
        dt=dt,
        horizon=H,
        start=x0.copy(),
        target=np.array(task.target, dtype=float),
        reference=ref_abs,
        task=task.kind,
        user=operator.name,
        object=obj.name,
        true_intent=world.intent.positions,
    )
    tick = ControlTick(
        controller,
        WindowIntent(source, H),
        WrenchPipeline(POINT_MASS_WRENCH, dt),
        SafetyLayer(POINT_MASS_LIMITS, dt, 6),
        command_space="effort",
    )
    tick.reset(Plan(ref_abs, np.array((x0[0], x0[1], 0.0, 0.0, 0.0, 0.0))), context)
    t_done = max(task.planner.end_time, world.intent.end_time)
    termination = TargetDwell(task.target, 0.025, int(math.ceil(5.0 / dt)), int(math.ceil(t_done / dt)))
    log = run_loop(world, tick, n_max, termination)
    n = log.n
    return {
        "time": np.arange(n) * dt,
        "pose": log.pose,
        "velocity": log.velocity,
        "wrench": log.wrench,
        "reference": ref_abs[:n, :2],
        "prediction": log.prediction_or_plan(ref_abs[:, :2], Hs),
        "intent": world.intent.positions[:n],
        "effort_h": log.effort_h,
        "effort_r": log.effort_r,
        "fault": log.fault,
        "ended": log.ended,
    }


@pytest.mark.parametrize(
    "spec",
    [
        TrialSpec("curved", seed=5),  # the game, the nominal plan in the loop
        TrialSpec("z", user=2, object="board", controller="impedance", seed=7, intent="oracle", obstacle="large"),
        TrialSpec("linear", controller="cooperative-arbitrated", seed=3, intent="constant-velocity"),
    ],
    ids=["cooperative-nominal", "impedance-oracle-board", "arbitrated-cv"],
)
def test_run_trial_is_the_loop_assembled_by_hand_bit_for_bit(spec):
    trial = run_spec(spec)
    preset = get_preset(spec.preset)
    controller = make_controller(spec.controller, preset)
    task = task_for_seed(spec.task, spec.seed, obstacle=spec.obstacle)
    source = load_intent_source(spec.intent, horizon=max(controller.horizon, preset.game.horizon))
    ref = _by_hand(task, operator_profile(spec.user), get_object(spec.object), controller, source, spec.seed)
    for name in COLUMNS:
        got, want = getattr(trial, name), ref[name]
        assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes(), name
    assert trial.meta.extra["ended"] == ref["ended"]
    assert trial.meta.seed == spec.seed and trial.meta.controller == controller.name


def test_the_episode_runs_through_run_loops_seam_as_run_episode_does():
    # A runner of many loops (lockstep) takes (world, tick, n_max, termination) and finishes
    # each log itself: the Trial must be run_episode's, which is run_trial's.
    spec = TrialSpec("sinusoidal", user=1, controller="manual", seed=2, intent="oracle")
    controller = make_controller("manual", get_preset(spec.preset))
    task = task_for_seed(spec.task, spec.seed)

    def episode():
        model = controller.model
        dt = float(model.dt)
        source = load_intent_source("oracle", horizon=50)
        n_max = episode_ticks(task, dt)
        plan = plan_grid(task, dt, n_max, int(source.horizon))
        world = PointMassWorld(
            task, operator_profile(1), get_object("handle"), model, spec.seed, n_max, plan.shape[0], ForceSensor()
        )
        return build_episode(
            world=world,
            controller=controller,
            intent=WindowIntent(source, int(controller.horizon)),
            wrench=WrenchPipeline(POINT_MASS_WRENCH, dt),
            safety=SafetyLayer(POINT_MASS_LIMITS, dt, 6),
            task=task,
            plan=plan,
            start_pose=np.r_[task.start, 0.0, 0.0, 0.0, 0.0],
            n_max=n_max,
            labels=EpisodeLabels("u", "handle", spec.seed, "sim", None, source.model_id),
            true_intent=world.intent.positions,
            intent_end_time=world.intent.end_time,
        )

    ep = episode()
    seam = ep.finish(run_loop(ep.world, ep.tick, ep.n_max, ep.termination))
    whole = run_episode(episode())
    assert whole.n_samples == seam.n_samples > 100
    for name in COLUMNS:
        assert getattr(seam, name).tobytes() == getattr(whole, name).tobytes(), name
    reference = run_trial(
        task, operator_profile(1), get_object("handle"), controller, load_intent_source("oracle", horizon=50), spec.seed
    )
    assert reference.pose.tobytes() == whole.pose.tobytes() and reference.fault.tobytes() == whole.fault.tobytes()


def test_sizing_is_the_time_limit_rule_and_the_horizons_rows():
    task = task_for_seed("z", 4)
    t_end = task.planner.end_time
    assert default_time_limit(task) == 2.0 * t_end + 10.0
    assert episode_ticks(task, 0.008) == math.ceil((2.0 * t_end + 10.0) / 0.008)
    assert episode_ticks(task, 0.002, time_limit=1.0) == 500
    with pytest.raises(ValueError, match="at least 2 ticks"):
        episode_ticks(task, 0.008, time_limit=0.008)
    assert plan_grid(task, 0.008, 100, 50).shape == (100 + MIN_LOOKAHEAD + 1, 4)
    assert plan_grid(task, 0.002, 100, 200).shape == (100 + 200 + 1, 4)


def test_the_seed_draws_the_same_task_in_every_world(tmp_path):
    from coassist.play.session import PlayConfig, PlaySession

    # run_spec (point mass), drive (MuJoCo, the arms) and play draw the task of seed s from SeedSequence([s, 0])
    pm = run_spec(TrialSpec("curved", seed=9)).meta.extra
    session = PlaySession(
        PlayConfig(user="eve", out=tmp_path, controllers=("manual",), tasks=("curved",), seed=9, paced=False)
    )

    def box(d):
        return {k: [float(v) for v in d[k]] for k in ("center", "size")}

    assert (
        box(session.next_task().obstacle.to_dict())
        == box(pm["obstacle"])
        == box(task_for_seed("curved", 9).obstacle.to_dict())
    )


def test_finish_holds_the_uncontrolled_dofs_and_unwraps_rotations():
    n, H = 6, 3
    start = np.array([0.1, -0.2, 0.3, 0.0, 3.1, 0.0])  # [m, rad] a tool pointing down: |rv| near π
    model = ImpedanceModel(np.full(6, 4.0), np.full(6, 30.0), 0.0, DT)
    world = ScriptedEffortWorld(np.tile(start[:2], (n, 1)))  # never run: finish() gets a log made here
    task = task_for_seed("linear", 0)
    plan = plan_grid(task, DT, n, H)
    intent = np.cumsum(np.full((plan.shape[0], 2), 1e-3), axis=0)
    ep = build_episode(
        world=world,
        controller=ManualGuidance(model),
        intent=NominalStage(H),
        wrench=WrenchPipeline(WrenchConfig(cutoff_hz=None), DT),
        safety=SafetyLayer(SafetyLimits(), DT, 6),
        task=task,
        plan=plan,
        start_pose=start,
        n_max=n,
        labels=EpisodeLabels("u", "none", 0, "sim", None, None),
        true_intent=intent,
        tick_config=TickConfig(dofs=(0, 1, 2, 3, 4, 5)),
    )
    # a rotation vector that wraps: rx-ry along +π·(0,1,0) then the same rotation written as −(2π − |rv|)
    pose = np.tile(start, (n, 1))
    pose[3:, 4] = 3.1 - 2.0 * np.pi
    log = LoopLog(
        pose=pose,
        velocity=np.zeros((n, 6)),
        wrench=np.zeros((n, 6)),
        reference=np.zeros((n, 6)),
        prediction=None,
        effort_h=np.zeros((n, 6)),
        effort_r=np.zeros((n, 6)),
        fault=np.zeros(n, np.int64),
        joints=None,
        joint_velocity=None,
        compute=np.zeros(n),
        ended="time_limit",
    )
    trial = ep.finish(log, {"note": 1})
    assert trial.prediction.shape == (n, H, 6)
    np.testing.assert_array_equal(trial.prediction[:, :, :2], np.stack([plan[k + 1 : k + 1 + H, :2] for k in range(n)]))
    np.testing.assert_array_equal(trial.prediction[:, :, 2:], np.broadcast_to(start[2:], (n, H, 4)))
    np.testing.assert_array_equal(trial.intent[:, :2], intent[:n])
    np.testing.assert_array_equal(trial.intent[:, 2:], np.broadcast_to(start[2:], (n, 4)))
    np.testing.assert_allclose(trial.pose[:, 4], 3.1, rtol=0, atol=1e-12)  # continuous through ±π (a hand unwrap)
    extra = trial.meta.extra
    assert extra["ended"] == "time_limit" and extra["note"] == 1 and extra["arrive_radius"] == 0.025
    empty = LoopLog(
        **{
            **log.__dict__,
            "pose": pose[:0],
            "velocity": pose[:0],
            "wrench": pose[:0],
            "reference": pose[:0],
            "effort_h": pose[:0],
            "effort_r": pose[:0],
            "fault": np.zeros(0, np.int64),
            "compute": np.zeros(0),
            "ended": "link_lost",
            "message": "cable",
        }
    )
    with pytest.raises(RuntimeError, match="before its first tick: cable"):
        ep.finish(empty)
