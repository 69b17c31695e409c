"""The in-loop ablation of intent sources (issues 18, 34): which prediction makes assistance better?

Every intent source drives the same assistive controllers on the same trials of the
application scenario (the report's seeds, :func:`~coassist.experiments.pipeline.application_seed`),
paired against manual guidance (MG) on those trials, in two worlds: the point-mass world
and the MuJoCo UR5 (``coassist drive``'s world, the arbitrated controller, the sources of
``reproduce.mujoco_sources``; fewer trials, the intervals say what they resolve). The sources:

- ``nominal``: the robot's own plan as the intent (the thesis' M0 assumption, eq. 4.7);
- ``constant-velocity``: the tool's constant-velocity extrapolation;
- ``present``: the present estimate from the hand force, extrapolated at constant velocity
  (:mod:`coassist.scenario.path_hypotheses`: the ``paths`` source without an obstacle);
- ``ridge`` / ``ridge-intent``: the validation-tuned ridge (the ``linear`` preset), trained on
  the tool's future / on the simulated operator's true intent;
- ``lstm-tool``: the LSTM+FC of the simulated stages trained on the tool's future (the thesis);
- ``lstm-hand-alone``: the same network trained on the path the hand alone would have
  produced (the ``thesis`` preset only, :mod:`coassist.experiments.source_training`);
- ``lstm-intent``: the same network trained on the operator's true intent (simulation only);
- ``paths``: the path hypotheses round the obstacle the robot is told of, calibrated to each
  operator (:func:`~coassist.experiments.source_training.calibrate_paths`);
- ``person``: the person model learnt from each operator's own probe trials, told no obstacle,
  no family and no label, the arm measured
  (:func:`~coassist.experiments.source_training.calibrate_person`); on the MuJoCo UR5 the same probe
  trials driven on the arm, fitted there (:func:`calibrate_then_drive`, ``reproduce.mujoco_person_calibration``);
- ``oracle``: the operator's true intent itself, the best any predictor could do;
- then every source registered with ``ablation=True`` in
  :data:`~coassist.scenario.intent_registry.INTENT_SOURCES` (:func:`registered_sources`; none by default).

Every learned source is trained from scratch on the same datasets by the same protocol; only
the label differs, and the ridge's model class. Each LSTM source is trained ``source_seeds``
times; the arbitrated controller runs every training (``<source>-s<k>``), the fixed-α one the
first (and only where ``reproduce.fixed_alpha_learned``: the default preset leaves the fixed-α
controller's learned cells out). The ``cooperative-damped`` controller (the arbitrated one with deceleration-gated
damping, :mod:`coassist.control.deceleration_damping`) runs the ``paths`` and ``oracle`` cells: the
lever's force, overshoot and jerk against the same sources without it.

A third set of cells, world ``held-out``, runs the point-mass world with operators of the
``held-out`` population (:mod:`coassist.scenario.populations`: detour families and arms nothing was
tuned to): MG and the arbitrated controller with :data:`HELD_OUT_SOURCES`, ``paths`` and ``person``
calibrated to those operators' own trials, the learned sources as trained (on the thesis population).

Per cell (world, object, controller, source): :func:`~coassist.experiments.application.application_metrics`,
and the **share of the oracle's benefit** for force and for overshoot::

    share = mean_i(MG_i − X_i) / mean_i(MG_i − oracle_i)

over the paired trials i, with a 95 % percentile bootstrap interval over trials
(:func:`~coassist.analysis.paired.gain_share`); the oracle of the same controller (the arbitrated one's for the damped
controller). 1 is everything the oracle gains over MG; 0 nothing; below 0 worse than MG.
Overshoot and clearance deficit are also given per side of the detour (the inside of the arc,
where the tool turns hardest, and the outside), each as a paired difference from MG.
"""

from __future__ import annotations

import os
import re
from collections.abc import Collection
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from coassist.analysis.paired import gain_share, paired_difference
from coassist.experiments.application import (
    OBJECTS,
    OBSTACLE,
    application_metrics,
    cell_options,
    pair_key,
)
from coassist.experiments.pipeline import EVAL_HORIZONS, Workspace, application_seed, in_loop_errors, trial_seed_base
from coassist.experiments.report import Claim, Section
from coassist.experiments.source_training import (
    APPLICATION_SOURCE,
    LEARNED,
    calibrate_paths,
    calibrate_person,
    calibration_options,
    seed_names,
)
from coassist.scenario.intent_registry import INTENT_FOLDERS, INTENT_SOURCES, Told

if TYPE_CHECKING:
    from coassist.scenario.person_intent import PersonFilterSettings

SOURCES = (
    "nominal",
    "constant-velocity",
    "present",
    "ridge",
    "ridge-intent",
    "lstm-tool",
    "lstm-hand-alone",
    "lstm-intent",
    "paths",
    "person",
    "oracle",
)
ARBITRATED = "cooperative-arbitrated"
DAMPED = "cooperative-damped"
CONTROLLERS = ("cooperative", ARBITRATED)
#: The damped controller's cells: the lever on the application's source and on the oracle.
DAMPED_SOURCES = ("paths", "oracle")
WORLDS = ("point-mass", "mujoco", "held-out")
#: The held-out population's cells (module docstring): the arbitrated controller with these sources.
HELD_OUT = "held-out"
HELD_OUT_SOURCES = ("nominal", "present", "lstm-intent", "paths", "person", "oracle")
#: The sources calibrated per operator (not trained): their folder is written per population.
CALIBRATED = ("paths", "person")
#: Issue 18's bar: a learned predictor in the loop gets this share of the oracle's benefit over MG.
ORACLE_SHARE_BAR = 0.8
#: Issue 34's bars for the application's source (arbitrated controller): shares of the oracle's force
#: saving and overshoot reduction, the bootstrap lower bound of the latter, and jerk against MG's.
FORCE_SHARE_BAR, OVERSHOOT_SHARE_BAR, SHARE_LOWER_BAR, JERK_BAR = 0.85, 0.60, 0.30, 1.2
#: Bootstrap resamples of the share's interval (seeded: the same run gives the same interval).
BOOTSTRAP = 2000
#: The sides of the detour (TrialMeta.extra["intent_side"]): +1 passes on the left of the path.
SIDES = {1: "left", -1: "right"}


def registered_sources() -> tuple[str, ...]:
    """The sources of :data:`~coassist.scenario.intent_registry.INTENT_SOURCES` whose entry asks for the
    ablation (``ablation=True``) besides :data:`SOURCES`, in the registry's order (read when called)."""
    return tuple(n for n, e in INTENT_SOURCES.items() if e.ablation and n not in SOURCES)


