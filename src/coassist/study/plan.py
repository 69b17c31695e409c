"""A study is a file: the TOML plan of ``coassist study``, read into frozen, validated dataclasses.

Every error is one :class:`PlanError` line naming the field as written in the plan
(``trials.per_condition must be an integer >= 1, got 0``; an unknown key gets a "did you
mean"), so ``coassist study init`` can print it as it is. The plan of a comparison::

    [study]
    name = "comparison"
    protocol = "comparison"        # comparison | iterative | transfer | online
    world = "play"                 # play (the page) | mujoco (UR5 in MuJoCo) | ur | franka (a real arm)
    participants = 4               # planned: the balanced Latin square is filled in this many rows
    seed = 0
    population = "thesis"          # who --simulate's participants are: thesis | varied | held-out

    [[condition]]                  # comparison: two or more; shown on the page as A, B, C…
    name = "assistive"
    controller = "cooperative"     # coassist.control.presets.CONTROLLERS
    intent = "present-held"        # a named source a person can run (present-held, the default; nominal,
                                   # present, paths, …), calibrated, or a folder: a model, a calibration
    [[condition]]
    name = "impedance"
    controller = "impedance"
    [[condition]]
    name = "manual"
    controller = "manual"

    [trials]
    tasks = ["linear", "curved", "sinusoidal"]   # measured trial j follows tasks[j mod n]
    per_condition = 3
    practice = 1                   # practice trials before each condition's (not analysed)

    [rest]
    between_conditions = 60.0      # [s]

    [questionnaire]                # after each condition
    tlx = true                     # raw NASA-TLX, six items 0-100
    likert = ["helped me", "I felt in control", "the motion was smooth", "I trusted it"]
    likert_points = 7

The other protocols add one table each (``[iterative]``, ``[transfer]``, ``[online]``)
and ``[training]``, the options of ``coassist train`` the study's models are trained with
(docs/study.md). Any protocol may open with a calibration block::

    [calibration]                  # manual guidance with small known pushes (controller manual-probe)
    trials = 9                     # 1 … 10 (default 3 a task); then the participant's person model is fitted
    asked = 1                      # then up to this many trials asking for a way shown too seldom (default 0)

after which a condition's ``intent = "calibrated"`` is that participant's own person model
(:mod:`coassist.study.calibration`); an iterative study may refit it between rounds
(``[iterative] source = "calibrated"``), a transfer or online study compare it too
(``compare_calibrated = true``). Nothing personal goes into a plan: participants are pseudonymous ids
given at run time, of the form ``[study] id_pattern`` sets (:mod:`coassist.study.ids`).

Every number has the range a study can use, upper bound included (a trial of 10⁷ s, a rest
of 10³⁰⁰ s or 10⁹ epochs are typos that would block a participant hours in, not plans), and
the fields that depend on each other are checked together (a time limit that leaves no time
to dwell in the target). What needs the models and the machine (a model's horizon against
the stop criterion, its label, the session's time and memory) is
:mod:`coassist.study.preflight`'s, run by ``coassist study init``.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coassist._checks import is_integer, is_real_number
from coassist.config import APPLICATION_PRESET, CONTROL_PRESETS
from coassist.control.presets import CONTROLLERS, INTENT_FREE_CONTROLLERS
from coassist.errors import CoassistError
from coassist.registry import unknown_name_message
from coassist.robot.drive import MAX_TIME_LIMIT
from coassist.robot.worlds import PLAY, WORLDS, study_worlds
from coassist.runtime.episode import DWELL
from coassist.scenario import intent_registry
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.objects import OBJECTS
from coassist.scenario.populations import POPULATIONS
from coassist.scenario.tasks import MOTION_TIME_RANGE, OBSTACLES, TASKS, task_for_seed
from coassist.study.ids import DEFAULT_ID_PATTERN, IdError, compile_id_pattern

__all__ = [
    "CALIBRATED",
    "PROTOCOLS",
    "is_real_arm",
    "study_worlds",
    "CalibrationPlan",
    "Condition",
    "IterativePlan",
    "OnlinePlan",
    "PlanError",
    "QuestionnairePlan",
    "RestPlan",
    "StudyPlan",
    "TrainingPlan",
    "TransferPlan",
    "TrialsPlan",
    "load_plan",
    "parse_plan",
    "person_intents",
    "plan_from_text",
]

PROTOCOLS = ("comparison", "iterative", "transfer", "online")
# The worlds a plan may name are coassist.robot.worlds.study_worlds() (re-exported here), read
# when a plan is parsed: PLAY (the page's point mass, the browser as the hand), mujoco (the UR5 in
# MuJoCo: the page as the hand, or a simulated participant), ur and franka (a real arm through
# ``coassist drive``), and any world registered in coassist.robot.worlds.WORLDS since.


def is_real_arm(world: str) -> bool:
    """Whether the plan's ``world`` is a real arm (a person, or a simulator behind its address, holds
    it): an arm world of :data:`coassist.robot.worlds.WORLDS` that is not simulated (ur, franka)."""
    entry = WORLDS[world]
    return entry.is_arm and not entry.simulated


#: The Likert items of the issue (thesis' journal version asked the participants these).
DEFAULT_LIKERT = ("helped me", "I felt in control", "the motion was smooth", "I trusted it")
#: Folder names the study keeps for itself inside a participant's folder (and ``calibration-*``, a
#: calibration block run again).
RESERVED_NAMES = frozenset({"practice", "models", "answers", "transfer-set", "adaptation", "calibration", "calibrated"})
#: A condition's ``intent`` that names the participant's own person model, fitted after the plan's
#: calibration block (not a source of the intent registry: each participant has their own).
CALIBRATED = "calibrated"
#: The most calibration trials a participant gives (issue 40: a lab calibrates in at most 10).
CALIBRATION_TRIALS_MAX = 10
#: [m] the widest target ball a plan may set: a fifth of the 0.5 m from every task's start to its target (the thesis'
#: 2.5 cm is a twentieth); wider, the tool is "in the target" from early in the motion
ARRIVE_RADIUS_MAX = 0.1
#: What an iterative study's rounds assist with: the network of Algorithm 4.1, or the person model.
ITERATIVE_SOURCES = ("network", CALIBRATED)
_NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,31}")  # matched whole (fullmatch: "$" would let a trailing newline by)
_STUDY_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")
# INTENT_FREE_CONTROLLERS (coassist.control.presets): two conditions of one that differ only in the intent are refused
_MAX_CONDITIONS = 26  # labelled A … Z
#: The ranges of the plan's numbers a study can use (module docstring), [s] unless said.
DWELL_RANGE = (0.0, 30.0)  # (open below) the thesis' arm trials dwell 5 s
REST_BETWEEN_CONDITIONS_MAX = 3600.0  # an hour's break is the most a session holds
REST_BETWEEN_TRIALS_MAX = 600.0
TOLERANCE_MAX = 1.0  # [m] the stop criterion's: a metre is no criterion at all
CRITERION_HORIZON_MAX = 1000  # samples (the models' horizon bounds it further: study.preflight)
MAX_SEED = 2**31 - 1  # seeds of trials are 10⁶·seed + …: they stay within int64
#: [training]'s: a network a study's background process trains within a rest (study.preflight
#: estimates the time and memory of what these allow).
EPOCHS_MAX = 1000
BATCH_SIZE_MAX = 65536
LAYERS_MAX = 8
WIDTH_MAX = 4096  # an LSTM's hidden size, an FC layer's width
FC_LAYERS_MAX = 8
LR_MAX = 10.0


class PlanError(CoassistError, ValueError):
    """A study plan that cannot be run; the text is one line naming the field."""


# ----------------------------------------------------------------------------- field checks


def _int(value: Any, name: str, lo: int, hi: int) -> int:
    if not is_integer(value) or value < lo or value > hi:
        raise PlanError(f"{name} must be an integer in {lo} … {hi}, got {value!r}")
    return int(value)


def _seconds(value: Any, name: str, lo: float, hi: float, *, open_lo: bool = False) -> float:
    """A number of seconds in [lo, hi] (``open_lo``: (lo, hi]); a string, bool, NaN or inf is refused."""
    if not is_real_number(value) or not math.isfinite(value) or value > hi or value < lo or (open_lo and value == lo):
        raise PlanError(
            f"{name} must be a number of seconds in {'(' if open_lo else '['}{lo:g}, {hi:g}], got {value!r}"
        )
    return float(value)


def _number(value: Any, name: str, what: str, ok) -> float:
    if not is_real_number(value) or not math.isfinite(value) or not ok(value):
        raise PlanError(f"{name} must be a finite number {what}, got {value!r}")
    return float(value)


def _choice(value: Any, name: str, choices, what: str) -> str:
    if not isinstance(value, str) or value not in choices:
        raise PlanError(f"{name}: {unknown_name_message(str(value), choices, what)}")
    return value


def _bool(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise PlanError(f"{name} must be true or false, got {value!r}")
    return value


def _table(data: Mapping[str, Any], key: str, fields: tuple[str, ...], where: str = "") -> dict[str, Any]:
    """``data[key]`` as a table whose keys are all in ``fields`` (else one line naming the unknown key)."""
    name = f"{where}{key}"
    value = data.get(key, {})
    if not isinstance(value, Mapping):
        raise PlanError(f"{name} must be a table ([{name}]), got {type(value).__name__}")
    for k in value:
        if k not in fields:
            raise PlanError(f"{name}.{k}: {unknown_name_message(k, fields, 'field')}")
    return dict(value)


def _model_path(value: Any, name: str, base: Path) -> str:
    """A model folder named in the plan, relative to the plan's folder: its absolute path, checked now."""
    marker = intent_registry.INTENT_FOLDERS["model"].marker
    if not isinstance(value, str) or not value:
        raise PlanError(f"{name} must be a model folder written by coassist train, got {value!r}")
    path = Path(value) if Path(value).is_absolute() else base / value
    if not (path / marker).is_file():
        raise PlanError(f"{name}: {value!r} is not a model folder (no {marker} in {path})")
    return str(path.resolve())


