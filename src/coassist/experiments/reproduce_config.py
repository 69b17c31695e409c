"""The main job's config (``coassist reproduce``): :class:`ReproduceConfig` and its presets.

:class:`ReproduceConfig` holds the sizes of every stage of the pipeline (trials, epochs,
strides, workers, which sources and cells run), validated on construction (errors name the
``reproduce.`` field); :data:`REPRODUCE_PRESETS` names the presets ``default``, ``full``,
``tiny`` and ``thesis``. The workspace that runs a config is
:class:`~coassist.experiments.pipeline.Workspace`; the trial seeds each collection uses are
:mod:`coassist.experiments.seed_plan`'s.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from coassist._checks import is_integer
from coassist.config import APPLICATION_PRESET, COLLECTION_PRESET
from coassist.registry import Registry, unknown_name_message
from coassist.robot.worlds import POINT_MASS
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.populations import REPORT_ONLY_POPULATIONS

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
    # The ticks the simulated stages' models are scored on (e_RMS, iterative and transfer): every n-th of each test
    # trial, model and baselines on the same ticks. 1 (every tick) in every preset but ``tiny``, the suite's, whose
    # models see every 25th window in training too: there scoring every tick took 14.9 of the run's 127 profiled
    # CPU-s (docs/performance.md).
    score_stride: int = 1
    # The learned sources of the in-loop ablation (experiments.source_training.LEARNED); the thesis preset
    # adds lstm-hand-alone, whose negative result docs/intent-labels.md records.
    learned_sources: tuple[str, ...] = ("ridge", "ridge-intent", "lstm-tool", "lstm-intent")
    # Training seeds of each LSTM source (the arbitrated ablation cells run every one; the others the first).
    source_seeds: int = 3
    # Calibration trials per application operator for the path-hypotheses source (MG, the handle, the
    # application's task and obstacle): their detours give the person's shape (scenario.path_hypotheses).
    calibration_trials: int = 4
    # The person model's calibration trials per application operator and calibration draw: MG with the probe
    # (controller manual-probe), the handle, the application's task and obstacle, the same first seed as the
    # path hypotheses' (experiments.source_training.calibration_options). Eight, chosen on the eight validation
    # cells (benchmarks/person_filter_cells.py's, 144 paired trials; docs/person-model.md, "Eight probe trials a
    # person"): the person model met force >= 85 % and overshoot >= 70 % with its lower bound >= 40 % in 3 of the
    # 8 cells with 4 trials, 5 with 6, 7 with 8 and 6 with 10 (issue 40 allows a lab 10).
    person_calibration_trials: int = 8
    # The most trials a person's calibration then adds, asking for a way round shown in fewer than FEW_PATHS
    # (scenario.path_model) of its person_calibration_trials but at least once (what coassist calibrate advises a
    # lab: experiments.person_calibration.ways_to_ask); the asked trials' paths join that way's, the ways' prior
    # counts only the chosen ones. 0: none asked (the calibration as before). Two: with eight probe trials a person
    # stays within the 10 issue 40 allows a lab. On the eight validation cells (benchmarks/person_filter_cells.py
    # --asked-trials 2 --paired-with, 144 paired trials; 53 trials asked in 37 of the 72 calibrations) against none:
    # overshoot -0.000 [-0.030, +0.029] mm, hand force -0.013 [-0.024, -0.002] N, jerk -0.001 [-0.004, +0.002] m/s³
    # (docs/person-model.md, "Asking for a way shown too seldom").
    person_calibration_asked: int = 2
    # Calibrations of each operator's person model in the point-mass, held-out and MuJoCo cells (issue 40; on the
    # MuJoCo UR5 draw k's probe trials are the point-mass draw k's, driven on the arm): each on its
    # own person_calibration_trials probe trials, the trial of seed s meeting draw s mod calibration_draws, and the
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
    # zero); four did on five of the six (docs/person-model.md): a count chosen on the report's own seeds, which the
    # report says. A MuJoCo trial is 0.5–1.4 CPU-s: eight add about 170 CPU-s to a run against one, four about 96.
    ablation_mujoco_trials: int = 8
    # The held-out population's cells of the ablation (experiments.ablation): trials per operator and
    # object (application_users of the held-out population); 0 leaves them out.
    held_out_trials: int = 8
    # Which people of the held-out population the report meets: its population seed (scenario.populations). 0, the
    # default: the three operators every report so far has met, whose families and arms three of the person model's
    # settings were chosen while seeing (docs/person-model.md, "What the held-out cells were told"). Another seed
    # draws three new people of the same families, whom no choice has seen: `coassist reproduce --held-out-people N`
    # (the population seed of held_out_population's people, below).
    held_out_people: int = 0
    # Whose families the held-out cells meet: "held-out" (Corrective, Hesitant; every report's) or "unseen" (Feint,
    # Ringing: families made after every choice of the person model and its evaluation, report only). The cells'
    # seeds are the same either way; only the people differ.
    held_out_population: str = "held-out"
    # The sources the MuJoCo UR5 runs (empty: every source of the point-mass cells). The claims read the
    # application's source, the person model and every world's default without a calibration (present-held)
    # against MG there, and the LSTM and the oracle put them in context. The full and thesis presets run
    # every source.
    mujoco_sources: tuple[str, ...] = ("lstm-intent", DEFAULT_INTENT, "paths", "person", "oracle")
    # Where the person model of the MuJoCo UR5's cells is calibrated: "mujoco", on the arm it assists, as a lab
    # would (the point-mass cells' probe trials driven there: person_calibration_trials per operator and
    # calibration draw, 24 × 4 trials in the default preset; 12 took ~8 CPU-s; told the arm's rigid board,
    # experiments.ablation.mujoco_person_filter); "point-mass", the
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
            "score_stride",
            "real_stride",
            "transfer_trials",
            "test_trials",
            "application_trials",
            "real_epochs",
            "workers",
            "threads",
            "source_seeds",
            "calibration_trials",
            "person_calibration_trials",
            "calibration_draws",
        ):
            v = getattr(self, name)
            if not is_integer(v) or v < 1:
                raise ValueError(f"reproduce.{name} must be an integer >= 1, got {v!r}")
        if not is_integer(self.person_calibration_asked) or not 0 <= self.person_calibration_asked <= 8:
            raise ValueError(
                f"reproduce.person_calibration_asked must be an integer 0 to 8, got {self.person_calibration_asked!r}"
            )
        if self.calibration_draws > 8:
            raise ValueError(f"reproduce.calibration_draws must be 1 to 8, got {self.calibration_draws}")
        if not is_integer(self.ablation_mujoco_trials) or self.ablation_mujoco_trials < 0:
            raise ValueError(
                f"reproduce.ablation_mujoco_trials must be an integer >= 0, got {self.ablation_mujoco_trials!r}"
            )
        if not is_integer(self.held_out_trials) or self.held_out_trials < 0:
            raise ValueError(f"reproduce.held_out_trials must be an integer >= 0, got {self.held_out_trials!r}")
        if not is_integer(self.held_out_people) or self.held_out_people < 0:
            raise ValueError(f"reproduce.held_out_people must be an integer >= 0, got {self.held_out_people!r}")
        if self.held_out_population not in REPORT_ONLY_POPULATIONS:
            raise ValueError(
                f"reproduce.held_out_population must be one of {REPORT_ONLY_POPULATIONS} (no population a setting "
                f"is chosen on), got {self.held_out_population!r}"
            )
        if self.ablation_mujoco_trials > self.application_trials:
            raise ValueError(
                f"reproduce.ablation_mujoco_trials ({self.ablation_mujoco_trials}) must be <= "
                f"reproduce.application_trials ({self.application_trials}): its trials are theirs"
            )
        if self.transfer_trials < 3:
            raise ValueError(f"reproduce.transfer_trials must be >= 3 (one per task), got {self.transfer_trials}")
        if isinstance(self.skip_alpha, bool) or not (
            isinstance(self.skip_alpha, (int, float)) and self.skip_alpha >= 0
        ):
            raise ValueError(f"reproduce.skip_alpha must be a number >= 0, got {self.skip_alpha!r}")
        if isinstance(self.tol, bool) or not isinstance(self.tol, (int, float)) or not self.tol > 0:
            raise ValueError(f"reproduce.tol must be > 0, got {self.tol!r}")
        if (
            not isinstance(self.new_users, tuple)
            or not self.new_users
            or any(not is_integer(u) or u < 1 for u in self.new_users)
        ):
            raise ValueError(f"reproduce.new_users must be user indices >= 1 (0 is the author), got {self.new_users!r}")
        if (
            not isinstance(self.application_users, tuple)
            or not self.application_users
            or any(not is_integer(u) or u < 0 for u in self.application_users)
        ):
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
        self._check_names()

    def _check_names(self) -> None:
        """The names and numbers a stage reads late: a typo in them failed minutes into a run (review, 2026-12-06)."""
        import math

        from coassist.config import CONTROL_PRESETS
        from coassist.scenario.tasks import TASKS  # (imported here: tasks' own registry is built after this module)

        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"reproduce.name must be a non-empty string, got {self.name!r}")
        for field, value in (("control_preset", self.control_preset), ("application_preset", self.application_preset)):
            if value not in CONTROL_PRESETS:
                raise ValueError(
                    f"reproduce.{field} {unknown_name_message(str(value), CONTROL_PRESETS, 'control preset')}"
                )
        if self.application_task not in TASKS:
            raise ValueError(
                f"reproduce.application_task {unknown_name_message(str(self.application_task), TASKS, 'task')}"
            )
        for field in ("intent_preset", "real_intent_preset", "device"):
            if not isinstance(getattr(self, field), str) or not getattr(self, field):
                raise ValueError(f"reproduce.{field} must be a non-empty string, got {getattr(self, field)!r}")
        # the model presets a stage builds its networks from: a typo failed minutes in, at the first training
        from coassist.intent.presets import MODEL_PRESETS

        for field in ("intent_preset", "real_intent_preset"):
            if getattr(self, field) not in MODEL_PRESETS:
                raise ValueError(
                    f"reproduce.{field} "
                    f"{unknown_name_message(getattr(self, field), MODEL_PRESETS, 'intent-model preset')}"
                )
        if not (self.device in ("cpu", "mps") or re.fullmatch(r"cuda(:\d+)?", self.device)):
            raise ValueError(f"reproduce.device must be cpu, cuda, cuda:<n> or mps, got {self.device!r}")
        for field in ("tol", "skip_alpha", "sweep_duration"):
            v = getattr(self, field)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"reproduce.{field} must be a finite number, got {v!r}")
        if not self.sweep_duration > 0:
            raise ValueError(f"reproduce.sweep_duration must be > 0 (s), got {self.sweep_duration!r}")
        if self.real_data is not None and (not isinstance(self.real_data, str) or not self.real_data):
            raise ValueError(f"reproduce.real_data must be a folder (a string) or None, got {self.real_data!r}")


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
            score_stride=25,
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
            person_calibration_trials=1,
            # one probe trial a person shows every way it takes once: too seldom; the tiny run asks for none
            person_calibration_asked=0,
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
    entry_type=ReproduceConfig,
)
