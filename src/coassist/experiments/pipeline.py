"""What the stages of ``coassist reproduce`` share at run time: the workspace that collects
datasets and trains models, the training and scoring jobs, and the in-loop error measure.

The run's config and presets are :mod:`coassist.experiments.reproduce_config`, its trial seeds
:mod:`coassist.experiments.seed_plan`. The stages themselves are modules of their own
(:mod:`coassist.experiments.transfer`, :mod:`~coassist.experiments.application`,
:mod:`~coassist.experiments.real_recordings`; the dMPC study and iterative training in
:mod:`~coassist.experiments.reproduce`), each returning a typed result from which its report
section is built.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import threading
from collections.abc import Callable, Collection
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from coassist.experiments.reproduce_config import ReproduceConfig

ITERATION_TASKS = ("linear", "curved", "sinusoidal")
EVAL_HORIZONS = (5, 10, 20, 50)

# ----------------------------------------------------------------------------- the workspace


def _may_defer(specs) -> bool:
    """Whether a collection's trials are the same bit for bit in any lockstep grouping: named intents
    and calibrated sources (no network), or a model whose network runs on ONNX Runtime (batch-invariant);
    not one on torch (:meth:`Workspace.prefetch`)."""
    from coassist.scenario.intent_registry import INTENT_SOURCES

    models = [s for s in specs if s.intent not in INTENT_SOURCES and (Path(s.intent) / "model.json").is_file()]
    if not models:
        return True
    from coassist.intent.onnx_network import onnx_runtime_available

    return all(s.network == "onnx" or (s.network == "auto" and onnx_runtime_available()) for s in models)


def default_real_data() -> str | None:
    """The recordings folder of :func:`coassist.data.default_real_data`, if it holds ``user-a/``."""
    from coassist.data import default_real_data as root

    return str(root()) if (root() / "user-a").is_dir() else None


@dataclass(frozen=True)
class Workspace:
    """The run's output folder and config: collects datasets and trains models into it."""

    config: ReproduceConfig
    out: Path
    progress: bool
    #: The simulation processes every collection runs on (coassist.sim.pool.worker_pool), started
    #: once for the run; None: each collection starts its own.
    pool: Executor | None = None
    #: A pool worker's (:func:`train_in_worker`): the trials of the dataset folders it last trained on are kept
    #: for its next training on the same folders (:class:`KeptTrials`), instead of read again.
    keep_trials: bool = False

    #: Collections put on the pool ahead of time (:meth:`prefetch`), by dataset name; and other
    #: jobs a later stage will ask for (:meth:`submit`, by key). Not part of the value.
    _pending: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)
    #: Without a pool: the collections :meth:`prefetch` deferred, name → (options, groups), in order.
    _deferred: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def collect(
        self,
        name: str,
        *,
        tasks,
        users=(0,),
        objects=("handle",),
        trials: int,
        seed: int,
        controller: str = "cooperative",
        preset: str | None = None,
        intent: str = "nominal",
        obstacle: str = "small",
        groups: int | None = None,
        population: str = "thesis",
        way: int = 0,
        population_seed: int = 0,
    ):
        """Simulate a dataset into ``out/datasets/<name>``; return its folder and the dataset (as
        :func:`~coassist.data.read_dataset` reads it; the trials simulated here as written, not read back).

        ``groups``: how many lockstep groups the trials are split into on the pool
        (:func:`~coassist.sim.trial_runner.submit_trials`; None: its rule), an option like the others.
        ``population``, ``population_seed``: who the simulated operators are (:mod:`coassist.scenario.populations`).
        ``way``: the way round the operators are asked to take (+1 left, −1 right; 0 their own choice).
        A collection :meth:`prefetch` started with the same options is waited for, not run
        again (the same trials bit for bit: the same jobs); one started under this name with
        other options is let finish, then replaced by the one asked for."""
        from coassist.sim.collect import collect_dataset

        options = self._spec_options(
            tasks, users, objects, trials, seed, controller, preset, intent, obstacle, population, way, population_seed
        )
        if (options, groups) == self._deferred.get(name):
            self.run_deferred()  # this one and every other collection deferred so far, in lockstep
        self._deferred.pop(name, None)  # deferred with other options: collected as asked, below
        written = self._pending.pop(f"dataset:{name}", None)
        if written is not None:
            if written[0] == (options, groups):
                return written[1].result()
            with contextlib.suppress(Exception):  # another collection under this name: let it end, then replace it
                written[1].result()
        folder = self.out / "datasets" / name
        return folder, collect_dataset(
            folder,
            dataset_id=name,
            workers=self.config.workers,
            progress=self.progress,
            overwrite=True,
            lockstep=self.config.lockstep,
            pool=self.pool,
            groups=groups,
            read=True,
            **options,
        )

    def prefetch(
        self,
        name: str,
        *,
        tasks,
        users=(0,),
        objects=("handle",),
        trials: int,
        seed: int,
        controller: str = "cooperative",
        preset: str | None = None,
        intent: str = "nominal",
        obstacle: str = "small",
        groups: int | None = None,
        population: str = "thesis",
        way: int = 0,
        population_seed: int = 0,
    ) -> None:
        """Start :meth:`collect`'s simulations for these options on the run's pool now and
        return at once; a thread of this process writes the dataset as the jobs end, and the
        :meth:`collect` with the same name and options returns it. The pool runs jobs in the
        order they were submitted, so a stage can keep the cores busy with simulations a
        later stage needs while its own work leaves one idle. A model in the loop must
        already be written.

        Without a pool (one worker) the collection is deferred: the first :meth:`collect` of any
        deferred collection runs all of them in this process in lockstep, a few collections to
        a group (:meth:`run_deferred`), instead of each alone as its :meth:`collect` comes. A
        tick's fixed cost is then shared by the trials of many small collections (the tiny
        preset's ablation cells, one trial each: 18 of its named cells, run_spec_lockstep, one process,
        took 6.3 CPU-s together against 26.8 one by one). The same
        trials bit for bit: named intents are exact in any grouping and ONNX Runtime's kernels
        are batch-invariant (:func:`~coassist.sim.trial_runner.run_spec_lockstep`); a collection whose
        model would run on torch, whose rounding depends on the batch, is not deferred."""
        from coassist.sim.collect import collect_dataset, dataset_specs
        from coassist.sim.trial_runner import submit_trials

        options = self._spec_options(
            tasks, users, objects, trials, seed, controller, preset, intent, obstacle, population, way, population_seed
        )
        if self.pool is None:
            if _may_defer(dataset_specs(**options)) and name not in self._deferred:
                self._deferred[name] = (options, groups)
            return
        pending = self._pending.get(f"dataset:{name}")
        if pending is not None:
            if pending[0] == (options, groups):
                return  # already on its way: the same trials
            raise ValueError(f"dataset {name!r} is already being prefetched with other options: collect it first")
        submitted = submit_trials(
            dataset_specs(**options),
            self.pool,
            workers=self.config.workers,
            lockstep=self.config.lockstep,
            groups=groups,
        )
        written: Future = Future()

        def write() -> None:
            # Written as the jobs end, in this thread: the stage that asks for it later finds it
            # written and loaded, instead of writing ~20 datasets in a row while the pool idles.
            try:
                folder = self.out / "datasets" / name
                dataset = collect_dataset(
                    folder, dataset_id=name, progress=False, overwrite=True, submitted=submitted, read=True, **options
                )
                written.set_result((folder, dataset))
            except BaseException as exc:  # handed to collect(), which raises it
                written.set_exception(exc)

        threading.Thread(target=write, name=f"coassist-write-{name}", daemon=True).start()
        self._pending[f"dataset:{name}"] = ((options, groups), written)

    def run_deferred(self, names: Collection[str] | None = None) -> None:
        """Run the deferred collections named (None: every one) here, in lockstep groups of whole collections
        of at most :data:`~coassist.sim.trial_runner.NAMED_GROUP` trials together (a bigger one alone), and write
        each dataset (so :meth:`collect` finds it as a prefetched one). The cap keeps memory where a
        one-worker :func:`~coassist.sim.trial_runner.run_trials` keeps it: a group holds its trials until it ends.
        Names not deferred (there is a pool, or a model on torch) are left to their :meth:`collect`; the other
        deferred collections stay deferred: a stage that times its own collections runs only those."""
        from coassist.sim.collect import collect_dataset, dataset_specs
        from coassist.sim.pool import SubmittedTrials, trial_payload
        from coassist.sim.trial_runner import NAMED_GROUP, run_spec_lockstep

        chosen = [name for name in self._deferred if names is None or name in names]
        deferred = [
            (name, options, groups, tuple(dataset_specs(**options)))
            for name, (options, groups) in ((name, self._deferred.pop(name)) for name in chosen)
        ]
        batches: list[list[tuple[str, dict, Any, tuple]]] = []
        for item in deferred:
            if batches and sum(len(b[3]) for b in batches[-1]) + len(item[3]) <= NAMED_GROUP:
                batches[-1].append(item)
            else:
                batches.append([item])
        for batch in batches:
            try:
                trials = run_spec_lockstep([spec for *_, specs in batch for spec in specs])
            except Exception:  # noqa: BLE001 -- e.g. a broken model: each collect runs alone, the error raised by its own
                continue
            start = 0
            for name, options, groups, specs in batch:
                done: Future = Future()
                done.set_result([trial_payload(t) for t in trials[start : start + len(specs)]])
                start += len(specs)
                folder = self.out / "datasets" / name
                dataset = collect_dataset(
                    folder,
                    dataset_id=name,
                    progress=False,
                    overwrite=True,
                    submitted=SubmittedTrials(specs, [(done, tuple(range(len(specs))))]),
                    read=True,
                    **options,
                )
                written: Future = Future()
                written.set_result((folder, dataset))
                self._pending[f"dataset:{name}"] = ((options, groups), written)

    def submit(self, key: str, fn: Callable[..., Any], *args: Any) -> Future | None:
        """Run ``fn(*args)`` on the run's pool, for a later :meth:`take` of ``key`` (None without a pool)."""
        if self.pool is None:
            return None
        future = self.pool.submit(fn, *args)
        self._pending[f"job:{key}"] = future
        return future

    def take(self, key: str) -> Future | None:
        """The future :meth:`submit` started under ``key`` (removed), or None."""
        return self._pending.pop(f"job:{key}", None)

    def result_of(self, key: str, fn: Callable[..., Any], *args: Any) -> Any:
        """What the job :meth:`submit` started under ``key`` returned (waited for); where none was
        started (no pool), ``fn(*args)`` run here: the same work in this process."""
        future = self.take(key)
        return fn(*args) if future is None else future.result()

    def _spec_options(
        self,
        tasks,
        users,
        objects,
        trials,
        seed,
        controller,
        preset,
        intent,
        obstacle,
        population,
        way=0,
        population_seed=0,
    ) -> dict[str, Any]:
        # coassist.sim.collect.dataset_specs' keyword arguments (way and population_seed only where asked: the
        # options, and so the collections' keys, as before)
        return (
            ({"way": way} if way else {})
            | ({"population_seed": population_seed} if population_seed else {})
            | {
                "controller": controller,
                "users": list(users),
                "tasks": list(tasks),
                "objects": list(objects),
                "trials": trials,
                "seed": seed,
                "preset": preset or self.config.control_preset,
                "intent": intent,
                "obstacle": obstacle,
                "population": population,
            }
        )

    def train(
        self,
        name: str,
        datasets: list[Path],
        *,
        init: str,
        epochs: int,
        test_fraction: float = 0.2,
        simulated: bool = True,
        preset_name: str | None = None,
        label: str | None = None,
        stride: int | None = None,
        fit_stride: int = 1,
        seed: int | None = None,
    ) -> Path:
        """Train and save a model. ``test_fraction=0`` when the model is scored on a separate
        test set anyway: then every trial collected for training is trained on. ``label``:
        what a fresh model learns to predict (``WindowConfig.label``; None: the preset's).
        ``stride``: every n-th window, for training and the per-epoch test loss (None: ``train_stride``).
        ``fit_stride``: every n-th window for the scalers and the linear skip's ridge (``TrainConfig.fit_stride``).
        ``seed``: the training's seed (initial weights, split, batch order; None: the run's)."""
        from coassist.intent import MODEL_PRESETS, load_trials, train_model, write_model

        cfg = self.config
        preset = MODEL_PRESETS[preset_name or cfg.intent_preset]
        if label is not None:
            preset = replace(preset, window=replace(preset.window, label=label))
        train_cfg = replace(
            preset.train,
            epochs=epochs,
            init=init,
            seed=cfg.seed if seed is None else seed,
            threads=cfg.threads,
            train_stride=stride or cfg.train_stride,
            eval_stride=stride or cfg.train_stride,
            fit_stride=fit_stride,
            device=cfg.device,
            test_fraction=test_fraction,
        )
        if simulated:
            train_cfg = replace(train_cfg, skip_alpha=cfg.skip_alpha)
        trials = KEPT_TRIALS.load(datasets) if self.keep_trials else load_trials(datasets)
        model = train_model(trials, preset, train_cfg, progress=self.progress)
        path = self.out / "models" / name
        write_model(model, path)
        return path


