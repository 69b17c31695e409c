"""The in-loop ablation of intent sources (issues 18, 34): which prediction makes assistance better?

Every intent source drives the same assistive controllers on the same trials of the
application scenario (the report's seeds, :func:`~coassist.experiments.seed_plan.application_seed`),
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
  :data:`~coassist.scenario.intent_registry.INTENT_SOURCES`
  (:func:`~coassist.experiments.ablation_cells.registered_sources`; none by default).

Every learned source is trained from scratch on the same datasets by the same protocol; only
the label differs, and the ridge's model class. Each LSTM source is trained ``source_seeds``
times; the arbitrated controller runs every training (``<source>-s<k>``), the fixed-α one the
first (and only where ``reproduce.fixed_alpha_learned``: the default preset leaves the fixed-α
controller's learned cells out). The ``cooperative-damped`` controller (the arbitrated one with deceleration-gated
damping, :mod:`coassist.control.deceleration_damping`) runs the ``paths`` and ``oracle`` cells: the
lever's force, overshoot and jerk against the same sources without it.

A third set of cells, world ``held-out``, runs the point-mass world with operators of the
``held-out`` population (:mod:`coassist.scenario.populations`: detour families and arms nothing was
tuned to): MG and the arbitrated controller with
:data:`~coassist.experiments.ablation_cells.HELD_OUT_SOURCES`, ``paths`` and ``person`` calibrated to
those operators' own trials, the learned sources as trained (on the thesis population).

Per cell (world, object, controller, source): :func:`~coassist.experiments.application.application_metrics`,
and the **share of the oracle's benefit** for force and for overshoot::

    share = mean_i(MG_i − X_i) / mean_i(MG_i − oracle_i)

over the paired trials i, with a 95 % percentile bootstrap interval over trials
(:func:`~coassist.analysis.paired.gain_share`); the oracle of the same controller (the arbitrated one's for the damped
controller). 1 is everything the oracle gains over MG; 0 nothing; below 0 worse than MG.
Overshoot and clearance deficit are also given per side of the detour (the inside of the arc,
where the tool turns hardest, and the outside), each as a paired difference from MG.

This module runs the cells; what the cells are (sources, controllers, worlds, the issues' bars) and
the :class:`~coassist.experiments.ablation_cells.AblationResult` that computes their statistics are
:mod:`coassist.experiments.ablation_cells`; the report's tables, first-screen rows and claims are
written from an ``AblationResult`` by :mod:`coassist.experiments.ablation_report`.
"""

from __future__ import annotations

import os
from collections.abc import Collection
from pathlib import Path
from typing import TYPE_CHECKING, Any

from coassist.experiments.ablation_cells import (
    ARBITRATED,
    CALIBRATED,
    HELD_OUT,
    HELD_OUT_SOURCES,
    AblationResult,
    ablation_cells,
    base_source,
    mujoco_sources,
)
from coassist.experiments.application import (
    OBJECTS,
    OBSTACLE,
    application_metrics,
    cell_options,
    pair_key,
)
from coassist.experiments.pipeline import EVAL_HORIZONS, Workspace, in_loop_errors
from coassist.experiments.seed_plan import application_seed, trial_seed_base
from coassist.experiments.source_training import (
    LEARNED,
    calibrate_paths,
    calibrate_person,
    calibration_draw_options,
    calibration_options,
    population_options,
)
from coassist.robot.worlds import POINT_MASS
from coassist.scenario.calibration_draws import draw_clusters, draw_count

if TYPE_CHECKING:
    from coassist.scenario.person_intent import PersonFilterSettings


def _intents(models: dict[str, str], names) -> dict[str, str]:
    """Cell source name → what the loop is given: its model folder, or the named source itself."""
    return {n: models.get(n, n) for n in names}


def _runnable(name: str, models: dict[str, str]) -> bool:
    return name in models or (base_source(name) not in LEARNED and name not in CALIBRATED)


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
        mg[(POINT_MASS, obj)] = application_metrics(base)
        pairs[(POINT_MASS, obj)] = [pair_key(t) for t in base]
        for controller, source in cells:
            trials = known.get((obj, controller, source))
            if trials is None:
                trials = collect(f"ablation-{obj}-{controller}-{source}", controller, intents[source])
            trials = sorted(trials, key=pair_key)
            if [pair_key(t) for t in trials] != pairs[(POINT_MASS, obj)]:
                raise RuntimeError(f"ablation cell {obj}/{controller}/{source} did not meet MG's trials")
            metrics[(POINT_MASS, obj, controller, source)] = application_metrics(trials)
            errors[(POINT_MASS, obj, controller, source)] = prediction_errors_against_intent(trials)
    world_intents = {POINT_MASS: intents}
    if cfg.held_out_trials > 0:
        world_intents[HELD_OUT] = _run_held_out(ws, intents, metrics, mg, pairs, errors)
        models = {**models, HELD_OUT_PERSON: world_intents[HELD_OUT]["person"]}  # its calibrations, for the report
    why = _mujoco_unavailable()
    if why is None and cfg.ablation_mujoco_trials > 0:
        _run_mujoco(ws, intents, metrics, mg, pairs, errors)
        models = {**models, **_mujoco_models(ws)}
        if "person" in mujoco_sources(cfg):  # its calibration draws, on the arm or the point-mass world's
            world_intents["mujoco"] = {"person": mujoco_intent(ws, "person", intents)}
    else:
        skipped["mujoco"] = why or "reproduce.ablation_mujoco_trials is 0"
    clusters = draw_clusters_of(world_intents, metrics, pairs)
    return AblationResult(
        metrics,
        mg,
        pairs,
        models,
        skipped,
        cfg.application_preset,
        errors,
        clusters,
        cfg.held_out_people,
        cfg.held_out_population,
    )