def run_sources(cfg) -> tuple[str, ...]:
    """This run's sources, in the tables' order: the named ones, ``paths`` and its learned ones, then
    the :func:`registered_sources`."""
    return tuple(s for s in SOURCES if s not in LEARNED or s in cfg.learned_sources) + registered_sources()


def mujoco_sources(cfg) -> tuple[str, ...]:
    """The sources of the MuJoCo UR5's cells (``reproduce.mujoco_sources``; empty: every source of the run)."""
    chosen = tuple(cfg.mujoco_sources)
    return tuple(s for s in run_sources(cfg) if not chosen or s in chosen)


def base_source(name: str) -> str:
    """The source of a cell's name: ``lstm-intent-s2`` → ``lstm-intent``."""
    return re.sub(r"-s\d+$", "", name)


def ablation_cells(cfg) -> list[tuple[str, str]]:
    """The (controller, source) cells of one object in the point-mass world (module docstring); the fixed-α
    controller runs the learned sources only where ``reproduce.fixed_alpha_learned`` says so."""
    cells = [
        (c, s)
        for c in CONTROLLERS
        for s in run_sources(cfg)
        if c == ARBITRATED or s not in LEARNED or cfg.fixed_alpha_learned
    ]
    cells += [
        (ARBITRATED, name) for s in run_sources(cfg) if s in LEARNED for name in seed_names(s, cfg.source_seeds)[1:]
    ]
    cells += [(DAMPED, s) for s in DAMPED_SOURCES]
    return cells


def _oracle_of(controller: str) -> str:
    """The controller whose oracle cell is a cell's reference (the damped one is measured against the arbitrated)."""
    return ARBITRATED if controller == DAMPED else controller


@dataclass(frozen=True)
class AblationResult:
    """metrics[(world, object, controller, source)] and mg[(world, object)]: :func:`application_metrics`;
    pairs[(world, object)]: the (operator, seed) of every trial, in the order all cells share;
    models: the learned sources' model folders (and ``paths``' calibration); skipped: world → why it
    did not run."""

    metrics: dict[tuple[str, str, str, str], dict[str, Any]]
    mg: dict[tuple[str, str], dict[str, Any]]
    pairs: dict[tuple[str, str], list[tuple[str, int]]]
    models: dict[str, str]
    skipped: dict[str, str]
    preset: str
    #: errors[(world, object, controller, source)][h] = {"tool": e_RMS against the measured future pose,
    #: "intent": against the operator's true intent} [m] of the predictions the loop used, h in samples.
    errors: dict[tuple[str, str, str, str], dict[int, dict[str, float]]]

    def shares(self, world: str, obj: str, controller: str, source: str) -> dict[str, tuple[float, float, float]]:
        """The share of the oracle's benefit for force and for overshoot (:func:`~coassist.analysis.paired.gain_share`
        of MG, the source and the oracle, :data:`BOOTSTRAP` resamples); each
        cell's bootstrap runs once (the summary, the section and the first screen all ask)."""
        key = (world, obj, controller, source)
        cache = self.__dict__.setdefault("_shares", {})  # frozen: the cache is not a field
        if key not in cache:
            cache[key] = self._shares_of(*key)
        return cache[key]

    def _shares_of(self, world: str, obj: str, controller: str, source: str) -> dict[str, tuple[float, float, float]]:
        mg = self.mg[(world, obj)]
        x = self.metrics[(world, obj, controller, source)]
        o = self.metrics[(world, obj, _oracle_of(controller), "oracle")]
        return {
            m: gain_share(mg[f"{m}_trials"], x[f"{m}_trials"], o[f"{m}_trials"], n_boot=BOOTSTRAP)
            for m in ("f_rms", "overshoot")
        }

    def by_side(
        self,
        world: str,
        obj: str,
        controller: str,
        source: str,
        metric: str,
    ) -> dict[int, tuple[float, float, float, float, int]]:
        """Per side of the detour (:data:`SIDES`): (mean, paired difference from MG, its 95 % low and high,
        trials) of ``metric`` ("overshoot" or "clearance_deficit") [m]."""
        x = self.metrics[(world, obj, controller, source)]
        mg = self.mg[(world, obj)]
        side = np.asarray(mg["side"])
        out = {}
        for s in SIDES:
            on = side == s
            a, b = np.asarray(x[f"{metric}_trials"], float)[on], np.asarray(mg[f"{metric}_trials"], float)[on]
            d, lo, hi, n = paired_difference(a, b)
            out[s] = (float(np.nanmean(a)) if n else float("nan"), d, lo, hi, n)
        return out

    def seeds_of(self, world: str, obj: str, controller: str, source: str) -> list[str]:
        """The cells of ``source``'s trainings that ran with ``controller`` (one unless the arbitrated LSTM)."""
        return sorted(
            (s for (w, o, c, s) in self.metrics if (w, o, c) == (world, obj, controller) and base_source(s) == source),
            key=lambda s: (s != source, s),
        )

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "preset": self.preset,
            "models": self.models,
            "skipped": self.skipped,
            "cells": {},
            "pairs": {f"{w}/{o}": p for (w, o), p in self.pairs.items()},
            "mg": {
                f"{w}/{o}": {k: v for k, v in m.items() if not k.endswith("_trials")} for (w, o), m in self.mg.items()
            },
        }
        for (world, obj, controller, source), r in self.metrics.items():
            sh = self.shares(world, obj, controller, source)
            out["cells"][f"{world}/{obj}/{controller}/{source}"] = {
                **{k: v for k, v in r.items() if not k.endswith("_trials")},
                "oracle_share_force": sh["f_rms"],
                "oracle_share_overshoot": sh["overshoot"],
                "by_side": {
                    SIDES[s]: {
                        m: dict(zip(("mean", "vs_mg", "low", "high", "trials"), v[s]))
                        for m, v in (
                            (m, self.by_side(world, obj, controller, source, m))
                            for m in ("overshoot", "clearance_deficit")
                        )
                    }
                    for s in SIDES
                },
                "prediction_errors": self.errors[(world, obj, controller, source)],
            }
        return out


def _intents(models: dict[str, str], names) -> dict[str, str]:
    """Cell source name → what the loop is given: its model folder, or the named source itself."""
    return {n: models.get(n, n) for n in names}


def _runnable(name: str, models: dict[str, str]) -> bool:
    return name in models or (base_source(name) not in LEARNED and name not in CALIBRATED)


def told_of(source: str) -> Told:
    """What a cell's source was told besides what an arm measures (:class:`~coassist.scenario.intent_registry.Told`)."""
    base = base_source(source)
    if base in INTENT_SOURCES:
        return INTENT_SOURCES[base].told
    if base == "person":
        return INTENT_FOLDERS["person-model"].told
    label = LEARNED[base][1] if base in LEARNED else ""
    return Told(
        label={
            "tool": "the tool's future pose",
            "intent": "the simulated operator's intent",
            "hand_alone": "the simulated hand-alone path",
        }.get(label, label)
    )