def person_intents() -> tuple[str, ...]:
    """The named intent sources a person's trial can use: every entry of
    :data:`coassist.scenario.intent_registry.INTENT_SOURCES` that is not simulation-only, read
    when called (a source registered there is one, with nothing to change here)."""
    return tuple(n for n, e in intent_registry.INTENT_SOURCES.items() if not e.simulation_only)


def _intent(value: Any, name: str, base: Path) -> str:
    """A condition's intent source: a name of :func:`person_intents`, or the absolute path of a folder of a
    kind in :data:`~coassist.scenario.intent_registry.INTENT_FOLDERS` (a model, a calibration), by its marker."""
    sources, folders = intent_registry.INTENT_SOURCES, intent_registry.INTENT_FOLDERS
    markers = " or ".join(kind.marker for kind in folders.values())
    choices = (
        f"a source a person can run ({', '.join(person_intents())}), {CALIBRATED!r} (the participant's own "
        f"person model) or a folder with {markers}"
    )
    if value == CALIBRATED:  # checked against [calibration] once the whole plan is read
        return value
    if isinstance(value, str) and value in sources:
        if sources[value].simulation_only:
            raise PlanError(f"{name}: {value!r} is {sources[value].summary}, which a person has not; use {choices}")
        return value
    if not isinstance(value, str) or not value:
        raise PlanError(f"{name} must be {choices}, got {value!r}")
    path = Path(value) if Path(value).is_absolute() else base / value
    if intent_registry.intent_folder_kind(str(path)) is None:
        raise PlanError(f"{name}: {value!r} is not {choices} (none in {path})")
    return str(path.resolve())


