"""The simulation's processes: a pool of worker processes kept across calls, and Ray.

:func:`~coassist.sim.trial_runner.run_trials` and :func:`~coassist.sim.trial_runner.submit_trials` send
trial specs here to run; a job runs in a worker and sends its trials back as plain data
(:func:`trial_payload`), and :class:`SubmittedTrials` delivers them as each job finishes.
This module knows processes and payloads, not what a trial is made of
(:mod:`coassist.sim.trial_runner` assembles and runs them).

**How the payloads travel.** A job's trials are its :class:`Payloads`. Pickled in one of
:func:`worker_pool`'s workers, their arrays go through a file of the pool's own in shared memory
(``/dev/shm``: a tmpfs, so memory, not a disk) and only the file's name, the arrays' shapes and
the trials' metadata through the pool's pipe; the parent reads each array straight into its own
buffer and removes the file as it unpickles the job's result. Through the pipe, the main job's
4.6 GB of trials (86 % of it the predictions the loops used) were pickled by the workers, sent
64 KiB at a time and read back by the pool's result thread, which spent 16–21 CPU-s of a run, nearly
all of it in the kernel (issue 44). Where the folder is missing or a write fails (no ``/dev/shm``, a full tmpfs,
Ray's workers, a pool of another kind), the arrays are pickled inline as before: the same
payloads either way. The folder is the pool's (created with it, removed at its shutdown, and a
folder whose process is gone is removed by the next pool), so a crashed job leaves nothing behind
its run.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from coassist._checks import check_int
from coassist._io import remove_stale, temp_name
from coassist._progress import progress_bar
from coassist.data import Trial, TrialMeta

__all__ = [
    "PARENT_POLL",
    "Payloads",
    "SubmittedTrials",
    "WorkerPool",
    "payloads",
    "pool_for",
    "run_on_ray",
    "trial_from_payload",
    "trial_payload",
    "worker_pool",
]


#: The array fields of :class:`~coassist.data.Trial`: all of its fields but ``meta``.
TRIAL_ARRAYS = tuple(f.name for f in dataclasses.fields(Trial) if f.name != "meta")


def trial_payload(trial: Trial) -> tuple[dict, dict]:
    """The trial as plain data to send between processes: (meta dict, arrays by name).

    TrialMeta holds read-only mapping proxies, which do not pickle: ship plain data. Every array field of
    :class:`~coassist.data.Trial` goes (a hand-written list once left out the arm's joints and joint velocities:
    the MuJoCo trials a worker ran arrived without them)."""
    return trial.meta.to_dict(), {name: getattr(trial, name) for name in TRIAL_ARRAYS}


def trial_from_payload(payload: tuple[dict, dict]) -> Trial:
    """The :class:`~coassist.data.Trial` of :func:`trial_payload`'s data."""
    meta, arrays = payload
    return Trial(meta=TrialMeta.from_dict(meta), **arrays)


#: Where a pool's folders of payload files go: shared memory where the system has it.
SHARED_MEMORY = Path("/dev/shm")
#: A pool's folder is ``SHARED_MEMORY / temp_name(FOLDER_NAME, "new")``: ``.coassist-pool.<pid>.<random>.new``,
#: pid the process that started the pool.
FOLDER_NAME = "coassist-pool"

# The payload folder of the pool this process works for: set once by the pool's initializer in
# each worker (:func:`_start_worker`) and read when a job's result is pickled; None elsewhere
# (the parent, Ray's workers, a process of no pool), where payloads are pickled inline.
_worker_folder: Path | None = None


class Payloads(list):
    """A job's trials as :func:`trial_payload`'s (meta, arrays) pairs: a list, pickled through a file in a
    worker of :func:`worker_pool` (module docstring), inline elsewhere; unpickled, the same list."""

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        shipped = _ship(self, _worker_folder)
        if shipped is None:
            return (Payloads, (list(self),))
        return (_receive, shipped)


def payloads(trials: Sequence[Trial]) -> Payloads:
    """``trials`` as a job's result: :class:`Payloads` of their :func:`trial_payload`."""
    return Payloads(trial_payload(t) for t in trials)