def run_ablation(
    ws: Workspace,
    models: dict[str, str],
    known: dict[tuple[str, str, str], list] | None = None,
) -> AblationResult:
    """Run every cell in both worlds with the learned sources' ``models`` (name → model folder,
    :func:`~coassist.experiments.source_training.train_sources`, and ``paths`` → its calibration).

    ``known``: (object, controller, source) → trials the application stage already ran with the
    same seeds, settings and model (its MG trials under ``(object, "manual", "nominal")`` and its
    assistive rows under the application's source); those cells reuse them instead of running
    them again. Without them every cell, MG's included, is collected here."""
    cfg = ws.config
    cells = ablation_cells(cfg)
    intents = _intents(models, {s for _, s in cells})
    known = known or {}
    metrics, mg, pairs, skipped, errors = {}, {}, {}, {}, {}
    for j, obj in enumerate(OBJECTS):

        def collect(name: str, controller: str, intent: str, j: int = j, obj: str = obj):
            _, ds = ws.collect(name, **cell_options(cfg, j, obj, controller, intent))
            return sorted(ds.trials, key=pair_key)

        base = known.get((obj, "manual", "nominal"))
        base = collect(f"ablation-{obj}-manual", "manual", "nominal") if base is None else sorted(base, key=pair_key)
        mg[("point-mass", obj)] = application_metrics(base)
        pairs[("point-mass", obj)] = [pair_key(t) for t in base]
        for controller, source in cells:
            trials = known.get((obj, controller, source))
            if trials is None:
                trials = collect(f"ablation-{obj}-{controller}-{source}", controller, intents[source])
            trials = sorted(trials, key=pair_key)
            if [pair_key(t) for t in trials] != pairs[("point-mass", obj)]:
                raise RuntimeError(f"ablation cell {obj}/{controller}/{source} did not meet MG's trials")
            metrics[("point-mass", obj, controller, source)] = application_metrics(trials)
            errors[("point-mass", obj, controller, source)] = prediction_errors_against_intent(trials)
    if cfg.held_out_trials > 0:
        _run_held_out(ws, intents, metrics, mg, pairs, errors)
    why = _mujoco_unavailable()
    if why is None and cfg.ablation_mujoco_trials > 0:
        _run_mujoco(ws, intents, metrics, mg, pairs, errors)
        models = {**models, **_mujoco_models(ws)}
    else:
        skipped["mujoco"] = why or "reproduce.ablation_mujoco_trials is 0"
    return AblationResult(metrics, mg, pairs, models, skipped, cfg.application_preset, errors)


def _mujoco_models(ws: Workspace) -> dict[str, str]:
    """The models the MuJoCo cells fitted themselves: the person model calibrated on the arm, where it ran."""
    cfg = ws.config
    if "person" in mujoco_sources(cfg) and cfg.mujoco_person_calibration == "mujoco":
        return {MUJOCO_PERSON: mujoco_intent(ws, "person", {})}
    return {}


def run_mujoco_ablation(ws: Workspace, models: dict[str, str]) -> AblationResult:
    """The MuJoCo UR5's cells alone (those :func:`run_ablation` runs there, with ``models`` as it is given
    them): to measure them without the main job (``benchmarks/bench_mujoco_cells.py``). Every source of
    ``reproduce.mujoco_sources`` that needs a model or a point-mass calibration must be in ``models``."""
    cfg = ws.config
    why = _mujoco_unavailable()
    if why is not None:
        raise RuntimeError(why)
    if cfg.ablation_mujoco_trials < 1:
        raise ValueError("run_mujoco_ablation: reproduce.ablation_mujoco_trials is 0, so there are no MuJoCo cells")
    intents = _intents(models, mujoco_sources(cfg))
    needed = [s for s in mujoco_sources(cfg) if not _runnable(s, models) and mujoco_intent(ws, s, intents) == s]
    if needed:
        raise ValueError(f"run_mujoco_ablation: models holds no model or calibration of {', '.join(needed)}")
    metrics: dict = {}
    mg: dict = {}
    pairs: dict = {}
    errors: dict = {}
    _run_mujoco(ws, intents, metrics, mg, pairs, errors)
    return AblationResult(metrics, mg, pairs, {**models, **_mujoco_models(ws)}, {}, cfg.application_preset, errors)


def held_out_models(ws: Workspace, intents: dict[str, str]) -> dict[str, str]:
    """The held-out cells' sources (:data:`HELD_OUT_SOURCES`): the calibrated ones fitted to the held-out
    population's operators (their own calibration trials), the others as the run has them."""
    out = {s: intents.get(s, s) for s in HELD_OUT_SOURCES if _runnable(s, intents) or s in CALIBRATED}
    out["paths"] = calibrate_paths(ws, population=HELD_OUT)
    out["person"] = calibrate_person(ws, population=HELD_OUT)
    return out


def _held_out_options(cfg, j: int, obj: str, controller: str, intent: str) -> dict[str, Any]:
    return {**cell_options(cfg, j, obj, controller, intent), "trials": cfg.held_out_trials, "population": HELD_OUT}


def _run_held_out(ws: Workspace, intents: dict[str, str], metrics: dict, mg: dict, pairs: dict, errors: dict) -> None:
    """The held-out population's cells (module docstring), paired against its own MG trials."""
    cfg = ws.config
    sources = held_out_models(ws, intents)
    # Every cell put on the pool at once (without one: deferred and run together), the same jobs as each
    # collect's: one cell, one lockstep group, would otherwise keep one process busy while the others wait.
    for j, obj in enumerate(OBJECTS):
        for source, intent in sources.items():
            ws.prefetch(f"held-out-{obj}-{source}", **_held_out_options(cfg, j, obj, ARBITRATED, intent))
    for j, obj in enumerate(OBJECTS):
        _, ds = ws.collect(f"held-out-{obj}-manual", **_held_out_options(cfg, j, obj, "manual", "nominal"))
        base = sorted(ds.trials, key=pair_key)
        mg[(HELD_OUT, obj)] = application_metrics(base)
        pairs[(HELD_OUT, obj)] = [pair_key(t) for t in base]
        for source, intent in sources.items():
            _, ds = ws.collect(f"held-out-{obj}-{source}", **_held_out_options(cfg, j, obj, ARBITRATED, intent))
            trials = sorted(ds.trials, key=pair_key)
            if [pair_key(t) for t in trials] != pairs[(HELD_OUT, obj)]:
                raise RuntimeError(f"held-out cell {obj}/{source} did not meet MG's trials")
            metrics[(HELD_OUT, obj, ARBITRATED, source)] = application_metrics(trials)
            errors[(HELD_OUT, obj, ARBITRATED, source)] = prediction_errors_against_intent(trials)