# ----------------------------------------------------------------------------- the tables


@dataclass(frozen=True)
class Condition:
    """One condition under test: its name (researcher-side only), the controller kind and its intent source.

    name : letters, digits, ``-``, ``_`` (it names the condition's folder; the page never sees it).
    controller : one of :data:`coassist.control.presets.CONTROLLERS`.
    intent : a name of :func:`person_intents` (``"nominal"``, ``"paths"``, …) or the absolute path of a
        folder of a kind in :data:`~coassist.scenario.intent_registry.INTENT_FOLDERS` (a model, a calibration).
        A plan that gives none: :data:`~coassist.scenario.assistance.DEFAULT_INTENT` for a controller that reads
        it (what every arm command assists with; ``nominal``, the plan, needs more hand force than MG), ``nominal``
        for one that does not (:data:`INTENT_FREE_CONTROLLERS`: only its logged prediction is the source's).
    """

    name: str
    controller: str
    intent: str = "nominal"


@dataclass(frozen=True)
class CalibrationPlan:
    """The calibration block, before anything else in every protocol: ``trials`` trials (1 … 10) under
    manual guidance with the calibration probe (controller ``manual-probe``: small known pushes that
    measure the person's arm), following the plan's tasks in turn; then the participant's person model
    is fitted from them (:mod:`coassist.study.calibration`). Every task needs one trial at least; a plan
    that does not say gets :func:`default_calibration_trials`.

    ``asked``: then, where the fit shows a way round the obstacle in fewer than
    :data:`~coassist.scenario.path_model.FEW_PATHS` of a task's paths (but once at least), up to this many more
    trials in which the page asks the participant to go round that way, and the person model is fitted again from
    all of them (the asked trials' paths join that way's, its prior stays the participant's own choices;
    :func:`~coassist.experiments.person_calibration.ways_to_ask`). At most ``10 − trials``; 0 (the default): none."""

    trials: int
    asked: int = 0


#: Calibration paths a task when the plan does not say: with two (the small obstacle moving between trials) the
#: person model overshot up to 1.4 × MG's where the two went round on either side; with three 0.60–0.86 ×, four
#: 0.60–1.05 × (thesis users 0–2, six trials each: benchmarks/calibration_paths.py, docs/person-model.md).
CALIBRATION_PATHS_PER_TASK = 3


def default_calibration_trials(tasks: tuple[str, ...]) -> int:
    """The calibration trials of a plan that does not say: :data:`CALIBRATION_PATHS_PER_TASK` for each distinct task,
    at most :data:`CALIBRATION_TRIALS_MAX` (the plan's three default tasks: 9)."""
    return min(CALIBRATION_TRIALS_MAX, CALIBRATION_PATHS_PER_TASK * len(dict.fromkeys(tasks)))