def _ship(items: list, folder: Path | None) -> tuple[str, list, list] | None:
    """Write every array of ``items`` into a new file in ``folder``, in order: (its path, each trial's meta,
    each array's (trial, name, dtype, shape) or (trial, name, None, None) for a None); None where it cannot
    (no folder, anything not a plain payload, a failed write: the file is removed), to pickle inline."""
    if folder is None or not folder.is_dir():
        return None
    metas, layout, arrays = [], [], []
    for t, item in enumerate(items):
        if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[1], dict)):
            return None
        meta, named = item
        metas.append(meta)
        for name, a in named.items():
            if a is None:
                layout.append((t, name, None, None))
            elif type(a) is np.ndarray and a.dtype.kind in "biuf" and not a.dtype.hasobject:
                layout.append((t, name, a.dtype.str, a.shape))
                arrays.append(np.ascontiguousarray(a))
            else:
                return None
    try:
        fd, path = tempfile.mkstemp(dir=folder, suffix=".payload")
    except OSError:
        return None
    try:
        with os.fdopen(fd, "wb", buffering=0) as fh:
            for a in arrays:
                if not a.nbytes:  # nothing to write (and no byte view of an empty shape)
                    continue
                view = a.data.cast("B")
                written = 0
                while written < len(view):  # a write to a pipe-like file may be short
                    written += fh.write(view[written:])
    except OSError:  # e.g. ENOSPC: a full tmpfs
        with contextlib.suppress(OSError):
            os.unlink(path)
        return None
    return path, metas, layout


def _receive(path: str, metas: list, layout: list) -> Payloads:
    """The :class:`Payloads` that :func:`_ship` wrote to ``path``, each array read into a buffer of its own;
    the file is removed."""
    try:
        fh = open(path, "rb", buffering=0)  # noqa: SIM115 -- closed below, and the file removed
    except FileNotFoundError:
        raise RuntimeError(
            f"a worker's trials were sent in {path}, which is gone (was the pool's folder in {SHARED_MEMORY} removed?)"
        ) from None
    out: list[tuple[dict, dict]] = [(meta, {}) for meta in metas]
    try:
        with fh:
            for t, name, dtype, shape in layout:
                if dtype is None:
                    out[t][1][name] = None
                    continue
                a = np.empty(shape, dtype=np.dtype(dtype))
                out[t][1][name] = a
                if not a.nbytes:
                    continue
                view = a.data.cast("B")
                got = 0
                while got < len(view):
                    n = fh.readinto(view[got:])
                    if not n:
                        raise RuntimeError(
                            f"a worker's trials in {path} end early: {got} of {len(view)} bytes of {name}"
                        )
                    got += n
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
    return Payloads(out)


def _pool_folder() -> Path | None:
    """A new, empty payload folder for a pool started by this process (module docstring), or None where
    there is no shared memory to put it in. The folders of processes that are gone are removed first: the
    folder is named as the project's other temporaries (:func:`coassist._io.temp_name`), which
    :func:`coassist._io.remove_stale` sweeps."""
    if not SHARED_MEMORY.is_dir():
        return None
    remove_stale(SHARED_MEMORY, FOLDER_NAME)
    folder = SHARED_MEMORY / temp_name(FOLDER_NAME, "new")
    try:
        folder.mkdir()
    except OSError:
        return None
    return folder


#: How often a worker process checks that its parent is alive [s].
PARENT_POLL = 0.2


def _start_worker(parent: int, folder: str | None) -> None:
    """Worker initializer: watch the parent (:func:`_watch_parent`) and send payloads through ``folder``."""
    global _worker_folder
    _worker_folder = None if folder is None else Path(folder)
    _watch_parent(parent)


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


