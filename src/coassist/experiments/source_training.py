"""The intent sources of the simulated stages, and which one the application uses.

Learned sources. Every one is trained from scratch on the same datasets (the iterative stage's
D_k and the board's and heavy load's transfer datasets, all collected with the run's models in
the loop) by the same protocol (the run's intent preset, epochs and skip shrinkage, every
``source_stride``-th window); only what it learns to predict differs, and the ridge's model class:

- ``ridge``: the validation-tuned ridge (the ``linear`` preset) on the tool's future pose;
- ``ridge-intent``: the same ridge on the simulated operator's true intent (``label="intent"``);
- ``lstm-tool``: the LSTM+FC on the tool's future pose (the thesis' label);
- ``lstm-hand-alone``: the LSTM+FC on the path the hand alone would have produced (the
  robot's logged effort removed through the known impedance, ``label="hand_alone"``; the
  ``thesis`` preset only: it never beat the intent label, docs/intent-labels.md);
- ``lstm-intent``: the LSTM+FC on the simulated operator's true intent (``label="intent"``).

Each LSTM source is trained ``source_seeds`` times: the first
is ``<source>``, the others ``<source>-s1``, ``<source>-s2``, … (:func:`seed_names`), on the
training seeds 1000·seed + k (no two runs' trainings share one).

The path-hypotheses source ``paths`` (:mod:`coassist.scenario.path_hypotheses`) is not trained:
:func:`calibrate_paths` fits each application operator's detour (clearance, anticipation, side
preference) to ``calibration_trials`` trials of theirs with MG and writes its calibration. It is
told the obstacle and built on the simulated operator's own family of detours.

The person model ``person`` (:mod:`coassist.scenario.person_model`) is what a lab can have:
:func:`calibrate_person` records ``person_calibration_trials`` trials per operator under manual guidance
with the probe (controller ``manual-probe``) and fits each one's arm and paths from what an arm
measures (no obstacle, no intent label, no family), as ``coassist calibrate`` does on a lab's trials.

:data:`APPLICATION_SOURCE` is the one the application scenario's assistive controllers use:
the source that did best in the in-loop ablation on validation seeds the report never uses
(docs/precision.md; the report's own ablation, :mod:`coassist.experiments.ablation`, measures
all of them again on the report's trials).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from coassist.experiments.pipeline import Workspace, train_in_worker

if TYPE_CHECKING:
    from coassist.experiments.reproduce_config import ReproduceConfig
    from coassist.scenario.person_intent import PersonFilterSettings

__all__ = [
    "APPLICATION_SOURCE",
    "DRAW_SEED_STEP",
    "LEARNED",
    "asked_way_seed",
    "CALIBRATED_KINDS",
    "calibrate_paths",
    "calibrate_person",
    "calibration_draw_options",
    "calibration_options",
    "checked_calibration",
    "population_options",
    "seed_names",
    "train_sources",
    "training_datasets",
]

#: The seeds between two calibration draws' first trials (:func:`calibrate_person`): a draw's trials (operators ×
#: person_calibration_trials) stay under it, and eight draws stay inside the run's calibration block (its application
#: trials start 20 000 seeds on); validation bases 10 000 apart (docs/precision.md's 50000 and 60000) keep their
#: draws apart too.
DRAW_SEED_STEP = 1000

#: The learned sources: (intent preset or None for the run's, window label).
LEARNED = {
    "ridge": ("linear", "tool"),
    "ridge-intent": ("linear", "intent"),
    "lstm-tool": (None, "tool"),
    "lstm-hand-alone": (None, "hand_alone"),
    "lstm-intent": (None, "intent"),
}
#: The application's intent source (module docstring). On the validation seeds (application_seed(50000, j)
#: and (60000, j), 24 trials per object, the arbitrated controller; docs/precision.md) the calibrated
#: path hypotheses got 87 / 92 % of the oracle's force saving and 69 / 72 % of its overshoot reduction
#: (board / heavy), the LSTM+FC on the intent label 87 / 90 % and −3 / −12 %.
APPLICATION_SOURCE = "paths"
#: The folder kind (:data:`~coassist.scenario.intent_registry.INTENT_FOLDERS`) each source calibrated per operator
#: here is given as (:func:`calibrate_paths`, :func:`calibrate_person`): what it was told is that folder's (the
#: operator's own trials besides the source's own knowledge).
CALIBRATED_KINDS = {"paths": "path-hypotheses", "person": "person-model"}


def seed_names(source: str, seeds: int) -> list[str]:
    """The model names of a learned source's trainings: ``source`` for the first seed, ``source-s<k>``
    for the others; a ridge is trained once (its closed form does not depend on a seed)."""
    if LEARNED[source][0] == "linear":
        return [source]
    return [source] + [f"{source}-s{k}" for k in range(1, seeds)]


def calibration_options(ws: Workspace, controller: str, seed: int | None = None, population: str = "thesis") -> dict:
    """The collection options of the operators' calibration trials (:meth:`Workspace.collect`): the
    application's task, obstacle and operators, the handle, first trial seed ``seed`` (default the run's
    :func:`~coassist.experiments.seed_plan.calibration_seed`), ``controller`` ("manual" for ``paths``,
    ``calibration_trials`` each; "manual-probe" for ``person``, ``person_calibration_trials`` each), operators of
    ``population``."""
    from coassist.experiments.application import OBSTACLE
    from coassist.experiments.person_calibration import PROBE_CONTROLLER
    from coassist.experiments.seed_plan import calibration_seed, trial_seed_base

    cfg = ws.config
    # the probe's trials are the person model's (coassist calibrate fits its arm from them): their own count
    trials = cfg.person_calibration_trials if controller == PROBE_CONTROLLER else cfg.calibration_trials
    return {
        "tasks": (cfg.application_task,),
        "users": cfg.application_users,
        "objects": ("handle",),
        "trials": trials,
        "seed": calibration_seed(trial_seed_base(cfg.seed), population) if seed is None else int(seed),
        "controller": controller,
        "preset": cfg.application_preset,
        "intent": "nominal",
        "obstacle": OBSTACLE,
        **population_options(cfg, population),
    }


def population_options(cfg: ReproduceConfig, population: str) -> dict[str, Any]:
    """The collection options (:meth:`Workspace.collect`) naming ``population``'s people: the held-out cells' are
    ``reproduce.held_out_population``'s people of population seed ``reproduce.held_out_people``; the defaults
    ("held-out", 0), and every other population, name the population alone (the options, and so the collections'
    keys, as before)."""
    from coassist.scenario.populations import HELD_OUT

    if population != HELD_OUT:
        return {"population": population}
    people = cfg.held_out_people
    return {"population": cfg.held_out_population, **({"population_seed": people} if people else {})}


def _suffix(population: str) -> str:
    return "" if population == "thesis" else f"-{population}"


def calibrate_person(ws: Workspace, seed: int | None = None, population: str = "thesis", draws: int = 1) -> str:
    """Collect ``person_calibration_trials`` probe trials per application operator of ``population``
    (:func:`calibration_options` with ``manual-probe``), fit each one's person model
    (:func:`~coassist.scenario.person_model.fit_person`: arm and paths from what an arm measures) and
    write them into ``models/person`` (``models/person-<population>`` for another population); the folder.

    ``draws`` > 1: that many calibrations, each on its own probe trials (draw k's first seed is draw 0's plus
    k·:data:`DRAW_SEED_STEP`; draw 0 is the one calibration of ``draws`` = 1, bit for bit), written as a
    calibration-draws folder ``models/person[-<population>]-draws`` (:mod:`coassist.scenario.calibration_draws`:
    the trial of seed s meets draw s mod ``draws``), so that an evaluation's intervals carry the calibration's
    own variance."""
    from coassist.scenario.calibration_draws import MAX_DRAWS, write_draws
    from coassist.scenario.person_model import PERSON_FILTER, fit_people, write_person_model

    if not 1 <= int(draws) <= MAX_DRAWS:
        raise ValueError(f"draws must be 1 to {MAX_DRAWS}, got {draws!r}")
    collections = calibration_draw_options(ws, population, int(draws), seed)
    (first, options), *_ = collections.items()
    if draws > 1 and len(options["users"]) * options["trials"] > DRAW_SEED_STEP:
        raise ValueError(
            f"{len(options['users'])} operators × {options['trials']} calibration trials do not fit in a draw's "
            f"{DRAW_SEED_STEP} seeds"
        )
    # each draw's probe trials fitted, and the trials it asks for put on the pool at once (they run while the next
    # draws are fitted); then each draw fitted again with its asked trials
    drawn = []
    for name, options in collections.items():
        folder, ds = ws.collect(name, **options)
        fits = fit_people(ds.trials)
        asked = _asked_collections(ws, name, options, fits)
        for more, more_options in asked.items():
            ws.prefetch(more, **more_options)
        drawn.append((folder, ds.trials, fits, asked))
    # whether to lead each person along their paths: their calibration replayed against their twin, each draw's
    # people a job on the pool (its workers are otherwise idle here, waiting for the calibration; without a pool,
    # here), which reads the draw's trials from their folders (a trial does not pickle)
    checks = []
    for folder, trials, fits, asked in drawn:
        extra = [ws.collect(name, **more_options) for name, more_options in asked.items()]
        if extra:
            fits = fit_people(list(trials) + [t for _, more_ds in extra for t in more_ds.trials])
        args = ([str(folder)] + [str(f) for f, _ in extra], fits, PERSON_FILTER)
        key = f"lead check: {folder.name}"
        ws.submit(key, checked_calibration, *args)
        checks.append((key, args))
    fitted = [ws.result_of(key, checked_calibration, *args) for key, args in checks]
    if draws == 1:
        return str(write_person_model(ws.out / "models" / f"person{_suffix(population)}", fitted[0]))
    folder = ws.out / "models" / f"person{_suffix(population)}-draws"
    names = [f"draw-{k}" for k in range(len(fitted))]
    for name, fits in zip(names, fitted):
        write_person_model(folder / name, fits)
    return str(write_draws(folder, names))


def checked_calibration(
    folders: Sequence[str], fits: Mapping[str, Any], settings: PersonFilterSettings
) -> dict[str, Any]:
    """A calibration draw's people with their lead checks (:func:`~coassist.sim.person_twin.checked_people`): the
    trials read from ``folders`` in order (the draw's probe trials, then those it asked for), ``fits`` fitted to them,
    ``settings`` the filter the model runs with. A pool's job (:func:`calibrate_person`)."""
    from coassist.data import read_dataset
    from coassist.sim.person_twin import checked_people

    trials = [t for folder in folders for t in read_dataset(folder).trials]
    return checked_people(trials, fits, settings)


def asked_way_seed(first: int, users: int, trials: int, position: int, way: int, most: int) -> int:
    """The first seed of the trials a calibration asks of its ``position``-th operator for ``way`` (+1 / −1), at most
    ``most`` of them: after the draw's ``users`` × ``trials`` chosen-way trials from ``first``, each operator's two
    ways ``most`` seeds apart (so the asked trials of a calibration never share a seed with another trial of it)."""
    return first + users * trials + (2 * position + (0 if way > 0 else 1)) * most


def _asked_collections(
    ws: Workspace, name: str, options: Mapping[str, Any], fits: Mapping[str, Any]
) -> dict[str, dict[str, Any]]:
    """The collections (name → :meth:`Workspace.collect` options) of the trials the calibration ``name`` (collected
    with ``options``, its people's fits ``fits``) asks of each operator: up to ``reproduce.person_calibration_asked``
    trials going a way round shown too seldom (:func:`~coassist.experiments.person_calibration.ways_to_ask`),
    ``<name>-ask-<user>-<way>``; none where it asks for none."""
    from coassist.experiments.person_calibration import ways_to_ask
    from coassist.scenario.path_model import WAY_NAMES
    from coassist.scenario.populations import population_profile

    most = ws.config.person_calibration_asked
    if not most:
        return {}
    users = list(options["users"])
    last = asked_way_seed(options["seed"], len(users), options["trials"], len(users), 1, most)
    if last - options["seed"] > DRAW_SEED_STEP:
        raise ValueError(
            f"{len(users)} operators × ({options['trials']} + 2 × {most} asked) calibration trials do not fit in a "
            f"draw's {DRAW_SEED_STEP} seeds"
        )
    out = {}
    for position, user in enumerate(users):
        who = population_profile(options["population"], user, options.get("population_seed", 0)).name
        for way, count in ways_to_ask(fits[who].paths.sides, most):
            seed = asked_way_seed(options["seed"], len(users), options["trials"], position, way, most)
            out[f"{name}-ask-{user}-{WAY_NAMES[way]}"] = {
                **options,
                "users": (user,),
                "trials": count,
                "seed": seed,
                "way": way,
            }
    return out


def calibration_draw_options(
    ws: Workspace, population: str = "thesis", draws: int = 1, seed: int | None = None
) -> dict[str, dict]:
    """The probe datasets :func:`calibrate_person` collects with ``draws``, in draw order (name →
    :meth:`Workspace.collect` options; draw 0's first seed ``seed``, as :func:`calibration_options`'s): what it
    collects, and what a stage puts on the pool before it asks."""
    suffix = _suffix(population)
    options = calibration_options(ws, "manual-probe", seed, population)
    out = {f"calibration-probe{suffix}": options}
    for k in range(1, int(draws)):
        out[f"calibration-probe{suffix}-draw{k}"] = {**options, "seed": options["seed"] + k * DRAW_SEED_STEP}
    return out


def calibrate_paths(ws: Workspace, seed: int | None = None, population: str = "thesis") -> str:
    """Collect ``calibration_trials`` MG trials per application operator of ``population`` (the handle, the
    application's task and obstacle, :func:`calibration_options`), fit each detour
    (:func:`~coassist.scenario.path_hypotheses.fit_detour`) and write every operator's shape into
    ``models/paths`` (``models/paths-<population>`` for another population,
    :func:`~coassist.scenario.path_hypotheses.write_calibration`); the folder."""
    from coassist.experiments.application import OBSTACLE
    from coassist.scenario.path_hypotheses import calibrate, fit_detour, write_calibration
    from coassist.scenario.tasks import task_for_seed

    suffix = _suffix(population)
    _, ds = ws.collect(f"calibration{suffix}", **calibration_options(ws, "manual", seed, population))
    fits: dict[str, list[tuple[int, float, float]]] = {}
    for trial in ds.trials:
        task = task_for_seed(trial.meta.task, int(trial.meta.seed), obstacle=OBSTACLE)
        fits.setdefault(str(trial.meta.user), []).append(fit_detour(task, trial.pose))
    return str(
        write_calibration(
            ws.out / "models" / f"paths{suffix}", {user: calibrate(f) for user, f in sorted(fits.items())}
        )
    )


def training_datasets(ws: Workspace) -> list[Path]:
    """The datasets every learned source is trained on: the iterative stage's D_k and the
    board's and heavy load's transfer datasets (collected with the run's models in the loop)."""
    root = ws.out / "datasets"
    names = sorted(p.name for p in root.glob("D*") if p.name[1:].isdigit())
    names += [n for n in ("TL-board", "TL-heavy") if (root / n).is_dir()]
    if not names:
        raise ValueError(f"no training datasets in {root}: run the iterative stage first")
    return [root / n for n in names]


def _train_here(
    trainings: Mapping[str, Callable[[], tuple[str, float, Any]]],
    told: Callable[[dict[str, str]], None],
    progress: bool,
) -> dict[str, str]:
    """:func:`train_sources`' trainings (name → :func:`train_in_worker` with its arguments) in this process, in their
    order, each on one torch thread as in a worker; this process's thread count put back after."""
    import torch

    from coassist._progress import progress_bar

    models: dict[str, str] = {}
    threads = torch.get_num_threads()
    told({})
    try:
        with progress_bar(progress) as bar:
            task = bar.add_task(f"training {len(trainings)} intent sources, one at a time", total=len(trainings))
            for name, train in trainings.items():
                models[name] = train()[0]
                bar.advance(task)
                told(dict(models))
    finally:
        torch.set_num_threads(threads)
    return models


def train_sources(
    ws: Workspace,
    datasets: list[Path],
    *,
    processes: int | None = None,
    on_models: Callable[[dict[str, str]], None] | None = None,
) -> dict[str, str]:
    """Train every learned source of ``reproduce.learned_sources`` on ``datasets`` (module docstring), each
    LSTM+FC once per training seed, into ``models/<name>``; model folders by name (:func:`seed_names`).

    On a CPU they train in worker processes, ``processes`` at a time (None: in the run's
    pool, ``reproduce.workers`` at a time; one at a time without the run's pool: in this
    process, the same trainings), each on one torch thread. Small LSTM kernels
    split badly over threads: on this 2-core machine two 1-thread trainings do 1.34x the
    work of one 2-thread training (``benchmarks/bench_training.py --pairs``), and four at
    once took 125.9 s against 124.4 s two at a time (the main job's datasets, one run
    each), so no more processes than cores. A process that shares the cores does not stall
    at OpenMP barriers either. One thread each, however many at a time: the weights do not
    depend on it. On an accelerator (``reproduce.device``) they train one after the other
    on it, in this process.

    ``on_models(models)`` is called in this process with the sources written so far
    (source → folder): once with none as soon as the trainings are on the pool, then as
    each one is written. A caller can put simulations that need no learned source, then
    those with each source in the loop, on the pool behind the trainings, so that a
    worker whose training ended early does not sit idle.
    """
    import contextlib
    from concurrent.futures import as_completed

    from coassist._progress import progress_bar
    from coassist.intent import MODEL_PRESETS
    from coassist.sim.pool import worker_pool

    # each training's arguments, once: the same for ws.train (on an accelerator) and train_in_worker (on a CPU)
    jobs: list[tuple[str, dict[str, Any]]] = []
    for source in ws.config.learned_sources:
        preset_name, label = LEARNED[source]
        epochs = ws.config.epochs if preset_name is None else MODEL_PRESETS[preset_name].train.epochs
        for k, name in enumerate(seed_names(source, ws.config.source_seeds)):
            options: dict[str, Any] = {
                "init": "scratch",
                "epochs": epochs,
                "preset_name": preset_name,
                "label": label,
                "stride": ws.config.source_stride,
                "fit_stride": ws.config.source_fit_stride,
                "seed": ws.config.seed * 1000 + k,  # training seeds seed·1000 + k: no two runs' trainings share one
            }
            jobs.append((name, options))
    told = on_models or (lambda models: None)
    models: dict[str, str] = {}
    if ws.config.device != "cpu":
        told({})
        for name, options in jobs:
            models[name] = str(ws.train(name, datasets, **options))
            told(dict(models))
        return models
    # the first seed of each LSTM+FC first (their cells wait for them), then the other seeds; the ridges last
    jobs.sort(key=lambda job: (job[1]["preset_name"] == "linear", job[1]["seed"]))
    n = max(1, min(ws.config.workers if processes is None else int(processes), len(jobs)))
    # the run's pool (workers processes) unless another count is asked for: then n started here
    shared = ws.pool if processes is None else None
    trainings = {name: partial(train_in_worker, ws.config, ws.out, name, datasets, **options) for name, options in jobs}
    if shared is None and n == 1:
        # one at a time and no pool: here, one after the other, as a one-process pool would have run them while
        # this process waited (its start, ~5 CPU-s importing numpy, scipy and torch, was all it added)
        models = _train_here(trainings, told, ws.progress)
    else:
        with contextlib.nullcontext(shared) if shared is not None else worker_pool(n) as pool:
            futures = {pool.submit(train): name for name, train in trainings.items()}
            told({})
            with progress_bar(ws.progress) as bar:
                task = bar.add_task(f"training {len(jobs)} intent sources, {n} at a time", total=len(jobs))
                for future in as_completed(futures):
                    models[futures[future]] = future.result()[0]
                    bar.advance(task)
                    told(dict(models))
    return {name: models[name] for name in sorted(trainings)}