@dataclass(frozen=True)
class TrialsPlan:
    """The trials of every block.

    tasks : the paths, measured trial j follows ``tasks[j mod n]`` (the same j in every condition:
        conditions meet the same tasks and obstacles, so they are paired).
    per_condition : measured trials per condition (comparison and the comparison phase of transfer/online).
    practice : practice trials before each condition's measured ones (kept, not analysed).
    object : carried object (arm worlds; the page's world has the handle only).
    obstacle : ``small`` (the evaluation's box) or ``large`` (the application's).
    motion_time : [s] planned motion time of every path (play world only; None: the thesis' per path).
    dwell : [s] in the target ball that ends a trial (play world; the arm worlds dwell 5 s).
    arrive_radius : [m] the target ball (σ's ε).
    time_limit : [s] per trial; None: 2 × the plan's end + 10 s.
    preset : control preset (:data:`coassist.config.CONTROL_PRESETS`).
    """

    tasks: tuple[str, ...] = ("linear", "curved", "sinusoidal")
    per_condition: int = 3
    practice: int = 1
    object: str = "handle"
    obstacle: str = "small"
    motion_time: float | None = None
    dwell: float = 3.0
    arrive_radius: float = 0.025
    time_limit: float | None = None
    preset: str = APPLICATION_PRESET


@dataclass(frozen=True)
class RestPlan:
    """Rests [s]: between conditions (and rounds), and between trials."""

    between_conditions: float = 60.0
    between_trials: float = 0.0


@dataclass(frozen=True)
class QuestionnairePlan:
    """What the page asks after each condition: raw NASA-TLX (six items 0–100) and Likert items."""

    tlx: bool = True
    likert: tuple[str, ...] = DEFAULT_LIKERT
    likert_points: int = 7

    @property
    def asked(self) -> bool:
        return self.tlx or bool(self.likert)


@dataclass(frozen=True)
class TrainingPlan:
    """The options of ``coassist train`` the study's models are trained with (the same names).

    preset : an intent-model preset.  epochs, lr, batch_size, seed, threads, test_fraction,
    optimizer : as ``coassist train``'s options (None: the preset's).  layers, hidden, fc :
    the network's sizes (a model trained from scratch only).
    """

    preset: str = "default"
    epochs: int | None = None
    lr: float | None = None
    batch_size: int | None = None
    seed: int | None = None
    threads: int | None = 1
    test_fraction: float | None = None
    optimizer: str | None = None
    layers: int | None = None
    hidden: int | None = None
    fc: tuple[int, ...] | None = None


@dataclass(frozen=True)
class IterativePlan:
    """Algorithm 4.1 with a person: round k collects ``trials_per_round`` with M_{k−1} in the loop
    (round 0: the nominal plan), M_k trains in the background while the participant rests.

    rounds : the most rounds.  tolerance : [m] the stop criterion of eq. 4.13 on the in-loop
    e_RMS at ``criterion_horizon`` samples.  stop_at_criterion : end the study once it is met.
    controller : the controller the models assist.  source : ``"network"`` (Algorithm 4.1's: round 0
    with the nominal plan, M_k trained) or ``"calibrated"`` (round 0 with the person model of the
    calibration block, P_{k+1} refitted after round k from the calibration's and the rounds' trials).
    """

    rounds: int = 3
    trials_per_round: int = 6
    tolerance: float = 1e-3
    criterion_horizon: int = 50
    stop_at_criterion: bool = True
    controller: str = "cooperative"
    source: str = "network"


@dataclass(frozen=True)
class TransferPlan:
    """Algorithm 4.2 with a new participant: ``trials`` with the source model in the loop, the
    frozen-LSTM transfer trained on them in the background, then the transferred model against
    the source model (blinded, counterbalanced, ``[trials]`` per condition); ``compare_calibrated``:
    the participant's person model (the calibration block's) as a third condition."""

    source_model: str
    trials: int = 15
    controller: str = "cooperative"
    compare_calibrated: bool = False


@dataclass(frozen=True)
class OnlinePlan:
    """Online adaptation (thesis ch. 6): ``trials`` with the model in the loop while its FC head is
    updated (frozen-LSTM transfer from ``source_model`` on the participant's trials so far) in a
    background process after each trial; a trial takes the newest model ready when it starts,
    never waiting. Then the last online model against the offline transfer on the same trials
    (``compare_calibrated``: and the participant's person model)."""

    source_model: str
    trials: int = 15
    controller: str = "cooperative"
    compare_calibrated: bool = False