def draw_clusters_of(
    world_intents: dict[str, dict[str, str]], metrics: Collection[tuple[str, str, str, str]], pairs: dict
) -> dict[tuple[str, str, str, str], list]:
    """The cells whose source is a calibration-draws folder (``world_intents[world][source]``), each with its
    pairs' (operator, draw) clusters (:func:`~coassist.scenario.calibration_draws.draw_clusters`)."""
    out = {}
    for key in metrics:
        world, obj, _, source = key
        intent = world_intents.get(world, {}).get(source)
        draws = draw_count(intent) if intent else 1
        if draws > 1:
            out[key] = draw_clusters(pairs[(world, obj)], draws)
    return out


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
    """The held-out cells' sources (:data:`~coassist.experiments.ablation_cells.HELD_OUT_SOURCES`): the
    calibrated ones fitted to the held-out population's operators (their own calibration trials), the
    others as the run has them."""
    out = {s: intents.get(s, s) for s in HELD_OUT_SOURCES if _runnable(s, intents) or s in CALIBRATED}
    out["paths"] = calibrate_paths(ws, population=HELD_OUT)
    out["person"] = calibrate_person(ws, population=HELD_OUT, draws=ws.config.calibration_draws)
    return out


def _held_out_options(cfg, j: int, obj: str, controller: str, intent: str) -> dict[str, Any]:
    # the population's own trial seeds (seed_plan.HELD_OUT_APPLICATION_SEED_OFFSET), not the thesis cells'
    seed = application_seed(trial_seed_base(cfg.seed), j, HELD_OUT)
    return {
        **cell_options(cfg, j, obj, controller, intent),
        "trials": cfg.held_out_trials,
        "seed": seed,
        **population_options(cfg, HELD_OUT),  # its people: reproduce.held_out_population, held_out_people
    }


def _run_held_out(
    ws: Workspace, intents: dict[str, str], metrics: dict, mg: dict, pairs: dict, errors: dict
) -> dict[str, str]:
    """The held-out population's cells (module docstring), paired against its own MG trials; their sources."""
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
    return sources


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
                self.ws.prefetch(
                    f"calibration-{HELD_OUT}", **calibration_options(self.ws, "manual", population=HELD_OUT)
                )
                for name, options in calibration_draw_options(self.ws, HELD_OUT, cfg.calibration_draws).items():
                    self.ws.prefetch(name, **options)
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
            # the report's cells run the controllers as the point-mass world's do: the stability guard is for the
            # people at an arm (drive, ros2, the study); on the report's operators it would not engage
            stability=None,
        )
        for n, s in enumerate(specs)
        if n % cfg.application_trials < cfg.ablation_mujoco_trials
    ]


