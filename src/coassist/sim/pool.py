"""The simulation's processes: a pool of worker processes kept across calls, and Ray.

:func:`~coassist.sim.trial_runner.run_trials` and :func:`~coassist.sim.trial_runner.submit_trials` send
trial specs here to run; a job runs in a worker and sends its trials back as plain data
(:func:`trial_payload`), and :class:`SubmittedTrials` delivers them as each job finishes.
This module knows processes and payloads, not what a trial is made of
(:mod:`coassist.sim.trial_runner` assembles and runs them).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass
from typing import Any

from coassist._checks import check_int
from coassist._progress import progress_bar
from coassist.data import Trial, TrialMeta

__all__ = [
    "PARENT_POLL",
    "SubmittedTrials",
    "pool_for",
    "run_on_ray",
    "trial_from_payload",
    "trial_payload",
    "worker_pool",
]


def trial_payload(trial: Trial) -> tuple[dict, dict]:
    """The trial as plain data to send between processes: (meta dict, arrays by name).

    TrialMeta holds read-only mapping proxies, which do not pickle: ship plain data."""
    arrays = {
        name: getattr(trial, name)
        for name in (
            "time",
            "pose",
            "velocity",
            "wrench",
            "reference",
            "prediction",
            "intent",
            "effort_h",
            "effort_r",
            "fault",
        )
    }
    return trial.meta.to_dict(), arrays


def trial_from_payload(payload: tuple[dict, dict]) -> Trial:
    """The :class:`~coassist.data.Trial` of :func:`trial_payload`'s data."""
    meta, arrays = payload
    return Trial(meta=TrialMeta.from_dict(meta), **arrays)


#: How often a worker process checks that its parent is alive [s].
PARENT_POLL = 0.2


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
    from concurrent.futures import ProcessPoolExecutor

    workers = check_int(workers, "workers", 1)
    ctx = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_watch_parent, initargs=(os.getpid(),))


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
        ray.init(address=address)
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