@dataclass(frozen=True)
class StudyPlan:
    """The whole plan (module docstring); folder paths in it are absolute (relative in the file: to its folder).

    id_pattern : the regular expression a person's id must match whole (:mod:`coassist.study.ids`).
    """

    name: str
    protocol: str
    world: str
    participants: int
    seed: int
    conditions: tuple[Condition, ...]
    id_pattern: str = DEFAULT_ID_PATTERN
    trials: TrialsPlan = field(default_factory=TrialsPlan)
    rest: RestPlan = field(default_factory=RestPlan)
    questionnaire: QuestionnairePlan = field(default_factory=QuestionnairePlan)
    training: TrainingPlan | None = None
    iterative: IterativePlan | None = None
    transfer: TransferPlan | None = None
    online: OnlinePlan | None = None
    #: who ``--simulate``'s participants are (:data:`coassist.scenario.populations.POPULATIONS`)
    population: str = "thesis"
    calibration: CalibrationPlan | None = None

    def intent_folders(self) -> tuple[str, ...]:
        """Every folder the plan names, models and calibrations (their hashes are recorded at ``study init``)."""
        out = [
            c.intent
            for c in self.conditions
            if c.intent not in intent_registry.INTENT_SOURCES and c.intent != CALIBRATED
        ]
        for extra in (self.transfer, self.online):
            if extra is not None:
                out.append(extra.source_model)
        return tuple(dict.fromkeys(out))

    def uses_calibrated(self) -> bool:
        """Whether a condition or the rounds assist with the participant's person model."""
        extra = self.transfer or self.online
        return (
            any(c.intent == CALIBRATED for c in self.conditions)
            or (self.iterative is not None and self.iterative.source == CALIBRATED)
            or (extra is not None and extra.compare_calibrated)
        )

    def task_end(self) -> float:
        """[s] the latest end of a task's planned motion among the plan's tasks (the play world's
        ``motion_time``, or the thesis' per path on an arm)."""
        mt = self.trials.motion_time if self.world == PLAY else None
        return max(float(task_for_seed(kind, 0, motion_time=mt).planner.end_time) for kind in self.trials.tasks)

    def dwell(self) -> float:
        """[s] in the target ball that ends a trial (the arm worlds: ``coassist drive``'s)."""
        return self.trials.dwell if self.world == PLAY else DWELL


_TOP = (
    "study",
    "condition",
    "trials",
    "rest",
    "questionnaire",
    "calibration",
    "training",
    "iterative",
    "transfer",
    "online",
)


