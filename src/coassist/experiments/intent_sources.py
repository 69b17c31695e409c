"""The learned intent sources of the simulated stages, and which one the application uses.

Every learned source is trained from scratch on the same datasets (the iterative stage's
D_k and the board's and heavy load's transfer datasets, all collected with the run's
models in the loop) by the same protocol (the run's intent preset, epochs, seed and skip
shrinkage, every ``source_stride``-th window); only what it learns to predict differs, and the ridge's model class:

- ``ridge``: the validation-tuned ridge (the ``linear`` preset) on the tool's future pose;
- ``lstm-tool``: the LSTM+FC on the tool's future pose (the thesis' label);
- ``lstm-hand-alone``: the LSTM+FC on the path the hand alone would have produced (the
  robot's logged effort removed through the known impedance, ``label="hand_alone"``);
- ``lstm-intent``: the LSTM+FC on the simulated operator's true intent (``label="intent"``).

:data:`APPLICATION_SOURCE` is the one the application scenario's assistive controllers
use: the source that got the largest share of the oracle's benefit in the in-loop
ablation on validation seeds the report never uses (``docs/intent-labels.md``; the
report's own ablation, :mod:`coassist.experiments.ablation`, measures all of them again on
the report's trials).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from coassist.experiments.pipeline import Workspace, train_in_worker

__all__ = ["APPLICATION_SOURCE", "LEARNED", "train_sources", "training_datasets"]

#: The learned sources: (intent preset or None for the run's, window label).
LEARNED = {"ridge": ("linear", "tool"), "lstm-tool": (None, "tool"), "lstm-hand-alone": (None, "hand_alone"),
           "lstm-intent": (None, "intent")}  # fmt: skip
#: The application's intent source (module docstring): on the validation seeds the LSTM+FC
#: on the intent label got 92 / 96 % of the oracle's force saving with the arbitrated
#: controller, the tool label 71 / 73 % (board / heavy; docs/intent-labels.md).
APPLICATION_SOURCE = "lstm-intent"


def training_datasets(ws: Workspace) -> list[Path]:
    """The datasets every learned source is trained on: the iterative stage's D_k and the
    board's and heavy load's transfer datasets (collected with the run's models in the loop)."""
    root = ws.out / "datasets"
    names = sorted(p.name for p in root.glob("D*") if p.name[1:].isdigit())
    names += [n for n in ("TL-board", "TL-heavy") if (root / n).is_dir()]
    if not names:
        raise ValueError(f"no training datasets in {root}: run the iterative stage first")
    return [root / n for n in names]


def train_sources(ws: Workspace, datasets: list[Path], *, processes: int | None = None,
                  on_models: Callable[[dict[str, str]], None] | None = None) -> dict[str, str]:
    """Train every learned source on ``datasets`` (module docstring) into ``models/<source>``; model folders by source.

    On a CPU they train in worker processes, ``processes`` at a time (None: in the run's
    pool, ``reproduce.workers`` at a time), each on one torch thread. Small LSTM kernels
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
    from coassist.sim.world import worker_pool

    jobs = []
    for source, (preset_name, label) in LEARNED.items():
        epochs = ws.config.epochs if preset_name is None else MODEL_PRESETS[preset_name].train.epochs
        jobs.append((source, epochs, preset_name, label))
    told = on_models or (lambda models: None)
    models: dict[str, str] = {}
    if ws.config.device != "cpu":
        told({})
        for source, epochs, preset_name, label in jobs:
            models[source] = str(ws.train(source, datasets, init="scratch", epochs=epochs, preset_name=preset_name,
                                          label=label, stride=ws.config.source_stride))  # fmt: skip
            told(dict(models))
        return models
    jobs.sort(key=lambda job: job[2] == "linear")  # the LSTM+FC ones first: the closed-form ridge is quick
    n = max(1, min(ws.config.workers if processes is None else int(processes), len(jobs)))
    # the run's pool (workers processes) unless another count is asked for: then n started here
    shared = ws.pool if processes is None else None
    with contextlib.nullcontext(shared) if shared is not None else worker_pool(n) as pool:
        futures = {pool.submit(train_in_worker, ws.config, ws.out, source, datasets, init="scratch", epochs=epochs,
                               preset_name=preset_name, label=label, stride=ws.config.source_stride): source
                   for source, epochs, preset_name, label in jobs}  # fmt: skip
        told({})
        with progress_bar(ws.progress) as bar:
            task = bar.add_task(f"training {len(jobs)} intent sources, {n} at a time", total=len(jobs))
            for future in as_completed(futures):
                models[futures[future]] = future.result()[0]
                bar.advance(task)
                told(dict(models))
    return {source: models[source] for source in LEARNED}
