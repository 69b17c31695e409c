"""What the stages of ``coassist reproduce`` share: its config and presets, the seed plan,
the workspace that collects datasets and trains models, and the in-loop error measure.

The stages themselves are modules of their own (:mod:`coassist.experiments.transfer`,
:mod:`~coassist.experiments.application`, :mod:`~coassist.experiments.real_recordings`;
the dMPC study and iterative training in :mod:`~coassist.experiments.reproduce`), each
returning a typed result from which its report section is built.
"""

from __future__ import annotations

import contextlib
import json
import threading
from collections.abc import Callable
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from coassist._checks import is_integer
from coassist.config import APPLICATION_PRESET, COLLECTION_PRESET
from coassist.registry import Registry
from coassist.robot.worlds import POINT_MASS

ITERATION_TASKS = ("linear", "curved", "sinusoidal")
EVAL_HORIZONS = (5, 10, 20, 50)


#: The learned intent sources a run may train (coassist.experiments.source_training.LEARNED's names).
LEARNED_SOURCES = ("ridge", "ridge-intent", "lstm-tool", "lstm-hand-alone", "lstm-intent")
#: Where the MuJoCo UR5's person model may be calibrated (ReproduceConfig.mujoco_person_calibration).
MUJOCO_PERSON_CALIBRATIONS = ("mujoco", POINT_MASS)