def parse_plan(data: Mapping[str, Any], base: str | Path = ".", default_intent: str = DEFAULT_INTENT) -> StudyPlan:
    """The :class:`StudyPlan` of a parsed TOML document; :class:`PlanError` naming the field. ``default_intent``: a
    condition's whose controller reads one and names none (:class:`Condition`); a study folder keeps the one it was
    made with (``nominal`` before it was :data:`~coassist.scenario.assistance.DEFAULT_INTENT`)."""
    base = Path(base)
    for k in data:
        if k not in _TOP:
            raise PlanError(f"{k}: {unknown_name_message(k, _TOP, 'table')}")
    s = _table(data, "study", ("name", "protocol", "world", "participants", "seed", "id_pattern", "population"))
    if "name" not in s:
        raise PlanError("study.name is missing (a short name: letters, digits, - and _)")
    name = s["name"]
    if not isinstance(name, str) or not _STUDY_NAME.fullmatch(name):
        raise PlanError(f"study.name must be 1-64 letters, digits, '-' or '_', got {name!r}")
    protocol = _choice(s.get("protocol", "comparison"), "study.protocol", PROTOCOLS, "protocol")
    world = _choice(s.get("world", PLAY), "study.world", study_worlds(), "study world")
    participants = _int(s.get("participants", 4), "study.participants", 1, 999)
    seed = _int(s.get("seed", 0), "study.seed", 0, MAX_SEED)
    id_pattern = s.get("id_pattern", DEFAULT_ID_PATTERN)
    try:
        compile_id_pattern(id_pattern)
    except IdError as exc:
        raise PlanError(f"study.id_pattern: {exc}") from None
    population = _choice(s.get("population", "thesis"), "study.population", POPULATIONS, "population")

    t = _table(data, "trials", tuple(TrialsPlan.__dataclass_fields__))
    tasks = t.get("tasks", list(TrialsPlan.tasks))
    if not isinstance(tasks, list) or not tasks:
        raise PlanError(f"trials.tasks must be a list of paths from {tuple(TASKS)}, got {tasks!r}")
    tasks = tuple(_choice(v, f"trials.tasks[{i}]", tuple(TASKS), "task") for i, v in enumerate(tasks))
    preset = t.get("preset", APPLICATION_PRESET)
    if not isinstance(preset, str) or preset not in CONTROL_PRESETS:
        raise PlanError(f"trials.preset: {unknown_name_message(str(preset), CONTROL_PRESETS, 'control preset')}")
    obj = _choice(t.get("object", "handle"), "trials.object", tuple(OBJECTS), "object")
    if world == PLAY and obj != "handle":
        raise PlanError(
            f"trials.object must be 'handle' in the play world (the page's robot carries nothing), got {obj!r}"
        )
    motion_time = (
        None if t.get("motion_time") is None else _seconds(t["motion_time"], "trials.motion_time", *MOTION_TIME_RANGE)
    )
    if world != PLAY:  # coassist drive plans the thesis' motion times and ends a trial after 5 s in the 2.5 cm ball
        for key in ("motion_time", "dwell", "arrive_radius"):
            if key in t:
                raise PlanError(
                    f"trials.{key} applies to the play world only (the arm worlds run coassist drive's "
                    "trials: the thesis' motion times, 5 s in the 2.5 cm target ball)"
                )
    trials = TrialsPlan(
        tasks=tasks,
        per_condition=_int(t.get("per_condition", 3), "trials.per_condition", 1, 1000),
        practice=_int(t.get("practice", 1), "trials.practice", 0, 100),
        object=obj,
        obstacle=_choice(t.get("obstacle", "small"), "trials.obstacle", tuple(OBSTACLES), "obstacle"),
        motion_time=motion_time,
        dwell=_seconds(t.get("dwell", 3.0), "trials.dwell", *DWELL_RANGE, open_lo=True),
        arrive_radius=_number(
            t.get("arrive_radius", 0.025),
            "trials.arrive_radius",
            f"in (0, {ARRIVE_RADIUS_MAX}] m (every task's target lies 0.5 m from its start: a wider ball holds the "
            "tool long before the end, and σ, time to target and overshoot measure nothing)",
            lambda v: 0 < v <= ARRIVE_RADIUS_MAX,
        ),
        time_limit=None
        if t.get("time_limit") is None
        else _seconds(t["time_limit"], "trials.time_limit", 0.0, MAX_TIME_LIMIT, open_lo=True),
        preset=preset,
    )

    r = _table(data, "rest", ("between_conditions", "between_trials"))
    rest = RestPlan(
        _seconds(r.get("between_conditions", 60.0), "rest.between_conditions", 0.0, REST_BETWEEN_CONDITIONS_MAX),
        _seconds(r.get("between_trials", 0.0), "rest.between_trials", 0.0, REST_BETWEEN_TRIALS_MAX),
    )

    q = _table(data, "questionnaire", ("tlx", "likert", "likert_points"))
    likert = q.get("likert", list(DEFAULT_LIKERT))
    if not isinstance(likert, list) or len(likert) > 12:
        raise PlanError(f"questionnaire.likert must be a list of at most 12 statements, got {likert!r}")
    for i, item in enumerate(likert):
        if not isinstance(item, str) or not item.strip() or len(item) > 120:
            raise PlanError(f"questionnaire.likert[{i}] must be a statement of 1-120 characters, got {item!r}")
    if len(set(likert)) != len(likert):
        raise PlanError("questionnaire.likert must not repeat a statement")
    questionnaire = QuestionnairePlan(
        _bool(q.get("tlx", True), "questionnaire.tlx"),
        tuple(likert),
        _int(q.get("likert_points", 7), "questionnaire.likert_points", 3, 11),
    )

    conditions = _conditions(data, protocol, base, default_intent)
    calibration = None
    if "calibration" in data:
        cal = _table(data, "calibration", tuple(CalibrationPlan.__dataclass_fields__))
        n = _int(cal.get("trials", default_calibration_trials(tasks)), "calibration.trials", 1, CALIBRATION_TRIALS_MAX)
        missing = [k for k in dict.fromkeys(tasks) if k not in tasks[:n]]
        if missing:
            need = max(tasks.index(k) for k in tasks) + 1
            raise PlanError(
                f"calibration.trials: {n} trials leave {', '.join(map(repr, missing))} of trials.tasks without a "
                f"calibration trial (they follow the tasks in turn): the person model would know no path there; give "
                f"at least {need}"
            )
        asked = _int(cal.get("asked", 0), "calibration.asked", 0, CALIBRATION_TRIALS_MAX - n)
        calibration = CalibrationPlan(n, asked)
    it = _table(data, "iterative", tuple(IterativePlan.__dataclass_fields__)) if protocol == "iterative" else {}
    iterative_source = _choice(it.get("source", "network"), "iterative.source", ITERATIVE_SOURCES, "source")
    trains = protocol in ("transfer", "online") or (protocol == "iterative" and iterative_source == "network")
    training = _training(data) if trains else None
    if protocol == "comparison" and "training" in data:
        raise PlanError("training: a comparison trains no model; leave [training] out")
    if not trains and "training" in data:
        raise PlanError(
            "training: an iterative study of the calibrated person model trains no network (it refits the person "
            "model); leave [training] out"
        )
    iterative = transfer = online = None
    for other in ("iterative", "transfer", "online"):
        if other in data and other != protocol:
            raise PlanError(f"{other}: the plan's protocol is {protocol!r}; leave [{other}] out")
    if protocol == "iterative":
        iterative = IterativePlan(
            rounds=_int(it.get("rounds", 3), "iterative.rounds", 1, 50),
            trials_per_round=_int(it.get("trials_per_round", 6), "iterative.trials_per_round", 1, 1000),
            tolerance=_number(
                it.get("tolerance", 1e-3),
                "iterative.tolerance",
                f"in (0, {TOLERANCE_MAX:g}] m",
                lambda v: 0 < v <= TOLERANCE_MAX,
            ),
            criterion_horizon=_int(
                it.get("criterion_horizon", 50), "iterative.criterion_horizon", 1, CRITERION_HORIZON_MAX
            ),
            stop_at_criterion=_bool(it.get("stop_at_criterion", True), "iterative.stop_at_criterion"),
            controller=_choice(
                it.get("controller", "cooperative"), "iterative.controller", tuple(CONTROLLERS), "controller"
            ),
            source=iterative_source,
        )
        if not iterative.controller.startswith("cooperative"):
            raise PlanError(
                f"iterative.controller must use the model (cooperative or cooperative-arbitrated), got {iterative.controller!r}"
            )
    elif protocol in ("transfer", "online"):
        tab = _table(data, protocol, ("source_model", "trials", "controller", "compare_calibrated"))
        if "source_model" not in tab:
            raise PlanError(f"{protocol}.source_model is missing (the model the participant starts from)")
        source = _model_path(tab["source_model"], f"{protocol}.source_model", base)
        n = _int(tab.get("trials", 15), f"{protocol}.trials", 2, 1000)
        controller = _choice(
            tab.get("controller", "cooperative"), f"{protocol}.controller", tuple(CONTROLLERS), "controller"
        )
        if not controller.startswith("cooperative"):
            raise PlanError(
                f"{protocol}.controller must use the model (cooperative or cooperative-arbitrated), got {controller!r}"
            )
        compare = _bool(tab.get("compare_calibrated", False), f"{protocol}.compare_calibrated")
        if protocol == "transfer":
            transfer = TransferPlan(source, n, controller, compare)
        else:
            online = OnlinePlan(source, n, controller, compare)
    plan = StudyPlan(
        name=name,
        protocol=protocol,
        world=world,
        participants=participants,
        seed=seed,
        conditions=conditions,
        id_pattern=id_pattern,
        trials=trials,
        rest=rest,
        questionnaire=questionnaire,
        training=training,
        iterative=iterative,
        transfer=transfer,
        online=online,
        population=population,
        calibration=calibration,
    )
    if plan.uses_calibrated() and calibration is None:
        where = next(
            (f"condition[{i}].intent" for i, c in enumerate(conditions) if c.intent == CALIBRATED),
            "iterative.source" if protocol == "iterative" else f"{protocol}.compare_calibrated",
        )
        raise PlanError(
            f"{where}: {CALIBRATED!r} is the participant's own person model, fitted from their calibration trials; "
            "add the block that records them: [calibration] trials = 1 … 10"
        )
    _check_trial_time(plan, "time_limit" in t)
    return plan