class AblationAhead:
    """Puts the ablation's simulations on the run's pool before the ablation stage asks for them.

    Called with the learned sources written so far (name → model folder; the application
    stage calls it while the sources train, :func:`~coassist.experiments.application.run_application`'s
    ``ahead``), it starts every cell whose source can run and has not started yet: the named
    sources' at the first call, each learned source's (and each training's) once it is written.
    The point-mass cells are prefetched datasets (:meth:`Workspace.prefetch`, the same options as
    :func:`run_ablation`'s collections: the same trials bit for bit), the MuJoCo UR5's one lockstep
    job per source (:meth:`Workspace.submit`). ``reused``: the (object, controller, source) cells the
    application stage collects and hands to :func:`run_ablation` as ``known``; not started here.
    """

    def __init__(self, ws: Workspace, reused: set[tuple[str, str, str]]) -> None:
        self.ws, self.reused = ws, set(reused)
        self.started: set[str] = set()
        cfg = ws.config
        self.mujoco = _mujoco_unavailable() is None and cfg.ablation_mujoco_trials > 0

    def __call__(self, models: dict[str, str], only: Collection[str] | None = None) -> None:
        """Start what ``models`` lets run and has not started; ``only``: of these sources (and
        :data:`MG_JOB`) alone, so that a caller can spread the work over its own idle spells."""
        cfg = self.ws.config
        cells = ablation_cells(cfg)
        intents = _intents(models, {s for _, s in cells})
        wanted = lambda key: only is None or key in only  # noqa: E731
        if MG_JOB not in self.started and wanted(MG_JOB):
            self.started.add(MG_JOB)
            for j, obj in enumerate(OBJECTS):
                if (obj, "manual", "nominal") not in self.reused:
                    self.ws.prefetch(f"ablation-{obj}-manual", **cell_options(cfg, j, obj, "manual", "nominal"))
            if self.mujoco:
                fn, args = mujoco_task(self.ws, MG_JOB, {})
                self.ws.submit(f"mujoco:{MG_JOB}", fn, *args)
            if cfg.held_out_trials > 0:  # the held-out operators' calibration trials and MG's cells
                for name, controller in (("calibration", "manual"), ("calibration-probe", "manual-probe")):
                    self.ws.prefetch(
                        f"{name}-{HELD_OUT}", **calibration_options(self.ws, controller, population=HELD_OUT)
                    )
                for j, obj in enumerate(OBJECTS):
                    self.ws.prefetch(f"held-out-{obj}-manual", **_held_out_options(cfg, j, obj, "manual", "nominal"))
        for controller, name in cells:
            key = f"{controller}/{name}"
            if key in self.started or not _runnable(name, models) or not wanted(base_source(name)):
                continue
            self.started.add(key)
            for j, obj in enumerate(OBJECTS):
                if (obj, controller, name) not in self.reused:
                    self.ws.prefetch(
                        f"ablation-{obj}-{controller}-{name}", **cell_options(cfg, j, obj, controller, intents[name])
                    )
        if self.mujoco:
            for source in mujoco_sources(cfg):
                key = f"mujoco:{source}"
                if key not in self.started and _runnable(source, models) and wanted(source):
                    self.started.add(key)
                    fn, args = mujoco_task(self.ws, source, intents)
                    self.ws.submit(key, fn, *args)


def prediction_errors_against_intent(trials, horizons=EVAL_HORIZONS) -> dict[int, dict[str, float]]:
    """e_RMS per horizon of the predictions the loop used, against the measured future pose
    ("tool", eq. 5.6) and against the operator's true intent ("intent"), pooled over the
    trials' scored ticks [m] (:func:`~coassist.experiments.pipeline.in_loop_errors`)."""
    trials = [t for t in trials if t.intent is not None]  # both columns over the same ticks
    tool, intent = (in_loop_errors(trials, horizons, against=a) for a in ("pose", "intent"))
    return {int(h): {"tool": tool[h]["e_rms"], "intent": intent[h]["e_rms"]} for h in tool}


def _mujoco_unavailable() -> str | None:
    """Why the MuJoCo UR5 cannot run here (None when it can): the robot extra is optional."""
    try:
        import mujoco  # noqa: F401
        import pinocchio  # noqa: F401
    except ImportError as exc:
        return f"the MuJoCo UR5 needs the robot extra (pip install coassist[robot]): {exc}"
    return None


def _mujoco_configs(cfg, obj: str, seed0: int, controller: str, intent: str) -> list:
    from coassist.robot.drive import DriveConfig
    from coassist.sim.collect import dataset_specs

    # The first trials of each operator in the point-mass cells (the same seeds: the same task and intent draws).
    specs = dataset_specs(
        controller=controller,
        users=cfg.application_users,
        tasks=(cfg.application_task,),
        objects=(obj,),
        trials=cfg.application_trials,
        seed=seed0,
        preset=cfg.application_preset,
        obstacle=OBSTACLE,
    )
    return [
        DriveConfig(
            world="mujoco",
            controller=controller,
            task=s.task,
            object=obj,
            preset=s.preset,
            intent=intent,
            user=s.user,
            seed=s.seed,
            obstacle=s.obstacle,
        )
        for n, s in enumerate(specs)
        if n % cfg.application_trials < cfg.ablation_mujoco_trials
    ]


def probe_configs(cfg) -> list:
    """The person model's calibration trials on the MuJoCo UR5 (``reproduce.mujoco_person_calibration`` =
    "mujoco"): what :func:`~coassist.experiments.source_training.calibration_options` collects in the
    point-mass world (MG with the probe, the handle, the application's task and obstacle, ``calibration_trials``
    per application operator, the same trial seeds: the same task and intent draws), driven on the arm."""
    from coassist.experiments.pipeline import calibration_seed
    from coassist.robot.drive import DriveConfig
    from coassist.sim.collect import dataset_specs

    specs = dataset_specs(
        controller="manual-probe",
        users=cfg.application_users,
        tasks=(cfg.application_task,),
        objects=("handle",),
        trials=cfg.calibration_trials,
        seed=calibration_seed(trial_seed_base(cfg.seed)),
        preset=cfg.application_preset,
        obstacle=OBSTACLE,
    )
    return [
        DriveConfig(
            world="mujoco",
            controller="manual-probe",
            task=s.task,
            object="handle",
            preset=s.preset,
            intent="nominal",
            user=s.user,
            seed=s.seed,
            obstacle=s.obstacle,
        )
        for s in specs
    ]