def train_and_score(
    ws: Workspace,
    name: str,
    datasets: list[Path],
    *,
    init: str,
    epochs: int,
    test_fraction: float = 0.2,
    preset_name: str | None = None,
    label: str | None = None,
    stride: int | None = None,
    evaluate_on: list[Path] | None = None,
    seed: int | None = None,
    fit_stride: int = 1,
) -> tuple[str, float, Any]:
    """:meth:`Workspace.train`, timed, then the model scored (:func:`score_model`) on
    ``evaluate_on`` when given: (model folder, training seconds, evaluation or None)."""
    import time

    t0 = time.perf_counter()
    path = ws.train(
        name,
        datasets,
        init=init,
        epochs=epochs,
        test_fraction=test_fraction,
        preset_name=preset_name,
        label=label,
        stride=stride,
        fit_stride=fit_stride,
        seed=seed,
    )
    seconds = time.perf_counter() - t0
    return str(path), seconds, None if evaluate_on is None else score_model(path, evaluate_on, ws.config.score_stride)


def score_model(model: str | Path, datasets: list[Path], stride: int = 1) -> Any:
    """:func:`~coassist.intent.evaluate_model` of the saved ``model`` on every trial of ``datasets`` (on every
    ``stride``-th tick: ``ReproduceConfig.score_stride``)."""
    from coassist.intent import evaluate_model, load_model, load_trials

    return evaluate_model(load_model(model), load_trials(datasets), held_out_only=False, stride=stride)