@dataclass(frozen=True)
class ReproduceConfig:
    """Sizes of the pipeline. Presets: ``default`` (≤ 15 min on 2 CPU cores), ``tiny``
    (a smoke run for tests), ``thesis`` (the thesis' dataset and network sizes; for a GPU).

    Counts of trials are per task (three tasks for the iterative datasets).
    """

    name: str = "default"
    intent_preset: str = "lstm"  # coassist.intent.presets.MODEL_PRESETS, for the simulated stages (as measured there)
    real_intent_preset: str = "default"  # the shipped default predictor, on the real recordings
    control_preset: str = COLLECTION_PRESET
    # Positions ×3.5, not ×10: in decimetres the robot's gain on the learned prediction (an extrapolation of its
    # own motion) removes 2/3 of the plant's damping and the tool rings (coassist.config.APPLICATION_DAMPED_SCALE).
    application_preset: str = APPLICATION_PRESET
    trials_per_task: int = 20  # thesis: 60 trials = 20 per trajectory
    iterations: int = 4  # models M_0 … M_3, as the thesis
    tol: float = 2.5e-4  # stop criterion on e_RMS at 50 samples [m] (eq. 4.13): a quarter millimetre
    epochs: int = 6  # training M_0
    resume_epochs: int = 3  # training M_{k+1} from M_k
    transfer_epochs: int = 8
    # Every n-th window (consecutive windows overlap almost entirely) for the iterative and transfer stages'
    # models; 8 since issue 35 (4 before: the full preset), which halves their training arithmetic.
    train_stride: int = 8
    # The real recordings' models (the shipped default predictor, its published figures): every 4th window.
    real_stride: int = 4
    # The application's learned intent sources (experiments.source_training) train on every simulated
    # dataset, 5.5x the data of M_0. Measured on 5a89abb's datasets (lstm-intent, 6 epochs, test loss
    # on the same held-out trials): 0.00677 at stride 16 against 0.00693 at stride 4 (epoch-to-epoch
    # spread ~0.0001); on the issue-34 operator's datasets 0.00569 / 0.00567 / 0.00561 / 0.00547 at
    # stride 16 / 32 / 48 / 96. Every 96th window since issue 35 (48 in the full preset): each LSTM
    # source is trained source_seeds times for a third of the arithmetic three sources took once at 16.
    source_stride: int = 96
    # The windows the learned sources' scalers and linear skip (a ridge, closed form) are fitted on: every
    # 4th since issue 35 (every window in the full and thesis presets). Over the sources' 330 trials that is
    # still more windows than M_0's skip sees (60 trials, every window). It saves 90 CPU-s a seed (313 → 267 s,
    # seed 0, one day) and moves the LSTM+FC sources' cells only: force share −0.4 to −0.7 points, overshoot
    # share −4 to −11 points, inside their intervals, no verdict (docs/performance.md). 1 restores the bits.
    source_fit_stride: int = 4
    # The learned sources of the in-loop ablation (experiments.source_training.LEARNED); the thesis preset
    # adds lstm-hand-alone, whose negative result docs/intent-labels.md records.
    learned_sources: tuple[str, ...] = ("ridge", "ridge-intent", "lstm-tool", "lstm-intent")
    # Training seeds of each LSTM source (the arbitrated ablation cells run every one; the others the first).
    source_seeds: int = 3
    # Calibration trials per application operator for the path-hypotheses source (MG, the handle, the
    # application's task and obstacle): their detours give the person's shape (scenario.path_hypotheses).
    calibration_trials: int = 4
    # Calibrations of each operator's person model in the point-mass and held-out cells (issue 40): each on its
    # own calibration_trials probe trials, the trial of seed s meeting draw s mod calibration_draws, and the
    # person model's intervals resample the (operator, draw) clusters whole, so that they carry the calibration's
    # own variance (scenario.calibration_draws). Four: each draw meets two of an operator's eight trials per
    # object. 1: one calibration, the intervals over the trials alone (before issue 40's fourth round).
    calibration_draws: int = 4
    # The models each transfer target trains (experiments.iterative.TRANSFER_STARTS): M_TL ("transfer", the
    # thesis' frozen LSTM) and the from-scratch model its claim compares it with; the fine-tuning of every
    # layer, reported but in no claim, only where a preset asks for it (the full and thesis presets).
    transfer_starts: tuple[str, ...] = ("transfer", "scratch")
    # The fixed-α controller's ablation cells with the learned sources (the arbitrated controller runs them
    # all, every training seed): in no claim; the full and thesis presets run them (with the MuJoCo cells of
    # every source, 0.55 of the full preset's 4.20 TFLOP in the loop: bench_floor.py, seed 0 of each preset).
    fixed_alpha_learned: bool = False
    # Shrinkage of the linear skip's ridge start in the simulated stages. M_k meets data collected
    # with M_k in the loop, i.e. inputs shifted from its training data; a weakly regularised linear
    # map extrapolates badly there (measured once, M_0 trained on D_0 and scored on D_1, e_RMS@50:
    # skip_alpha 1 → 5.7 mm, 10 → 3.2 mm, 100 → 2.6 mm; each run reports its own M_0-on-D_1 error).
    # On the real user-a recordings (no such shift) the preset's 1 is best, and the real stage keeps it.
    skip_alpha: float = 100.0
    transfer_trials: int = 15  # thesis: 15 per transfer target
    test_trials: int = 6  # held-out trials per transfer target, for the comparison
    new_users: tuple[int, ...] = (1, 2, 3, 4, 5)
    # Per operator, object and controller (thesis: three, one operator); three operators give
    # 24 trials per object and controller, enough for a paired confidence interval against MG and
    # for each side of the detour (issue 34: ≥ 24).
    application_trials: int = 8
    application_users: tuple[int, ...] = (0, 1, 2)
    application_task: str = "curved"
    # The intent-source ablation on the MuJoCo UR5 (experiments.ablation): trials per operator, object, controller
    # and source (each operator's first application trials; the point-mass world runs application_trials); 0 leaves
    # the MuJoCo world out. Eight (all 24 paired trials per object; 1 until issue 40) resolve the direction of the
    # person model against MG on both objects of seeds 0, 1 and 2 (every paired difference's 95 % interval below
    # zero); four did on five of the six (docs/person-model.md). A MuJoCo trial is 0.5–1.4 CPU-s: eight add about
    # 170 CPU-s to a run against one, four about 96.
    ablation_mujoco_trials: int = 8
    # The held-out population's cells of the ablation (experiments.ablation): trials per operator and
    # object (application_users of the held-out population); 0 leaves them out.
    held_out_trials: int = 8
    # The sources the MuJoCo UR5 runs (empty: every source of the point-mass cells). The claims read the
    # application's source and the person model against MG there, and the LSTM and the oracle put them in
    # context. The full and thesis presets run every source.
    mujoco_sources: tuple[str, ...] = ("lstm-intent", "paths", "person", "oracle")
    # Where the person model of the MuJoCo UR5's cells is calibrated: "mujoco", on the arm it assists, as a lab
    # would (the point-mass cells' probe trials driven there: calibration_trials per operator, 12 trials for
    # ~8 CPU-s; told the arm's rigid board, experiments.ablation.mujoco_person_filter); "point-mass", the
    # point-mass cells' model as it is (docs/person-model.md compares them).
    mujoco_person_calibration: str = "mujoco"
    real_data: str | None = None  # folder holding user-a/ and user-b/ recordings
    real_epochs: int = 15
    workers: int = 2
    # Torch threads for the trainings in this process (the iterative stage's M_k). One: the pool's
    # workers run other work beside them (the real recordings, the scoring), and OpenMP threads
    # that share a core with another process stall at every barrier; and on this 2-core machine a
    # second thread hardly speeds the default network up (7.3k windows/s on one thread, 7.6k on
    # two in the main job). Every other training runs in a worker on one thread.
    threads: int = 1
    device: str = "cpu"
    seed: int = 0
    sweep_duration: float = 10.0
    # Trials with a model in the loop advance in lockstep, one network call per tick for all of them
    # (coassist.runtime.batched_loops); False: each trial alone, the reference path (benchmarks/bench_reproduce.py).
    lockstep: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.lockstep, bool):
            raise ValueError(f"reproduce.lockstep must be true or false, got {self.lockstep!r}")
        for name in (
            "trials_per_task",
            "iterations",
            "epochs",
            "resume_epochs",
            "transfer_epochs",
            "train_stride",
            "source_stride",
            "source_fit_stride",
            "real_stride",
            "transfer_trials",
            "test_trials",
            "application_trials",
            "real_epochs",
            "workers",
            "threads",
            "source_seeds",
            "calibration_trials",
            "calibration_draws",
        ):
            v = getattr(self, name)
            if not is_integer(v) or v < 1:
                raise ValueError(f"reproduce.{name} must be an integer >= 1, got {v!r}")
        if self.calibration_draws > 8:
            raise ValueError(f"reproduce.calibration_draws must be 1 to 8, got {self.calibration_draws}")
        if not is_integer(self.ablation_mujoco_trials) or self.ablation_mujoco_trials < 0:
            raise ValueError(
                f"reproduce.ablation_mujoco_trials must be an integer >= 0, got {self.ablation_mujoco_trials!r}"
            )
        if not is_integer(self.held_out_trials) or self.held_out_trials < 0:
            raise ValueError(f"reproduce.held_out_trials must be an integer >= 0, got {self.held_out_trials!r}")
        if self.ablation_mujoco_trials > self.application_trials:
            raise ValueError(
                f"reproduce.ablation_mujoco_trials ({self.ablation_mujoco_trials}) must be <= "
                f"reproduce.application_trials ({self.application_trials}): its trials are theirs"
            )
        if self.transfer_trials < 3:
            raise ValueError(f"reproduce.transfer_trials must be >= 3 (one per task), got {self.transfer_trials}")
        if not (isinstance(self.skip_alpha, (int, float)) and self.skip_alpha >= 0):
            raise ValueError(f"reproduce.skip_alpha must be a number >= 0, got {self.skip_alpha!r}")
        if not self.tol > 0:
            raise ValueError(f"reproduce.tol must be > 0, got {self.tol!r}")
        if not self.new_users or any(u < 1 for u in self.new_users):
            raise ValueError(f"reproduce.new_users must be user indices >= 1 (0 is the author), got {self.new_users!r}")
        if not self.application_users or any(not is_integer(u) or u < 0 for u in self.application_users):
            raise ValueError(f"reproduce.application_users must be user indices >= 0, got {self.application_users!r}")
        from coassist.experiments.iterative import TRANSFER_STARTS

        if (
            not isinstance(self.transfer_starts, tuple)
            or not {"transfer", "scratch"} <= set(self.transfer_starts)
            or not set(self.transfer_starts) <= set(TRANSFER_STARTS)
            or len(set(self.transfer_starts)) != len(self.transfer_starts)
        ):
            raise ValueError(
                f"reproduce.transfer_starts must hold 'transfer' and 'scratch' (their claim compares them), and "
                f"only names of {TRANSFER_STARTS}, once each; got {self.transfer_starts!r}"
            )
        if not isinstance(self.mujoco_sources, tuple) or not all(isinstance(x, str) and x for x in self.mujoco_sources):
            raise ValueError(f"reproduce.mujoco_sources must be a tuple of source names, got {self.mujoco_sources!r}")
        if self.mujoco_person_calibration not in MUJOCO_PERSON_CALIBRATIONS:
            raise ValueError(
                f"reproduce.mujoco_person_calibration must be one of {MUJOCO_PERSON_CALIBRATIONS}, "
                f"got {self.mujoco_person_calibration!r}"
            )
        if not isinstance(self.fixed_alpha_learned, bool):
            raise ValueError(f"reproduce.fixed_alpha_learned must be true or false, got {self.fixed_alpha_learned!r}")
        if (
            not isinstance(self.learned_sources, tuple)
            or len(set(self.learned_sources)) != len(self.learned_sources)
            or any(src not in LEARNED_SOURCES for src in self.learned_sources)
        ):
            raise ValueError(
                f"reproduce.learned_sources must be distinct names of {LEARNED_SOURCES}, got {self.learned_sources!r}"
            )
        if not is_integer(self.seed) or self.seed < 0:
            raise ValueError(f"reproduce.seed must be an integer >= 0, got {self.seed!r}")