class WorkerPool(ProcessPoolExecutor):
    """:func:`worker_pool`'s processes: ``workers`` of context ``context``, each started by :func:`_start_worker`,
    and the pool's payload folder ``folder`` (module docstring; None: payloads pickled inline), removed when the
    pool shuts down: by then its jobs' files have been read, or are no longer wanted."""

    def __init__(self, workers: int, context: Any, folder: Path | None) -> None:
        super().__init__(
            max_workers=workers,
            mp_context=context,
            initializer=_start_worker,
            initargs=(os.getpid(), None if folder is None else str(folder)),
        )
        self.payload_folder = folder

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            super().shutdown(wait=wait, cancel_futures=cancel_futures)
        finally:
            if self.payload_folder is not None:
                shutil.rmtree(self.payload_folder, ignore_errors=True)


def worker_pool(workers: int) -> Executor:
    """``workers`` simulation processes to pass to :func:`~coassist.sim.trial_runner.run_trials` (``pool``) call after call.

    Each :func:`~coassist.sim.trial_runner.run_trials` without a pool starts its own processes, and a fresh
    interpreter importing numpy, scipy and torch costs seconds: a pipeline of many small
    collections (``coassist reproduce``: ~40) spends more time starting workers than
    simulating. One pool for the whole run pays it once. spawn: a clean interpreter per
    worker (no inherited threads, locks or torch state); callers' scripts need the usual
    ``if __name__ == "__main__":`` guard. Workers keep the parent's BLAS thread settings
    (inherited environment): the game's gains, and so every trial, are bit-identical
    only for the same BLAS thread count. Use it as a context manager (it shuts down).
    """
    import multiprocessing

    workers = check_int(workers, "workers", 1)
    ctx = multiprocessing.get_context("spawn")
    return WorkerPool(workers, ctx, _pool_folder())


def pool_for(pool: Executor | None, workers: int):
    """The caller's pool, left running, or a new one of ``workers`` processes, shut down after use."""
    return worker_pool(workers) if pool is None else contextlib.nullcontext(pool)


@dataclass(eq=False)
class SubmittedTrials:
    """Trials running on a pool (:func:`coassist.sim.trial_runner.submit_trials`): their specs, and per
    job the future of its payloads (:func:`trial_payload`) and the indices (into ``specs``) of
    the trials it runs.

    :meth:`gather` takes the jobs off this handle (``jobs`` is empty after it): a future
    holds its job's trials for as long as it is referenced.
    """

    specs: tuple[Any, ...]
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
                    deliver(i, trial_from_payload(payload))
                del payloads
                bar.advance(task_id, len(members))


def run_on_ray(
    job: Callable[[list[Any]], list[tuple[dict, dict]]],
    specs: Sequence[Any],
    address: str,
    progress: bool,
    on_result: Callable[[int, Trial], None] | None = None,
) -> list[Trial]:
    """Each spec as its own Ray task ``job([spec])`` (payloads, :func:`trial_payload`) on the
    cluster at ``address``; the trials in the order of ``specs`` (as :func:`~coassist.sim.trial_runner.run_trials`
    says), or ``on_result(i, trial)`` for each as it finishes and an empty list.

    Needs the optional extra ``pip install coassist[cluster]`` (RuntimeError saying so otherwise).
    """
    try:
        import ray  # optional extra
    except ImportError:
        raise RuntimeError(
            "run_trials(ray_address=...) needs Ray, an optional extra: pip install coassist[cluster]"
        ) from None
    if not ray.is_initialized():
        try:
            ray.init(address=address)
        except (ValueError, ConnectionError, RuntimeError) as exc:  # the cluster's own words, with what was asked
            raise ConnectionError(f"the Ray cluster at {address!r} could not be reached: {exc}") from None
    remote = ray.remote(job)
    refs = [remote.remote([spec]) for spec in specs]
    index = {ref: i for i, ref in enumerate(refs)}
    results: list[Trial | None] = [None] * len(specs)
    pending = list(refs)
    with progress_bar(progress) as bar:
        task_id = bar.add_task("simulating", total=len(specs))
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                trial = trial_from_payload(ray.get(ref)[0])
                if on_result is None:
                    results[index[ref]] = trial
                else:
                    on_result(index[ref], trial)
                bar.advance(task_id)
    return [] if on_result else results  # type: ignore[return-value]