def probe_configs(cfg, draw: int = 0) -> list:
    """The person model's calibration trials on the MuJoCo UR5 (``reproduce.mujoco_person_calibration`` =
    "mujoco"): what :func:`~coassist.experiments.source_training.calibration_options` collects in the
    point-mass world (MG with the probe, the handle, the application's task and obstacle,
    ``person_calibration_trials`` per application operator, the same trial seeds: the same task and intent draws),
    driven on the arm. ``draw`` k: the point-mass world's calibration draw k, its seeds k ·
    :data:`~coassist.experiments.source_training.DRAW_SEED_STEP` on (``reproduce.calibration_draws``)."""
    from coassist.experiments.seed_plan import calibration_seed
    from coassist.experiments.source_training import DRAW_SEED_STEP
    from coassist.robot.drive import DriveConfig
    from coassist.sim.collect import dataset_specs

    specs = dataset_specs(
        controller="manual-probe",
        users=cfg.application_users,
        tasks=(cfg.application_task,),
        objects=("handle",),
        trials=cfg.person_calibration_trials,
        seed=calibration_seed(trial_seed_base(cfg.seed)) + int(draw) * DRAW_SEED_STEP,
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
    from coassist.scenario.person_model import person_filter_for

    return person_filter_for("mujoco")


def calibrate_then_drive(probes: list[list], folder: str, configs: list, asked: int = 0) -> list[tuple[dict, dict]]:
    """A worker's MuJoCo person-model job: drive the calibration trials of every draw in ``probes`` (one list
    per calibration draw, :func:`probe_configs`; all in one lockstep batch), fit each operator's person model
    per draw (:func:`~coassist.scenario.person_model.fit_people`, as
    :func:`~coassist.experiments.source_training.calibrate_person` does on the point-mass world's) with
    :func:`mujoco_person_filter`, and write them into ``folder`` (the intent of ``configs``): one draw, a
    person-model folder; several, a calibration-draws folder (``draw-0`` …, :mod:`coassist.scenario.calibration_draws`:
    the trial of seed s meets draw s mod K). ``asked`` > 0: each draw then asks each operator for up to that many
    trials going a way round its fit shows too seldom, as the point-mass world's calibration does
    (``reproduce.person_calibration_asked``; :func:`asked_trials`), driven together, and refits with them. Then
    drive ``configs`` as :func:`_drive_batch` does. One job: the cells wait for their own calibration and for
    nothing else."""
    import torch

    from coassist.robot.drive import drive_lockstep
    from coassist.scenario.calibration_draws import write_draws
    from coassist.scenario.person_model import fit_people, write_person_model
    from coassist.sim.person_twin import checked_people

    torch.set_num_threads(1)
    if not probes or not all(probes):
        raise ValueError("calibrate_then_drive needs at least one calibration trial in every draw")
    trials = drive_lockstep([c for draw in probes for c in draw])
    fits, own, at = [], [], 0
    for draw in probes:
        own.append(list(trials[at : at + len(draw)]))  # each draw's calibration trials (the asked ones join below)
        fits.append(fit_people(own[-1]))
        at += len(draw)
    if asked:
        more = [asked_trials(draw, fit, asked) for draw, fit in zip(probes, fits)]
        driven = drive_lockstep([c for draw in more for c in draw])
        at = 0
        for k, draw in enumerate(more):
            if draw:
                own[k] += driven[at : at + len(draw)]
                fits[k] = fit_people(own[k])
            at += len(draw)
    # whether to lead each person along their paths: their calibration replayed against their twin (in the
    # point-mass world, as every calibration's check is: coassist.sim.person_twin)
    settings = mujoco_person_filter()
    fits = [checked_people(calibrated, fit, settings) for calibrated, fit in zip(own, fits)]
    if len(fits) == 1:
        write_person_model(folder, fits[0], settings=settings)
    else:
        names = [f"draw-{k}" for k in range(len(fits))]
        for name, fit in zip(names, fits):
            write_person_model(Path(folder) / name, fit, settings=settings)
        write_draws(folder, names)
    return _drive_batch(configs)


def asked_trials(probes: list, fits: dict, most: int) -> list:
    """The drive configs of the trials one calibration draw asks for (:func:`calibrate_then_drive`): for each
    operator of ``probes`` (its chosen-way trials, in :func:`probe_configs`' order) whose fit in ``fits`` shows a way
    round too seldom (:func:`~coassist.experiments.person_calibration.ways_to_ask`, at most ``most``), their probe
    trial asked that way, on the seeds the point-mass world's calibration gives them
    (:func:`~coassist.experiments.source_training.asked_way_seed`)."""
    from dataclasses import replace

    from coassist.experiments.person_calibration import ways_to_ask
    from coassist.experiments.source_training import asked_way_seed

    users = list(dict.fromkeys(c.user for c in probes))
    per_user = len(probes) // len(users)
    first = min(c.seed for c in probes)
    out = []
    for position, user in enumerate(users):
        mine = [c for c in probes if c.user == user]
        for way, count in ways_to_ask(fits[mine[0].who].paths.sides, most):
            seed = asked_way_seed(first, len(users), per_user, position, way, most)
            out += [replace(mine[0], seed=seed + i, way=way) for i in range(count)]
    return out


def _drive_batch(configs: list) -> list[tuple[dict, dict]]:
    """A worker's MuJoCo runs, in lockstep (one network call per tick for those sharing a model;
    spawned process, one torch thread like the simulator's workers)."""
    import torch

    from coassist.robot.drive import drive_lockstep
    from coassist.sim.pool import payloads

    torch.set_num_threads(1)
    return payloads(drive_lockstep(configs))


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
#: under the run's ``models`` (a calibration-draws folder where ``reproduce.calibration_draws`` > 1).
MUJOCO_PERSON = "person-mujoco"
#: The held-out population's person model (its operators' own calibrations), as the ablation's models name it.
HELD_OUT_PERSON = "person-held-out"


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
        probes = [probe_configs(ws.config, k) for k in range(ws.config.calibration_draws)]
        return calibrate_then_drive, (probes, intent, configs, ws.config.person_calibration_asked)
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

    from coassist.sim.pool import trial_from_payload, worker_pool

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
