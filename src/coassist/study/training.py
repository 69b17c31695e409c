"""The study's models, trained in a background process exactly as ``coassist train`` trains them.

:func:`train_job` is what the background process runs: the trials loaded from the same
folders or files (:func:`coassist.intent.load_trials`, so the same trial ids and the same
split), the intent preset with the plan's ``[training]`` options applied the way the
command line applies its options, :func:`~coassist.intent.training.train_model` and
:func:`~coassist.intent.training.write_model`. Given the seed and the thread count, training
is deterministic, so the model equals the one :func:`train_command` (recorded with it) makes
from the same trials; the tests check that tensor by tensor.

:class:`BackgroundTraining` runs jobs in a ``spawn``-ed process each (torch in a process of
its own: the study's control loop and page never wait for it) and tells when one is ready.
The worker dies with the study's run: a thread of its own, started before any job, polls its
parent (:func:`_exit_with_parent`) and ends it within :data:`PARENT_POLL_S` once the run is
gone (a kill -9 included), so no orphan keeps training, holding memory, the model's lock and
the pipe of a dead parent; the resumed run trains the model again (the same model).
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from coassist.study.plan import TrainingPlan

__all__ = ["BackgroundTraining", "TrainJob", "study_preset", "train_command", "train_job"]

#: [s] how often a training worker checks that the run that started it is alive.
PARENT_POLL_S = 0.2


@dataclass(frozen=True)
class TrainJob:
    """One model to train: ``data`` dataset folders or trial files, ``init`` as ``coassist train --init``
    (scratch, resume:<model>, transfer:<model>), into ``out``, with the plan's ``training`` options."""

    data: tuple[str, ...]
    out: str
    init: str
    training: TrainingPlan


def study_preset(t: TrainingPlan, init: str):
    """The intent preset as ``coassist train --preset … --epochs … --init init`` builds it (coassist.cli.intent)
    from the plan's ``[training]`` ``t``; the sizes (layers, hidden, fc) apply to ``init="scratch"`` only."""
    from coassist.intent.presets import MODEL_PRESETS, with_overrides

    p = with_overrides(
        MODEL_PRESETS.lookup(t.preset),
        epochs=t.epochs,
        lr=t.lr,
        batch_size=t.batch_size,
        seed=t.seed,
        threads=t.threads,
        test_fraction=t.test_fraction,
        init=init,
        optimizer=t.optimizer,
    )
    if init == "scratch" and (t.layers, t.hidden, t.fc) != (None, None, None):
        p = replace(
            p,
            lstm_layers=p.lstm_layers if t.layers is None else t.layers,
            hidden=p.hidden if t.hidden is None else t.hidden,
            fc=p.fc if t.fc is None else t.fc,
        )
        p.network(2)  # validates the sizes
    return p


def train_job(job: TrainJob) -> dict[str, Any]:
    """Train and write one model (module docstring); returns what the study records of it."""
    import torch

    from coassist._io import OutputLock
    from coassist.intent import load_trials
    from coassist.intent.training import train_model, write_model

    trials = load_trials(job.data)
    p = study_preset(job.training, job.init)
    torch.set_num_threads(p.train.threads)
    with OutputLock(job.out):
        model = train_model(trials, p, p.train, checkpoint_to=job.out)
        write_model(model, job.out)
    last = model.info["training_history"][-1]
    return {
        "model": job.out,
        "trials": [lt.id for lt in trials],
        "train_seconds": float(model.info["train_seconds"]),
        "train_loss": last["train_loss"],
        "test_loss": last["test_loss"],
        "command": train_command(job),
    }


def train_command(job: TrainJob) -> list[str]:
    """The ``coassist train`` command line that makes the same model from the same trials."""
    t = job.training
    cmd = ["coassist", "train", *job.data, "--out", job.out, "--preset", t.preset, "--init", job.init]
    for option, value in (
        ("--epochs", t.epochs),
        ("--lr", t.lr),
        ("--batch-size", t.batch_size),
        ("--seed", t.seed),
        ("--threads", t.threads),
        ("--test-fraction", t.test_fraction),
        ("--optimizer", t.optimizer),
    ):
        if value is not None:
            cmd += [option, str(value)]
    if job.init == "scratch":
        for option, value in (("--layers", t.layers), ("--hidden", t.hidden)):
            if value is not None:
                cmd += [option, str(value)]
        if t.fc is not None:
            cmd += ["--fc", ",".join(str(v) for v in t.fc)]
    return cmd


def _exit_with_parent(parent: int) -> None:
    """A training worker's initializer: a daemon thread ends the process (``os._exit``, as a kill would)
    once its parent ``parent`` is gone, i.e. once the worker has been handed to another parent."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="coassist-exit-with-parent", daemon=True).start()


class BackgroundTraining:
    """Jobs by name, each in a fresh ``spawn``-ed process (one at a time: the machine's cores
    are the control loop's first). :meth:`ready` never blocks; :meth:`wait` does. A job is a
    :class:`TrainJob` (run by :func:`train_job`) or another job with the module-level function
    ``work`` that runs it (the calibration's fit: :func:`coassist.study.calibration.fit_job`)."""

    def __init__(self) -> None:
        self._pool: ProcessPoolExecutor | None = None
        self._jobs: dict[str, Future] = {}

    def submit(self, name: str, job: Any, work: Callable[[Any], dict[str, Any]] = train_job) -> Future:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                1,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_exit_with_parent,
                initargs=(os.getpid(),),
            )
        fut = self._pool.submit(work, job)
        self._jobs[name] = fut
        return fut

    def running(self, name: str) -> bool:
        fut = self._jobs.get(name)
        return fut is not None and not fut.done()

    def busy(self, names: Sequence[str] | None = None) -> bool:
        return any(not f.done() for n, f in self._jobs.items() if names is None or n in names)

    def has(self, name: str) -> bool:
        return name in self._jobs

    def ready(self, name: str) -> bool:
        fut = self._jobs.get(name)
        return fut is not None and fut.done()

    def wait(self, name: str) -> dict[str, Any]:
        """The job's record once it finished (its exception if it failed)."""
        return self._jobs[name].result()

    def close(self, *, interrupted: bool = False) -> None:
        """Shut the worker down; ``interrupted`` (the run was stopped): end a training in progress now
        instead of waiting for it (its model is trained again, the same, when next needed)."""
        if self._pool is None:
            return
        if interrupted:
            for proc in list(getattr(self._pool, "_processes", {}).values()):  # no public kill before Python 3.14
                proc.terminate()
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None


def model_ready(folder: str | Path) -> bool:
    """Whether ``folder`` holds a finished model (``write_model`` swaps the folder in whole)."""
    return (Path(folder) / "model.json").is_file()