def _check_trial_time(plan: StudyPlan, limit_given: bool) -> None:
    """A trial must be able to end in the target: its time limit covers the longest task's planned motion
    and the dwell after it (else every trial runs to its limit, or, for a limit under a tick, fails)."""
    end, dwell = plan.task_end(), plan.dwell()
    limit = plan.trials.time_limit if plan.trials.time_limit is not None else 2.0 * end + 10.0
    if limit < end + dwell:
        field = "trials.time_limit" if limit_given else "trials.dwell"
        raise PlanError(
            f"{field}: a time limit of {limit:g} s leaves no time to dwell {dwell:g} s in the target after the "
            f"longest task's planned motion ({end:g} s): no trial could end in the target; give time_limit >= "
            f"{end + dwell:g} s or a shorter dwell"
        )


def _conditions(
    data: Mapping[str, Any], protocol: str, base: Path, default_intent: str = DEFAULT_INTENT
) -> tuple[Condition, ...]:
    raw = data.get("condition", [])
    if protocol != "comparison":
        if raw:
            raise PlanError(f"condition: the {protocol} protocol sets its own conditions; leave [[condition]] out")
        return ()
    if not isinstance(raw, list) or len(raw) < 2:
        raise PlanError("condition: a comparison needs two or more [[condition]] tables")
    if len(raw) > _MAX_CONDITIONS:
        raise PlanError(f"condition: at most {_MAX_CONDITIONS} conditions (labelled A … Z), got {len(raw)}")
    out = []
    for i, c in enumerate(raw):
        where = f"condition[{i}]"
        if not isinstance(c, Mapping):
            raise PlanError(f"{where} must be a table ([[condition]]), got {type(c).__name__}")
        for k in c:
            if k not in ("name", "controller", "intent"):
                raise PlanError(f"{where}.{k}: {unknown_name_message(k, ('name', 'controller', 'intent'), 'field')}")
        name = c.get("name")
        if (
            not isinstance(name, str)
            or not _NAME.fullmatch(name)
            or name in RESERVED_NAMES
            or name.startswith(("round-", "calibration-"))
        ):
            raise PlanError(
                f"{where}.name must be 1-32 lower-case letters, digits, '-' or '_' (not one of "
                f"{sorted(RESERVED_NAMES)}, round-* or calibration-*), got {name!r}"
            )
        controller = _choice(c.get("controller"), f"{where}.controller", tuple(CONTROLLERS), "controller")
        # no intent given: what the arm commands assist with, never the plan (which a person pushes against); a
        # controller that reads none logs the plan's rows, as before
        unsaid = "nominal" if controller in INTENT_FREE_CONTROLLERS else default_intent
        intent = _intent(c.get("intent", unsaid), f"{where}.intent", base)
        out.append(Condition(name, controller, intent))
    names = [c.name for c in out]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise PlanError(f"condition: the name {dup!r} is used twice")
    # what the person gets: a controller that reads no intent moves the same whatever the source (only the logged
    # prediction, and its e_RMS, differ): two such conditions are one condition under two names for the person
    felt = [(c.controller, None if c.controller in INTENT_FREE_CONTROLLERS else c.intent) for c in out]
    for j, key in enumerate(felt):
        i = felt.index(key)
        if i == j:
            continue
        if out[i].intent == out[j].intent:
            raise PlanError("condition: two conditions have the same controller and intent (nothing to compare)")
        raise PlanError(
            f"condition[{i}] and condition[{j}] give the person the same motion: controller {key[0]!r} reads no "
            f"intent ({out[i].intent!r} and {out[j].intent!r} differ only in the prediction logged); keep one, or "
            f"use a controller that reads it ({', '.join(k for k in CONTROLLERS if k not in INTENT_FREE_CONTROLLERS)})"
        )
    return tuple(out)