def mujoco_person_filter() -> PersonFilterSettings:
    """The online filter of the person model calibrated on the MuJoCo UR5: the point-mass world's
    (:data:`~coassist.scenario.person_model.PERSON_FILTER`) told no yaw mode (``object_yaw`` off). The MuJoCo
    UR5 holds every object rigidly (:mod:`coassist.robot.ur5_mjcf`: the cup's torsion is not modelled), so
    there the hand moves with the tip; a lab tells the source its own object's mount the same way."""
    from dataclasses import replace

    from coassist.scenario.person_model import PERSON_FILTER

    return replace(PERSON_FILTER, object_yaw=False)


def calibrate_then_drive(probes: list, folder: str, configs: list) -> list[tuple[dict, dict]]:
    """A worker's MuJoCo person-model job: drive the calibration trials ``probes`` (:func:`probe_configs`), fit
    each operator's person model (:func:`~coassist.scenario.person_model.fit_person`, as
    :func:`~coassist.experiments.source_training.calibrate_person` does on the point-mass world's), write them
    into ``folder`` (the intent of ``configs``) with :func:`mujoco_person_filter`, then drive ``configs`` as
    :func:`_drive_batch` does. One job: the cells wait for their own calibration and for nothing else."""
    import torch

    from coassist.robot.drive import drive_lockstep
    from coassist.scenario.person_model import fit_person, write_person_model

    torch.set_num_threads(1)
    by_user: dict[str, list] = {}
    for trial in drive_lockstep(probes):
        by_user.setdefault(str(trial.meta.user), []).append(trial)
    fits = {user: fit_person(trials) for user, trials in sorted(by_user.items())}
    write_person_model(folder, fits, settings=mujoco_person_filter())
    return _drive_batch(configs)


def _drive_batch(configs: list) -> list[tuple[dict, dict]]:
    """A worker's MuJoCo runs, in lockstep (one network call per tick for those sharing a model;
    spawned process, one torch thread like the simulator's workers)."""
    import torch

    from coassist.robot.drive import drive_lockstep
    from coassist.sim.pool import trial_payload

    torch.set_num_threads(1)
    return [trial_payload(t) for t in drive_lockstep(configs)]


#: The MuJoCo job of MG's trials (its cells have no intent source).
MG_JOB = "nominal-mg"


def _mujoco_cells(cfg, source: str, intent: str) -> list[tuple[tuple[str, str, str], list]]:
    """The MuJoCo cells of one job: per object, (object, controller, source) and its drive configs: MG's
    for :data:`MG_JOB`, else the arbitrated controller with ``source`` (its first training)."""
    controller = "manual" if source == MG_JOB else ARBITRATED
    name = "nominal" if source == MG_JOB else source
    return [
        (
            (obj, controller, name),
            _mujoco_configs(cfg, obj, application_seed(trial_seed_base(cfg.seed), j), controller, intent),
        )
        for j, obj in enumerate(OBJECTS)
    ]


def _mujoco_job(cfg, source: str, intent: str) -> list:
    return [c for _, configs in _mujoco_cells(cfg, source, intent) for c in configs]


#: The MuJoCo UR5's person model when it is calibrated there (``reproduce.mujoco_person_calibration``): its folder
#: under the run's ``models``.
MUJOCO_PERSON = "person-mujoco"


def mujoco_intent(ws: Workspace, source: str, intents: dict[str, str]) -> str:
    """What a MuJoCo job's loop is given: MG's plan, the person model calibrated on the MuJoCo UR5
    (``models/person-mujoco``, written by its own job) unless ``reproduce.mujoco_person_calibration`` says
    "point-mass" (the point-mass cells' model), else what the point-mass cells are given."""
    if source == MG_JOB:
        return "nominal"
    if source == "person" and ws.config.mujoco_person_calibration == "mujoco":
        return str(ws.out / "models" / MUJOCO_PERSON)
    return intents[source]


def mujoco_task(ws: Workspace, source: str, intents: dict[str, str]) -> tuple[Any, tuple]:
    """A MuJoCo job as (function, arguments) for a pool: :func:`_drive_batch` of its cells, or for the person
    model calibrated on the arm :func:`calibrate_then_drive` (its calibration trials first, in the same job)."""
    intent = mujoco_intent(ws, source, intents)
    configs = _mujoco_job(ws.config, source, intent)
    if source == "person" and ws.config.mujoco_person_calibration == "mujoco":
        return calibrate_then_drive, (probe_configs(ws.config), intent, configs)
    return _drive_batch, (configs,)


def _mujoco_jobs(ws: Workspace, intents: dict[str, str]) -> dict[str, list[tuple[tuple[str, str, str], list]]]:
    """One job per intent source of the run (and MG's, :data:`MG_JOB`): its cells, which run in lockstep
    in one worker, so a model in the loop is called once per tick for all of them."""
    return {
        source: _mujoco_cells(ws.config, source, mujoco_intent(ws, source, intents))
        for source in (MG_JOB, *mujoco_sources(ws.config))
    }


def _run_mujoco(ws: Workspace, intents: dict[str, str], metrics: dict, mg: dict, pairs: dict, errors: dict) -> None:
    """The arbitrated cells on the MuJoCo UR5 (fewer trials: ``ablation_mujoco_trials`` per operator)."""
    import contextlib

    from coassist.sim.pool import trial_from_payload
    from coassist.sim.world import worker_pool

    cfg = ws.config
    jobs = _mujoco_jobs(ws, intents)
    workers = max(1, min(cfg.workers, os.cpu_count() or 1))
    # the run's simulation processes where it has them (started once), else a pool for these runs
    with contextlib.nullcontext(ws.pool) if ws.pool is not None else worker_pool(workers) as pool:
        # a job AblationAhead started is taken, not run again
        futures = []
        for source, cells in jobs.items():
            future = ws.take(f"mujoco:{source}")
            if future is None:
                fn, args = mujoco_task(ws, source, intents)
                future = pool.submit(fn, *args)
            futures.append((cells, future))
        done = []
        for cells, fut in futures:
            runs = iter(fut.result())
            for key, configs in cells:
                done.append((key, [next(runs) for _ in configs]))
        for (obj, controller, source), payloads in done:
            trials = [trial_from_payload(p) for p in payloads]
            trials = sorted(trials, key=pair_key)
            if controller == "manual":
                mg[("mujoco", obj)] = application_metrics(trials)
                pairs[("mujoco", obj)] = [pair_key(t) for t in trials]
                continue
            if [pair_key(t) for t in trials] != pairs[("mujoco", obj)]:
                raise RuntimeError(f"ablation cell mujoco/{obj}/{controller}/{source} did not meet MG's trials")
            metrics[("mujoco", obj, controller, source)] = application_metrics(trials)
            errors[("mujoco", obj, controller, source)] = prediction_errors_against_intent(trials)