#: Reproduce presets by name.
REPRODUCE_PRESETS: Registry[ReproduceConfig] = Registry(
    "reproduce preset",
    {
        "default": ReproduceConfig(),
        # The default preset until issue 35 (2026-11-29): every window stride, comparison model and ablation cell of
        # the run at 1c264a8 plus issue 34's; 14.9 TFLOP of network arithmetic against the default's 8.5
        # (docs/performance.md: the verdicts of both on seeds 0, 1 and 2).
        "full": ReproduceConfig(
            name="full",
            train_stride=4,
            source_stride=48,
            source_fit_stride=1,
            transfer_starts=("transfer", "scratch", "finetune_all"),
            fixed_alpha_learned=True,
            mujoco_sources=(),
        ),
        "tiny": ReproduceConfig(
            name="tiny",
            trials_per_task=2,
            iterations=2,
            epochs=1,
            resume_epochs=1,
            transfer_epochs=1,
            train_stride=25,
            source_stride=25,
            transfer_trials=3,
            test_trials=2,
            new_users=(1,),
            application_trials=1,
            application_users=(0,),
            real_epochs=1,
            ablation_mujoco_trials=0,
            held_out_trials=1,
            source_seeds=1,
            calibration_trials=1,
            calibration_draws=2,
            real_stride=25,
            sweep_duration=1.0,
        ),
        "thesis": ReproduceConfig(
            name="thesis",
            intent_preset="thesis",
            real_intent_preset="thesis",
            epochs=25,
            resume_epochs=25,
            transfer_epochs=25,
            train_stride=1,
            source_stride=1,
            source_fit_stride=1,
            real_epochs=25,
            device="cuda",
            learned_sources=("ridge", "ridge-intent", "lstm-tool", "lstm-hand-alone", "lstm-intent"),
            transfer_starts=("transfer", "scratch", "finetune_all"),
            fixed_alpha_learned=True,
            mujoco_sources=(),
        ),
    },
)