def _training(data: Mapping[str, Any]) -> TrainingPlan:
    from coassist.intent.presets import MODEL_PRESETS, OPTIMIZERS  # the learn extra, only for a plan that trains

    tr = _table(data, "training", tuple(TrainingPlan.__dataclass_fields__))
    preset = tr.get("preset", "default")
    if not isinstance(preset, str) or preset not in MODEL_PRESETS:
        raise PlanError(f"training.preset: {unknown_name_message(str(preset), MODEL_PRESETS, 'intent-model preset')}")

    def opt_int(key: str, lo: int, hi: int) -> int | None:
        return None if tr.get(key) is None else _int(tr[key], f"training.{key}", lo, hi)

    fc = tr.get("fc")
    if fc is not None:
        if (
            not isinstance(fc, list)
            or len(fc) > FC_LAYERS_MAX
            or not all(is_integer(v) and 1 <= v <= WIDTH_MAX for v in fc)
        ):
            raise PlanError(
                f"training.fc must be a list of at most {FC_LAYERS_MAX} layer widths in 1 … {WIDTH_MAX}, got {fc!r}"
            )
        fc = tuple(int(v) for v in fc)
    optimizer = tr.get("optimizer")
    if optimizer is not None:
        optimizer = _choice(optimizer, "training.optimizer", OPTIMIZERS, "optimiser")
    lr = tr.get("lr")
    tf = tr.get("test_fraction")
    return TrainingPlan(
        preset=preset,
        epochs=opt_int("epochs", 1, EPOCHS_MAX),
        batch_size=opt_int("batch_size", 1, BATCH_SIZE_MAX),
        seed=opt_int("seed", 0, 2**32 - 1),
        threads=_int(tr.get("threads", 1), "training.threads", 1, 256),
        layers=opt_int("layers", 0, LAYERS_MAX),
        hidden=opt_int("hidden", 1, WIDTH_MAX),
        fc=fc,
        optimizer=optimizer,
        lr=None if lr is None else _number(lr, "training.lr", f"in (0, {LR_MAX:g}]", lambda v: 0 < v <= LR_MAX),
        test_fraction=None if tf is None else _number(tf, "training.test_fraction", "in [0, 1)", lambda v: 0 <= v < 1),
    )


def load_plan(path: str | Path, default_intent: str = DEFAULT_INTENT) -> StudyPlan:
    """Read and validate the plan file ``path`` (:class:`PlanError` for a file that is not a plan);
    ``default_intent``: :func:`parse_plan`'s."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise PlanError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise PlanError(f"{path}: is a folder; give the plan's .toml file") from None
    except UnicodeDecodeError:
        raise PlanError(f"{path}: not UTF-8 text") from None
    return plan_from_text(text, path.parent, default_intent)


def plan_from_text(text: str, base: str | Path, default_intent: str = DEFAULT_INTENT) -> StudyPlan:
    """The plan of TOML ``text`` whose relative model paths are relative to ``base``; ``default_intent``:
    :func:`parse_plan`'s."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise PlanError(f"not TOML: {exc}") from None
    return parse_plan(data, base, default_intent)