def share_text(s: tuple[float, float, float]) -> str:
    """A (share, low, high) as the report writes it: percent with its interval, or n/a."""
    share, lo, hi = s
    if not np.isfinite(share):
        return "n/a"
    bracket = f" [{100 * lo:.0f}, {100 * hi:.0f}]" if np.isfinite(lo) else ""
    return f"{100 * share:.0f} %{bracket}"


def seeds_text(result: AblationResult, world: str, obj: str, controller: str, source: str, metric: str) -> str:
    """The share over a source's trainings: the first one's with its interval, and each other seed's."""
    names = result.seeds_of(world, obj, controller, source)
    first = share_text(result.shares(world, obj, controller, names[0])[metric])
    if len(names) == 1:
        return first
    others = [result.shares(world, obj, controller, n)[metric][0] for n in names]
    return f"{first}; seeds {', '.join(f'{100 * v:.0f}' for v in others)} %"


def _side_text(v: tuple[float, float, float, float, int]) -> str:
    mean, d, lo, hi, n = v
    if not n:
        return "—"
    return (
        f"{1e3 * mean:.1f} ({1e3 * d:+.1f} [{1e3 * lo:+.1f}, {1e3 * hi:+.1f}])"
        if np.isfinite(lo)
        else f"{1e3 * mean:.1f}"
    )


#: The first screen's rows: (label, controller, source); the LSTM's and the ridge's as the previous
#: application source and its simplest rival, the application's, and the oracle.
HEADLINE = (
    ("nominal plan", ARBITRATED, "nominal"),
    ("LSTM+FC, intent label", ARBITRATED, "lstm-intent"),
    ("ridge, intent label", ARBITRATED, "ridge-intent"),
    ("present estimate", ARBITRATED, "present"),
    ("path hypotheses", ARBITRATED, "paths"),
    ("path hypotheses + deceleration damping", DAMPED, "paths"),
    ("person model (learnt from probe trials)", ARBITRATED, "person"),
    ("oracle (true intent)", ARBITRATED, "oracle"),
)


def headline_rows(result: AblationResult, world: str = "point-mass") -> tuple[str, list[str], list[list[Any]]]:
    """The report's first-screen table (issue 34): per object, MG and each headline source with the
    arbitrated controller: f_RMS and its share of the oracle's saving, overshoot past the intent per side
    of the detour and its share, the clearance deficit per side, jerk and σ."""
    rows = []
    for obj in OBJECTS:
        if (world, obj) not in result.mg:
            continue
        m = result.mg[(world, obj)]
        side = np.asarray(m["side"])

        def sided(values, side: np.ndarray = side) -> str:
            v = np.asarray(values, float)
            return " / ".join(f"{1e3 * np.nanmean(v[side == s]):.1f}" if (side == s).any() else "—" for s in SIDES)

        rows.append(
            [
                obj,
                "MG",
                f"{m['f_rms']:.2f}",
                "",
                sided(m["overshoot_trials"]),
                "",
                sided(m["clearance_deficit_trials"]),
                f"{m['jerk_rms']:.2f}",
                f"{1e3 * m['sigma']:.2f}",
                "",
            ]
        )
        for label, controller, source in HEADLINE:
            if (world, obj, controller, source) not in result.metrics:
                continue
            r = result.metrics[(world, obj, controller, source)]
            default = " (the application's)" if source == APPLICATION_SOURCE and controller == ARBITRATED else ""
            rows.append(
                [
                    obj,
                    label + default,
                    f"{r['f_rms']:.2f}",
                    seeds_text(result, world, obj, controller, source, "f_rms"),
                    sided(r["overshoot_trials"]),
                    seeds_text(result, world, obj, controller, source, "overshoot"),
                    sided(r["clearance_deficit_trials"]),
                    f"{r['jerk_rms']:.2f} ({r['jerk_rms'] / m['jerk_rms']:.2f}× MG)",
                    f"{1e3 * r['sigma']:.2f}",
                    told_of(source).text(),
                ]
            )
    n = len(result.pairs.get((world, OBJECTS[0]), ()))
    who = (
        "the held-out population: operators whose detour families and arms nothing was tuned to, point-mass world"
        if world == HELD_OUT
        else "the MuJoCo UR5: each operator's first trials of the point-mass world, driven on the arm"
        if world == "mujoco"
        else f"{world} world"
    )
    caption = (
        f"Precision at the person's turns ({who}, arbitrated controller, {n} paired trials per object; "
        "shares of the oracle's benefit over MG with their 95 % bootstrap interval, and each training seed's for "
        "a learned source; left / right: the detour's side, right being the inside of the arc)"
    )
    header = [
        "object",
        "intent source",
        "f_RMS [N]",
        "force: share of oracle's saving",
        "overshoot left / right [mm]",
        "overshoot: share of oracle's reduction",
        "clearance deficit left / right [mm]",
        "jerk RMS [m/s³]",
        "σ [mm]",
        "told (besides what an arm measures)",
    ]
    return caption, header, rows