# ----------------------------------------------------------------------------- the seed plan
# A dataset of n trials collected with seed s uses the trial seeds s … s+n−1
# (coassist.sim.collect). Each collection of the pipeline starts at the run's trial-seed base
# (run seed × RUN_SEED_STRIDE: seed 0's is 0) plus its own offset; the offsets are far enough
# apart that no two collections share a trial seed for any preset, and every offset is below
# the stride, so runs with different seeds share none either (tests/experiments/test_reproduce.py
# checks the thesis preset's sizes and three seeds).

#: The trial seeds of run seed k are k·RUN_SEED_STRIDE … (k + 1)·RUN_SEED_STRIDE − 1.
RUN_SEED_STRIDE = 1_000_000


def trial_seed_base(seed: int) -> int:
    """The first trial seed of run seed ``seed`` (its collections' offsets are added to it)."""
    return int(seed) * RUN_SEED_STRIDE


#: D_k (iterative training, k = 0 … iterations): seed + ITERATION_SEED_STEP·(k+1).
ITERATION_SEED_STEP = 100_000
#: Transfer target i's training trials: seed + TRANSFER_SEED_OFFSET + TRANSFER_SEED_STEP·i;
#: its held-out test trials TRANSFER_TEST_SEED_OFFSET further on.
# (600_000: D_4 of a four-iteration run starts at 500_000, where the targets started before.)
TRANSFER_SEED_OFFSET, TRANSFER_SEED_STEP, TRANSFER_TEST_SEED_OFFSET = 600_000, 20_000, 10_000
#: The heavy load's own transfer dataset (application stage).
HEAVY_TRANSFER_SEED_OFFSET = 800_000
#: The application operators' calibration trials (the path-hypotheses source's person shapes).
CALIBRATION_SEED_OFFSET = 880_000
#: Application trials of object j: seed + APPLICATION_SEED_OFFSET + APPLICATION_SEED_STEP·j
#: (every controller meets the same trials: the same seeds).
APPLICATION_SEED_OFFSET, APPLICATION_SEED_STEP = 900_000, 1000


