"""Collect a simulated dataset (thesis §5.2.2: 60 trials, 20 per trajectory) and write it to disk."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import asdict
from pathlib import Path
from typing import Any, Literal, overload

from coassist._checks import check_int
from coassist.data import Dataset, DatasetWriter, read_dataset
from coassist.data.datasets import MANIFEST_NAME, digest
from coassist.data.trial_file import FORMAT_VERSION
from coassist.scenario.intent_registry import INTENT_FOLDERS, INTENT_SOURCES, intent_folder_kind
from coassist.scenario.path_model import WAY_NAMES
from coassist.sim.pool import SubmittedTrials
from coassist.sim.trial_runner import TrialSpec, run_trials, spec_episode


def dataset_specs(
    *,
    controller: str,
    users: Sequence[int],
    tasks: Sequence[str],
    objects: Sequence[str],
    trials: int,
    seed: int,
    preset: str = "thesis-evaluation",
    intent: str = "nominal",
    population_seed: int = 0,
    obstacle: str = "small",
    network: str = "auto",
    population: str = "thesis",
    way: int = 0,
) -> list[TrialSpec]:
    """One spec per (user, object, task, repetition); trial i of the list gets seed ``seed + i``.
    ``network``: what evaluates a model's network (:attr:`TrialSpec.network <coassist.sim.trial_runner.TrialSpec>`).
    ``population``, ``population_seed``: who the users are (:mod:`coassist.scenario.populations`).
    ``way``: the way round every trial's operator is asked to take (:class:`~coassist.sim.trial_runner.TrialSpec`'s;
    0: their own choice).

    Every trial has its own seed, so two datasets with different ``seed`` share no
    trial as long as the seed ranges do not overlap (a 60-trial dataset uses seed … seed+59).
    """
    trials = check_int(trials, "trials", 1)  # per user, object and task
    seed = check_int(seed, "seed", 0)
    for name, values in (("users", users), ("tasks", tasks), ("objects", objects)):
        if len(values) == 0:
            raise ValueError(f"{name} must not be empty")
    specs = []
    for user in users:
        for obj in objects:
            for task in tasks:
                for _ in range(trials):
                    specs.append(
                        TrialSpec(
                            task=task,
                            user=user,
                            object=obj,
                            controller=controller,
                            preset=preset,
                            seed=seed + len(specs),
                            intent=intent,
                            population_seed=population_seed,
                            obstacle=obstacle,
                            network=network,
                            population=population,
                            way=way,
                        )
                    )
    return specs


# The return follows ``read``: the folder, or the dataset (its overloads say which to a type checker).
@overload
def collect_dataset(
    out: str | Path,
    *,
    dataset_id: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    ray_address: str | None = None,
    overwrite: bool = False,
    say: Callable[[str], None] | None = None,
    lockstep: bool = True,
    pool: Executor | None = None,
    submitted: SubmittedTrials | None = None,
    groups: int | None = None,
    live: Any = None,
    read: Literal[False] = False,
    **spec_options: Any,
) -> Path: ...


@overload
def collect_dataset(
    out: str | Path,
    *,
    dataset_id: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    ray_address: str | None = None,
    overwrite: bool = False,
    say: Callable[[str], None] | None = None,
    lockstep: bool = True,
    pool: Executor | None = None,
    submitted: SubmittedTrials | None = None,
    groups: int | None = None,
    live: Any = None,
    read: Literal[True],
    **spec_options: Any,
) -> Dataset: ...


def collect_dataset(
    out: str | Path,
    *,
    dataset_id: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    ray_address: str | None = None,
    overwrite: bool = False,
    say: Callable[[str], None] | None = None,
    lockstep: bool = True,
    pool: Executor | None = None,
    submitted: SubmittedTrials | None = None,
    groups: int | None = None,
    live: Any = None,
    read: bool = False,
    **spec_options,
) -> Path | Dataset:
    """Simulate the trials of :func:`dataset_specs` (``spec_options``) and write them as a dataset.

    ``dataset_id`` defaults to the folder's name. Returns the dataset folder. ``lockstep``,
    ``pool``: :func:`~coassist.sim.trial_runner.run_trials`' (trials advance together in lockstep
    groups; processes kept across collections). ``submitted``: this collection's trials,
    already put on a pool by :func:`~coassist.sim.trial_runner.submit_trials` (its specs must be
    :func:`dataset_specs` of ``spec_options``): they are waited for instead of run again.
    ``groups``: :func:`~coassist.sim.trial_runner.run_trials`' (lockstep groups on the processes).
    ``live``: a :class:`~coassist.runtime.live.LiveFeed` (``--foxglove``) that watches one trial, the
    first still to run: it runs first, in this process, alone (:func:`~coassist.sim.trial_runner.run_spec`'s
    path: the same trial bit for bit with a named intent, to the network's float32 rounding with a
    model, as ``lockstep``), then the others as before.

    ``read``: return the dataset as :func:`~coassist.data.read_dataset` reads it from ``out``
    instead of the folder, the trials simulated here as they were written rather than read back
    (:meth:`DatasetWriter.dataset <coassist.data.DatasetWriter.dataset>`).

    The output is checked and locked before anything is simulated. Each trial is
    written as soon as it finishes (:class:`coassist.data.DatasetWriter`), so memory
    does not grow with the trial count and a killed run loses only the trials in
    flight: running the same collection again continues where it stopped (``say``
    is told how many trials it found; another collection's unfinished trials there are
    refused, naming them, unless ``overwrite``), and once it has finished, running it again
    finds the complete dataset and does nothing. The dataset replaces an old one in
    ``out`` (``overwrite=True``) only once it is complete.
    """
    specs = dataset_specs(**spec_options)
    if submitted is not None and submitted.specs != tuple(specs):
        raise ValueError("collect_dataset(submitted=...): the submitted trials are not this collection's specs")
    out = Path(out)
    s0 = specs[0]
    description = (
        f"simulated: controller={s0.controller} preset={s0.preset} intent={s0.intent} "
        f"users={sorted({s.user for s in specs})} tasks={sorted({s.task for s in specs})} "
        f"objects={sorted({s.object for s in specs})} seeds {specs[0].seed}..{specs[-1].seed}"
        + ("" if s0.population == "thesis" else f" population={s0.population} (seed {s0.population_seed})")
        + ("" if not s0.way else f" asked to go round on the {WAY_NAMES[s0.way]}")
    )
    dataset_id = dataset_id or out.absolute().name  # "--out ." names its folder, not ""
    # What is collected, so that a re-run continues only the same collection.
    model_hash = None if s0.intent in INTENT_SOURCES else _model_hash(Path(s0.intent))
    key = digest(
        {
            "specs": [spec_key(s) for s in specs],
            "dataset_id": dataset_id,
            "format": FORMAT_VERSION,
            "model": model_hash,
        }
    )
    if not overwrite and _holds_collection(out, key, len(specs)):
        if say:
            say(f"{out} already holds this collection, complete ({len(specs)} trials): nothing to do")
        return read_dataset(out) if read else out
    with DatasetWriter(
        out, dataset_id, n_trials=len(specs), key=key, description=description, overwrite=overwrite, keep=read
    ) as writer:

        def finish() -> Path | Dataset:
            folder = writer.finish()
            return writer.dataset() if read else folder

        if say and writer.discarded:
            say(f"removed the unfinished trials of a different collection in {writer.partial}")
        if say and writer.resumed:
            say(f"continuing: {len(writer.resumed)} of {len(specs)} trials were already written in {writer.partial}")
        todo = [i for i in range(len(specs)) if not writer.has(i)]
        if live is not None and todo and submitted is None:
            watched = todo.pop(0)
            spec = specs[watched]
            if say:
                say(f"live: trial {watched} (task {spec.task}, user {spec.user}, seed {spec.seed}) runs first, watched")
            episode = spec_episode(spec)
            writer.add(watched, episode.finish(episode.run(on_tick=live.watch(episode))))
        if submitted is not None:
            submitted.gather(lambda i, trial: writer.add(i, trial) if not writer.has(i) else None, progress)
            return finish()
        run_trials(
            [specs[i] for i in todo],
            workers=workers,
            progress=progress,
            ray_address=ray_address,
            lockstep=lockstep,
            pool=pool,
            groups=groups,
            on_result=lambda j, trial: writer.add(todo[j], trial),
        )
        return finish()


def spec_key(spec: TrialSpec) -> dict:
    """A spec as the collection's key sees it: the thesis population's specs are keyed as they were
    before populations had names (a finished or half-written collection of it stays recognised)."""
    out = asdict(spec)
    if out["population"] == "thesis":
        del out["population"]
    if not out["way"]:  # the operator's own choice: keyed as before ways could be asked for
        del out["way"]
    return out


def _model_hash(folder: Path) -> str | None:
    """A digest of what an ``--intent`` folder runs, so that a re-run continues only the same model's collection: the
    file that marks its kind (:data:`~coassist.scenario.intent_registry.INTENT_FOLDERS`: a trained model's sidecar,
    a calibration, a person model — calibrated again, another model), for a calibration-draws folder with each draw's
    person model; None where the folder is of no kind."""
    kind = intent_folder_kind(str(folder))
    if kind is None:
        return None
    marker = folder / INTENT_FOLDERS[kind].marker
    if kind != "calibration-draws":
        return digest(marker.read_bytes().hex())
    files = [marker, *sorted(folder.glob(f"*/{INTENT_FOLDERS['person-model'].marker}"))]
    return digest({str(f.relative_to(folder)): f.read_bytes().hex() for f in files})


def _holds_collection(out: Path, key: str, n_trials: int) -> bool:
    """Whether ``out`` is the finished dataset of the collection ``key`` (its manifest says so)."""
    try:
        manifest = json.loads((out / MANIFEST_NAME).read_text("utf-8"))
    except (OSError, ValueError):
        return False
    return (
        isinstance(manifest, dict)
        and manifest.get("collection_key") == key
        and isinstance(manifest.get("trials"), list)
        and len(manifest["trials"]) == n_trials
    )