def ablation_section(result: AblationResult) -> Section:
    """The report's ablation section: every cell of both worlds, and the claims of issues 18 and 34."""
    s = Section("6. Which intent makes assistance better? The in-loop ablation (issues 18, 34)")
    s.paragraphs.append(
        "Each intent source drives the fixed-α and the arbitrated assistive controller (preset "
        f"'{result.preset}') on the application's trials, paired against MG on the same trials. The learned sources are "
        "trained from scratch on the same datasets by the same protocol; only what they learn to predict differs: the "
        "tool's future pose (the thesis) or the simulated operator's true intent; each LSTM is trained with several seeds "
        "(the arbitrated controller runs every one). 'present' estimates where the operator wants the tool now from the "
        "hand force; 'paths' adds path hypotheses round the obstacle the robot is told of, fitted to each operator's "
        "calibration trials. 'cooperative-damped' is the arbitrated controller with damping while the tool slows down. "
        "Share of the oracle's benefit = mean(MG − X) / mean(MG − oracle) over paired trials, with a 95 % bootstrap "
        "interval. Overshoot and clearance deficit (how much closer to the obstacle the tool passed than the operator "
        "meant) per side of the detour, as paired differences from MG with their 95 % intervals."
    )
    for world, why in result.skipped.items():
        s.paragraphs.append(f"The {world} world did not run: {why}.")
    if MUJOCO_PERSON in result.models:
        s.paragraphs.append(
            "On the MuJoCo UR5 the person model is calibrated on the arm it assists: each operator's probe trials "
            "(the point-mass cells' calibration trials, the same seeds) are driven there and fitted as in the "
            "point-mass world (reproduce.mujoco_person_calibration)."
        )
    for world in WORLDS:
        rows = []
        for obj in OBJECTS:
            if (world, obj) not in result.mg:
                continue
            m = result.mg[(world, obj)]
            rows.append(
                [
                    obj,
                    "—",
                    "MG",
                    f"{m['f_rms']:.2f}",
                    f"{m['sigma'] * 1e3:.2f}",
                    f"{m['overshoot'] * 1e3:.1f}",
                    "",
                    "",
                    "",
                    "",
                    f"{m['jerk_rms']:.2f}",
                    f"{m['peak_effort_ratio']:.2f}",
                    "",
                    "",
                ]
            )
            for (w, ob, controller, source), r in result.metrics.items():
                if (w, ob) != (world, obj):
                    continue
                sh = result.shares(world, obj, controller, source)
                d, lo, hi, _ = paired_difference(r["overshoot_trials"], m["overshoot_trials"])
                os_side = result.by_side(world, obj, controller, source, "overshoot")
                cd_side = result.by_side(world, obj, controller, source, "clearance_deficit")
                rows.append(
                    [
                        obj,
                        controller,
                        source,
                        f"{r['f_rms']:.2f}",
                        f"{r['sigma'] * 1e3:.2f}",
                        f"{r['overshoot'] * 1e3:.1f} ({d * 1e3:+.1f} [{lo * 1e3:+.1f}, {hi * 1e3:+.1f}])",
                        _side_text(os_side[1]),
                        _side_text(os_side[-1]),
                        _side_text(cd_side[1]),
                        _side_text(cd_side[-1]),
                        f"{r['jerk_rms']:.2f}",
                        f"{r['peak_effort_ratio']:.2f}",
                        share_text(sh["f_rms"]),
                        share_text(sh["overshoot"]),
                    ]
                )
        if rows:
            n = len(result.pairs[(world, OBJECTS[0])])
            s.tables.append(
                (
                    f"{world} world, {n} paired trials per cell: f_RMS [N], σ [mm], overshoot past the intent [mm] (paired "
                    "difference from MG, 95 % interval), the same per side of the detour, the clearance deficit per side [mm], "
                    "jerk RMS [m/s³], peak robot/hand effort, share of the oracle's benefit",
                    [
                        "object",
                        "controller",
                        "intent source",
                        "f_RMS",
                        "σ",
                        "overshoot",
                        "overshoot, left",
                        "overshoot, right",
                        "clearance deficit, left",
                        "clearance deficit, right",
                        "jerk RMS",
                        "peak |u_r|/|u_h|",
                        "oracle share: force",
                        "oracle share: overshoot",
                    ],
                    rows,
                )
            )
    rows = []
    for (world, obj, controller, source), e in result.errors.items():
        if world == "point-mass" and controller == ARBITRATED:
            rows.append(
                [source, obj]
                + [f"{1e3 * e[h]['tool']:.2f} / {1e3 * e[h]['intent']:.2f}" if h in e else "—" for h in EVAL_HORIZONS]
            )
    s.tables.append(
        (
            "What each source predicted in the loop (point-mass world, arbitrated controller): e_RMS [mm] against the tool's "
            "measured future pose / against the operator's true intent, per horizon",
            ["intent source", "object"] + [f"{h} samples" for h in EVAL_HORIZONS],
            rows,
        )
    )
    for obj in OBJECTS:
        for source in ("lstm-tool", "lstm-hand-alone", "lstm-intent"):
            key = ("point-mass", obj, ARBITRATED, source)
            if key not in result.metrics:
                continue
            sh = result.shares(*key)
            f, o = sh["f_rms"][0], sh["overshoot"][0]
            s.claims.append(
                Claim(
                    f"{obj}: the arbitrated controller with {source} in the loop gets ≥ {100 * ORACLE_SHARE_BAR:.0f} % of the "
                    "oracle's force saving and of its overshoot reduction over MG (issue 18's bar; point-mass world)",
                    bool(np.isfinite(f) and np.isfinite(o) and f >= ORACLE_SHARE_BAR and o >= ORACLE_SHARE_BAR),
                    f"force {share_text(sh['f_rms'])}, overshoot {share_text(sh['overshoot'])} of the oracle's benefit",
                    reason="a network on the hand force learns where the tool goes, not where the person wants it now: at a "
                    "turn it runs past it (docs/precision.md)",
                )
            )
    s.claims.extend(precision_claims(result))
    s.claims.extend(person_claims(result))
    return s


#: Issue 40's bars for the person model (arbitrated controller): (force share, overshoot share, its lower
#: bound, jerk against MG's) in the population it was developed on, and on the held-out population.
PERSON_BARS = {"point-mass": (0.85, 0.70, 0.40, 1.1), HELD_OUT: (0.80, 0.60, 0.30, None)}


def person_claims(result: AblationResult, source: str = "person") -> list[Claim]:
    """Issue 40's goals for the person model, per object, in the point-mass world and on the held-out
    population (where its cells ran): shares of the oracle's benefit, jerk, and per side no more
    overshoot than MG on the held-out population; then the MuJoCo UR5's direction (:func:`mujoco_person_claims`)."""
    claims = []
    for world, (force_bar, over_bar, lower_bar, jerk_bar) in PERSON_BARS.items():
        for obj in OBJECTS:
            key = (world, obj, ARBITRATED, source)
            if key not in result.metrics:
                continue
            sh = result.shares(*key)
            (f, _, _), (o, o_lo, _) = sh["f_rms"], sh["overshoot"]
            r, m = result.metrics[key], result.mg[(world, obj)]
            where = "held-out population" if world == HELD_OUT else f"{world} world"
            ok = all(np.isfinite(v) for v in (f, o, o_lo)) and f >= force_bar and o >= over_bar and o_lo >= lower_bar
            jerk = r["jerk_rms"] / m["jerk_rms"]
            text = f"force {share_text(sh['f_rms'])}, overshoot {share_text(sh['overshoot'])}; jerk {jerk:.2f}× MG"
            goal = (
                f"{obj}, {where}: the person model (learnt from each operator's probe trials, told no scene, family or "
                f"label) gets ≥ {100 * force_bar:.0f} % of the oracle's force saving and ≥ {100 * over_bar:.0f} % of its "
                f"overshoot reduction (lower bound ≥ {100 * lower_bar:.0f} %)"
            )
            if jerk_bar is not None:
                goal += f", jerk ≤ {jerk_bar:g} × MG's"
                ok = ok and jerk <= jerk_bar
            else:
                sides = result.by_side(*key, "overshoot")
                goal += ", and overshoots no more than MG on either side"
                ok = ok and all(n >= 1 and np.isfinite(d) and d <= 0.0 for _, d, _, _, n in sides.values())
                text += "; " + "; ".join(f"{SIDES[sd]} {_side_text(v)} mm vs MG" for sd, v in sides.items())
            claims.append(
                Claim(
                    goal + " (issue 40)",
                    bool(ok),
                    text,
                    reason="the way round is known only once the person has left the plan by more than the filter's "
                    "dead zone, and the rows follow the person's own scatter of shapes (docs/precision.md)",
                )
            )
    return claims + mujoco_person_claims(result, source)