class KeptTrials:
    """The trials of the dataset folders loaded last, kept for the next load of the same folders.

    A pool worker trains the application's learned sources one after another, eight trainings on the same seven
    datasets (330 trials in the main job: 1.7–2.6 CPU-s to read with their checksums on a quiet core, 5–7 beside
    the run's other work, each time): kept, each worker reads them once
    (issue 44). A folder is known by its resolved path, its manifest's SHA-256 and every file's size and
    modification time, so a dataset written anew is read anew; a path that is not a dataset folder (a trial file,
    recordings, bags) is read every time and not kept. One entry: other folders' trials replace the kept ones
    (let go before they are read). The trials are immutable (read-only arrays); each load returns a list of its own.
    """

    def __init__(self) -> None:
        self._key: tuple | None = None
        self._trials: list | None = None

    def load(self, paths: Collection[str | Path]) -> list:
        """:func:`~coassist.intent.load_trials` of ``paths``, or the kept trials when they are those folders'."""
        from coassist.intent import load_trials

        key = _folders_key(paths)
        if key is None:
            return load_trials(paths)
        if key != self._key:
            self._key = self._trials = None  # the kept trials go before the next are read
            self._trials = load_trials(paths)
            self._key = key
        return list(self._trials or ())


def _folders_key(paths: Collection[str | Path]) -> tuple | None:
    """What identifies these dataset folders' trials (:class:`KeptTrials`), or None if one is not a dataset folder."""
    from coassist.data.datasets import MANIFEST_NAME

    key = []
    for p in paths:
        folder = Path(p).resolve()
        manifest = folder / MANIFEST_NAME
        if not manifest.is_file():
            return None
        stats = ((f.name, f.stat()) for f in folder.iterdir() if f.is_file())
        files = tuple(sorted((name, st.st_size, st.st_mtime_ns) for name, st in stats))
        key.append((str(folder), hashlib.sha256(manifest.read_bytes()).hexdigest(), files))
    return tuple(key)