def iteration_seed(base: int, k: int) -> int:
    """First trial seed of D_k; ``base``: the run's :func:`trial_seed_base` (or any base)."""
    return base + ITERATION_SEED_STEP * (k + 1)


def transfer_seeds(base: int, i: int) -> tuple[int, int]:
    """First trial seeds of transfer target i's training and test datasets (``base``: as :func:`iteration_seed`'s)."""
    train = base + TRANSFER_SEED_OFFSET + TRANSFER_SEED_STEP * i
    return train, train + TRANSFER_TEST_SEED_OFFSET


def heavy_transfer_seed(base: int) -> int:
    """First trial seed of the heavy load's transfer dataset (``base``: as :func:`iteration_seed`'s)."""
    return base + HEAVY_TRANSFER_SEED_OFFSET


def calibration_seed(base: int) -> int:
    """First trial seed of the application operators' calibration trials (``base``: as :func:`iteration_seed`'s)."""
    return base + CALIBRATION_SEED_OFFSET


def application_seed(base: int, j: int) -> int:
    """First trial seed of the application trials with object j (``base``: as :func:`iteration_seed`'s; the
    validation trials of docs/precision.md are bases 50000 and 60000, which no run seed's collections use)."""
    return base + APPLICATION_SEED_OFFSET + APPLICATION_SEED_STEP * j


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
    ):
        """Simulate a dataset into ``out/datasets/<name>``; return its folder and the dataset read back.

        ``groups``: how many lockstep groups the trials are split into on the pool
        (:func:`~coassist.sim.trial_runner.submit_trials`; None: its rule), an option like the others.
        ``population``: who the simulated operators are (:mod:`coassist.scenario.populations`).
        A collection :meth:`prefetch` started with the same options is waited for, not run
        again (the same trials bit for bit: the same jobs); one started under this name with
        other options is let finish, then replaced by the one asked for."""
        from coassist.data import read_dataset
        from coassist.sim.collect import collect_dataset

        options = self._spec_options(
            tasks, users, objects, trials, seed, controller, preset, intent, obstacle, population
        )
        if (options, groups) == self._deferred.get(name):
            self._run_deferred()  # this one and every other collection deferred so far, in lockstep
        self._deferred.pop(name, None)  # deferred with other options: collected as asked, below
        written = self._pending.pop(f"dataset:{name}", None)
        if written is not None:
            if written[0] == (options, groups):
                return written[1].result()
            with contextlib.suppress(Exception):  # another collection under this name: let it end, then replace it
                written[1].result()
        folder = collect_dataset(
            self.out / "datasets" / name,
            dataset_id=name,
            workers=self.config.workers,
            progress=self.progress,
            overwrite=True,
            lockstep=self.config.lockstep,
            pool=self.pool,
            groups=groups,
            **options,
        )
        return folder, read_dataset(folder)

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
    ) -> None:
        """Start :meth:`collect`'s simulations for these options on the run's pool now and
        return at once; a thread of this process writes the dataset as the jobs end, and the
        :meth:`collect` with the same name and options returns it. The pool runs jobs in the
        order they were submitted, so a stage can keep the cores busy with simulations a
        later stage needs while its own work leaves one idle. A model in the loop must
        already be written.

        Without a pool (one worker) the collection is deferred: the first :meth:`collect` of any
        deferred collection runs all of them in this process in lockstep, a few collections to
        a group (:meth:`_run_deferred`), instead of each alone as its :meth:`collect` comes. A
        tick's fixed cost is then shared by the trials of many small collections (the tiny
        preset's ablation cells, one trial each: 18 of its named cells, run_spec_lockstep, one process,
        took 6.3 CPU-s together against 26.8 one by one). The same
        trials bit for bit: named intents are exact in any grouping and ONNX Runtime's kernels
        are batch-invariant (:func:`~coassist.sim.trial_runner.run_spec_lockstep`); a collection whose
        model would run on torch, whose rounding depends on the batch, is not deferred."""
        from coassist.data import read_dataset
        from coassist.sim.collect import collect_dataset, dataset_specs
        from coassist.sim.trial_runner import submit_trials

        options = self._spec_options(
            tasks, users, objects, trials, seed, controller, preset, intent, obstacle, population
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
            # on disk and read back, instead of writing ~20 datasets in a row while the pool idles.
            try:
                folder = collect_dataset(
                    self.out / "datasets" / name,
                    dataset_id=name,
                    progress=False,
                    overwrite=True,
                    submitted=submitted,
                    **options,
                )
                written.set_result((folder, read_dataset(folder)))
            except BaseException as exc:  # handed to collect(), which raises it
                written.set_exception(exc)

        threading.Thread(target=write, name=f"coassist-write-{name}", daemon=True).start()
        self._pending[f"dataset:{name}"] = ((options, groups), written)

    def _run_deferred(self) -> None:
        """Run every deferred collection here, in lockstep groups of whole collections of at most
        :data:`~coassist.sim.trial_runner.NAMED_GROUP` trials together (a bigger one alone), and write
        each dataset (so :meth:`collect` finds it as a prefetched one). The cap keeps memory where a
        one-worker :func:`~coassist.sim.trial_runner.run_trials` keeps it: a group holds its trials until it ends."""
        from coassist.data import read_dataset
        from coassist.sim.collect import collect_dataset, dataset_specs
        from coassist.sim.pool import SubmittedTrials, trial_payload
        from coassist.sim.trial_runner import NAMED_GROUP, run_spec_lockstep

        deferred = [
            (name, options, groups, tuple(dataset_specs(**options)))
            for name, (options, groups) in self._deferred.items()
        ]
        self._deferred.clear()
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
                folder = collect_dataset(
                    self.out / "datasets" / name,
                    dataset_id=name,
                    progress=False,
                    overwrite=True,
                    submitted=SubmittedTrials(specs, [(done, tuple(range(len(specs))))]),
                    **options,
                )
                written: Future = Future()
                written.set_result((folder, read_dataset(folder)))
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
        self, tasks, users, objects, trials, seed, controller, preset, intent, obstacle, population
    ) -> dict[str, Any]:
        # coassist.sim.collect.dataset_specs' keyword arguments
        return {
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
        model = train_model(load_trials(datasets), preset, train_cfg, progress=self.progress)
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
    return str(path), seconds, None if evaluate_on is None else score_model(path, evaluate_on)


def score_model(model: str | Path, datasets: list[Path]) -> Any:
    """:func:`~coassist.intent.evaluate_model` of the saved ``model`` on every trial of ``datasets``."""
    from coassist.intent import evaluate_model, load_model, load_trials

    return evaluate_model(load_model(model), load_trials(datasets), held_out_only=False)


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
        Workspace(replace(config, threads=1), out, progress=False),
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


def evaluate_in_worker(model: str | Path, datasets: list[Path]) -> Any:
    """:func:`score_model` as a job for a worker process of the run's pool, on one torch thread."""
    import torch

    torch.set_num_threads(1)
    return score_model(model, datasets)


# ----------------------------------------------------------------------------- measures


def in_loop_errors(trials, horizons=EVAL_HORIZONS, against: str = "pose") -> dict[int, dict[str, float]]:
    """e_RMS and e_MAX per horizon of the predictions the loop used (Trial.prediction), pooled over trials.

    Per-tick errors of all trials are averaged together (eq. 5.6 over the concatenated
    trajectories); e_MAX: mean and max over ticks of the per-tick maximum (eq. 5.7–5.8).
    ``against``: ``"pose"``, the measured future poses (the thesis), or ``"intent"``, the
    simulated operator's true intent (eq. 5.6 with x_ref,h(k+i) in place of x(k+i); trials
    without one are left out).
    """
    from coassist.metrics import prediction_errors

    if against not in ("pose", "intent"):
        raise ValueError(f"against must be 'pose' or 'intent', got {against!r}")
    out = {}
    for h in horizons:
        rms, mx = [], []
        for t in trials:
            reference = getattr(t, against)
            if t.prediction is None or t.prediction.shape[1] < h or reference is None:
                continue
            e = prediction_errors(t.prediction, reference, h)
            rms.append(e.rms)
            mx.append(e.max)
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