def mujoco_person_claims(result: AblationResult, source: str = "person") -> list[Claim]:
    """Issue 40's goal on the MuJoCo UR5, per object where its cells ran: the point-mass world's direction
    with an interval. The person model needs less hand force and overshoots less than MG on the same trials,
    each paired difference's 95 % upper bound below zero (:func:`~coassist.analysis.paired.paired_difference`);
    the evidence gives the shares of the oracle's benefit with their bootstrap intervals and the jerk."""
    claims = []
    for obj in OBJECTS:
        key = ("mujoco", obj, ARBITRATED, source)
        if key not in result.metrics:
            continue
        r, m = result.metrics[key], result.mg[("mujoco", obj)]
        sh = result.shares(*key)
        ok, parts = True, []
        for metric, unit, scale in (("f_rms", "N", 1.0), ("overshoot", "mm", 1e3)):
            d, lo, hi, n = paired_difference(r[f"{metric}_trials"], m[f"{metric}_trials"])
            ok = ok and bool(np.isfinite(hi) and hi < 0.0)
            what = "force" if metric == "f_rms" else "overshoot"
            # below two pairs there is no interval: the difference alone, and the claim does not hold
            interval = f" [{scale * lo:+.2f}, {scale * hi:+.2f}]" if np.isfinite(lo) else ", no interval"
            parts.append(
                f"{what} {share_text(sh[metric])} of the oracle's benefit, {scale * r[metric]:.2f} vs MG "
                f"{scale * m[metric]:.2f} {unit} ({scale * d:+.2f}{interval})"
            )
        parts.append(f"jerk {r['jerk_rms'] / m['jerk_rms']:.2f}× MG; {len(r['f_rms_trials'])} paired trials")
        claims.append(
            Claim(
                f"{obj}, MuJoCo UR5: the person model (calibrated from each operator's probe trials) needs less hand "
                "force and overshoots less than MG on the same trials, each paired difference's 95 % upper bound "
                "below zero (the point-mass world's direction, with an interval; issue 40)",
                ok,
                "; ".join(parts),
                reason="the arm's joint limits and the safety layer's filters delay the robot's effort, and fewer "
                "trials run on the arm than in the point-mass world",
            )
        )
    return claims


def precision_claims(result: AblationResult, source: str = APPLICATION_SOURCE) -> list[Claim]:
    """Issue 34's goals for ``source`` with the arbitrated controller in the point-mass world, per object
    (and the direction in the MuJoCo UR5's cells when they ran)."""
    claims = []
    for obj in OBJECTS:
        key = ("point-mass", obj, ARBITRATED, source)
        if key not in result.metrics:
            continue
        sh = result.shares(*key)
        (f, _, _), (o, o_lo, _) = sh["f_rms"], sh["overshoot"]
        claims.append(
            Claim(
                f"{obj}: with '{source}' the arbitrated controller gets ≥ {100 * FORCE_SHARE_BAR:.0f} % of the oracle's force "
                f"saving and ≥ {100 * OVERSHOOT_SHARE_BAR:.0f} % of its overshoot reduction over MG, the latter's bootstrap "
                f"lower bound ≥ {100 * SHARE_LOWER_BAR:.0f} % (issue 34)",
                bool(
                    np.isfinite(f)
                    and np.isfinite(o)
                    and np.isfinite(o_lo)
                    and f >= FORCE_SHARE_BAR
                    and o >= OVERSHOOT_SHARE_BAR
                    and o_lo >= SHARE_LOWER_BAR
                ),
                f"force {share_text(sh['f_rms'])}, overshoot {share_text(sh['overshoot'])} of the oracle's benefit",
                reason="the side of the detour is known only some 0.1 s after it starts, and the person's shape varies from "
                "trial to trial: the robot follows the present estimate meanwhile",
            )
        )
        for metric, what in (
            ("overshoot", "overshoots the intent"),
            ("clearance_deficit", "passes closer to the obstacle"),
        ):
            sides = result.by_side(*key, metric)
            ok = all(n >= 2 and np.isfinite(hi) and hi <= 0.0 for _, _, _, hi, n in sides.values())
            claims.append(
                Claim(
                    f"{obj}: with '{source}' the arbitrated controller {what} no more than MG on either side of the detour "
                    "(paired difference's 95 % upper bound ≤ 0; issue 34)",
                    bool(ok),
                    "; ".join(f"{SIDES[sd]} {_side_text(v)} mm vs MG" for sd, v in sides.items()),
                    reason="MG's heavy tool swings wide of the obstacle at the outside turn; a controller that follows the "
                    "intent closely passes nearer to it than MG does (the oracle too)"
                    if metric == "clearance_deficit"
                    else "where the side is decided late, the tool follows the old direction for a moment",
                )
            )
        r, m = result.metrics[key], result.mg[("point-mass", obj)]
        claims.append(
            Claim(
                f"{obj}: with '{source}' the arbitrated controller's jerk RMS is ≤ {JERK_BAR:g} × MG's (issue 34)",
                bool(r["jerk_rms"] <= JERK_BAR * m["jerk_rms"]),
                f"jerk RMS {r['jerk_rms']:.2f} vs MG {m['jerk_rms']:.2f} m/s³ ({r['jerk_rms'] / m['jerk_rms']:.2f}×)",
                reason="the rows change when the filter decides the side or the shape: the robot's effort changes with them",
            )
        )
    if all(("mujoco", obj, ARBITRATED, source) in result.metrics for obj in OBJECTS):
        parts, ok = [], True
        for obj in OBJECTS:
            r, m = result.metrics[("mujoco", obj, ARBITRATED, source)], result.mg[("mujoco", obj)]
            ok &= bool(r["f_rms"] < m["f_rms"] and r["overshoot"] <= m["overshoot"])
            parts.append(
                f"{obj}: f_RMS {r['f_rms']:.2f} vs MG {m['f_rms']:.2f} N, overshoot {1e3 * r['overshoot']:.1f} vs "
                f"MG {1e3 * m['overshoot']:.1f} mm"
            )
        claims.append(
            Claim(
                f"on the MuJoCo UR5, '{source}' with the arbitrated controller needs less force than MG and overshoots no more, "
                "on both objects (the point-mass result's direction; issue 34)",
                ok,
                "; ".join(parts),
                reason="the arm's joint limits and the safety layer's filters delay the robot's effort, and few trials run there",
            )
        )
    return claims