#: This process's kept trials (a pool worker's; :attr:`Workspace.keep_trials`).
KEPT_TRIALS = KeptTrials()


def train_in_worker(
    config: ReproduceConfig,
    out: Path,
    name: str,
    datasets: list[Path],
    *,
    init: str,
    epochs: int,
    test_fraction: float = 0.2,
    preset_name: str | None = None,
    label: str | None = None,
    stride: int | None = None,
    evaluate_on: list[Path] | None = None,
    seed: int | None = None,
    fit_stride: int = 1,
) -> tuple[str, float, Any]:
    """:func:`train_and_score` as a job for a worker process of the run's pool, on one torch
    thread (two 1-thread trainings at once do 1.34x the work of one 2-thread training on this
    machine's 2 cores, ``benchmarks/bench_training.py --pairs``)."""
    import torch

    torch.set_num_threads(1)
    return train_and_score(
        Workspace(replace(config, threads=1), out, progress=False, keep_trials=True),
        name,
        datasets,
        init=init,
        epochs=epochs,
        test_fraction=test_fraction,
        preset_name=preset_name,
        label=label,
        stride=stride,
        evaluate_on=evaluate_on,
        seed=seed,
        fit_stride=fit_stride,
    )


def evaluate_in_worker(model: str | Path, datasets: list[Path], stride: int = 1) -> Any:
    """:func:`score_model` as a job for a worker process of the run's pool, on one torch thread."""
    import torch

    torch.set_num_threads(1)
    return score_model(model, datasets, stride)


# ----------------------------------------------------------------------------- measures


def in_loop_errors(trials, horizons=EVAL_HORIZONS, against: str = "pose") -> dict[int, dict[str, float]]:
    """e_RMS and e_MAX per horizon of the predictions the loop used (Trial.prediction), pooled over trials.

    Per-tick errors of all trials are averaged together (eq. 5.6 over the concatenated
    trajectories); e_MAX: mean and max over ticks of the per-tick maximum (eq. 5.7–5.8).
    ``against``: ``"pose"``, the measured future poses (the thesis), or ``"intent"``, the
    simulated operator's true intent (eq. 5.6 with x_ref,h(k+i) in place of x(k+i); trials
    without one are left out).
    """
    from coassist.metrics import prediction_errors_by_horizon

    if against not in ("pose", "intent"):
        raise ValueError(f"against must be 'pose' or 'intent', got {against!r}")
    # each trial's errors at every horizon at once (the prediction converted and checked once), bit for bit
    # prediction_errors' per horizon
    per_trial = []
    for t in trials:
        reference = getattr(t, against)
        if t.prediction is None or reference is None:
            continue
        hs = [h for h in horizons if t.prediction.shape[1] >= h]
        per_trial.append(prediction_errors_by_horizon(t.prediction, reference, hs))
    out = {}
    for h in horizons:
        rms = [e[h].rms for e in per_trial if h in e]
        mx = [e[h].max for e in per_trial if h in e]
        if rms:
            rms_all, max_all = np.concatenate(rms), np.concatenate(mx)
            out[h] = {
                "e_rms": float(rms_all.mean()),
                "e_max_mean": float(max_all.mean()),
                "e_max_max": float(max_all.max()),
            }
    return out


def windows_trained(model_path) -> int:
    """Training windows times this run's epochs of a saved model (its sidecar): the training work done."""
    meta = json.loads((Path(model_path) / "model.json").read_text("utf-8"))
    return int(meta["train_config"]["epochs"]) * int(meta["n_train_windows"])


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
