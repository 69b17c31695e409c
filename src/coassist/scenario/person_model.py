"""A person model: what coassist learns of a person from their own calibration trials, and its folder.

Fitted from what a lab records with an arm — the tool's positions and velocities, the wrench
at the sensor, the robot's effort and the nominal plan — of a few trials per person under
manual guidance with the probe (controller ``manual-probe``), with no intent label and no
obstacle told:

1. the arm, K̂ and Ĉ (:func:`~coassist.scenario.arm_identification.identify_arm`; the typical arm where that
   measurement says too little: :func:`~coassist.scenario.arm_identification.measured_arm`);
2. each trial's intent path, reconstructed with that arm: q = p + (w + Ĉ v)/K̂, smoothed
   (zero-phase, ``smoothing`` Hz) — the path the person pursued, not the one the tool took;
3. the person's paths on the task (:func:`~coassist.scenario.path_model.fit_path_model`), with the
   present estimate's noise σ (the RMS of q less its smoothed self, lateral to the plan);
4. where the calibration flows run it (``coassist calibrate``, a study's block, the main job), whether to lead the
   person along those paths at all (:class:`LeadCheck`, :func:`coassist.sim.person_twin.lead_check`: each trial
   replayed, leave-one-out, against a twin of the person with the measured arm; a person the lead would make
   overshoot more than MG gets the present estimate held).

The folder (``person-model.json``) is one JSON document carrying its own SHA-256
(:func:`coassist._io.write_hashed_json`: a hand edit is refused in one line): per person their arm and, per task
(nominal path), their path model; :func:`read_person_model` gives the intent source. A folder
may name one of its people ``default``: whoever else is at the handle gets that person's model
(a study writes each participant's own folder so: whatever name the world gives them).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from coassist._checks import check_int, check_real
from coassist._io import read_hashed_json, write_hashed_json
from coassist.scenario.arm_identification import ArmEstimate, identify_arm, measured_arm
from coassist.scenario.path_model import (
    ASKED_WAY,
    PathFrame,
    PathModel,
    PathModelSettings,
    check_way,
    fit_path_model,
)
from coassist.scenario.person_intent import PersonFilterSettings, PersonPathsIntent

__all__ = [
    "PERSON_FILTER",
    "INTENT_SMOOTHING",
    "PERSON_MODEL_FILE",
    "LeadCheck",
    "PersonFit",
    "asked_way",
    "fit_people",
    "fit_person",
    "intent_estimate",
    "intent_paths",
    "read_person_model",
    "without_trial",
    "write_person_model",
]

PERSON_MODEL_FILE = "person-model.json"
#: The filter a fitted person model runs with unless told otherwise: the defaults, with the present estimate
#: put 0.06 s ahead (a measured arm's Ĉ holds the person's reaction delay) and taken at the hand point of an
#: object that yaws on its mount. On the validation trials (application_seed(50000), the board, 24 trials, the
#: arbitrated controller) the lead took the force share from 77 to 83 (0.03 s) and 87 % (0.06 s), the overshoot
#: share 46 → 46 / 43 %, the jerk 1.33 → 1.38 / 1.42 × MG; the hand point then took them from 87 % / 54 % / 1.34 ×
#: to 93 % / 91 % [81, 103] / 1.17 ×; the rows low-passed over 0.04 s (their lag advanced away) took them to
#: 91 % / 91 % [80, 104] / 1.07 × on the board and from 87 % / 62 % / 1.18 × to 85 % / 61 % / 1.06 × on the heavy
#: load; 0.08 s took the jerk to MG's but the heavy load's force share to 83 % (docs/person-model.md).
#: On a way the calibration never saw, the present estimate's rows, not the other way's mirror: on the varied
#: population (base 50000, four calibrations) 57 % [6, 90] → 75 % [51, 97] (board) and 73 → 76 % (heavy); on the
#: thesis population's validation trials (every way seen there) only the heavy load's jerk moved, 1.093 → 1.090 ×.
#: The way's evidence by the onset rule, only where the ways' mean paths are 5 mm apart, and the hedge without the
#: tool's sideways velocity: a person still on the plan where their demonstrations had already left it decided
#: a way from noise, and the hedge's extrapolated sideways drift became the robot's push and then evidence
#: (replayed on varied user 7's board trials). On the eight validation cells (thesis and varied, bases 50000 and
#: 60000, both objects, 144 paired trials) the overshoot −0.18 [−0.35, −0.02] mm and the jerk −0.013
#: [−0.025, −0.000] m/s³ against the filter before, the hand force +0.018 [−0.001, +0.036] N; each of the three
#: alone moved neither beyond its interval (docs/person-model.md, "Deciding the way only where the ways part").
#: The dead zone at least 3 σ₀ of the person's calibration noise (2 mm at least, as before): on the eight cells,
#: paired against the filter before, overshoot −0.09 [−0.18, +0.01] mm, hand force −0.004 [−0.011, +0.003] N, jerk
#: −0.005 [−0.013, +0.002] m/s³; trials whose rows ever followed the way the person did not take 15 → 4 of 144
#: (replayed; 2 σ₀ 9, 4 σ₀ 1), the right way decided a median 4 → 6 ticks after the intent is 5 mm off the plan
#: (docs/person-model.md, "A dead zone in the person's own noise").
#: The decided way's rows keep the present estimate's offset across the plan from their curves, fading over
#: residual_time = 0.2 s (the estimate's own error stays correlated about that long): on the same cells against the
#: filter with the dead zone, hand force −0.019 [−0.026, −0.012] N, overshoot +0.03 [−0.04, +0.11] mm, jerk +0.002
#: [−0.000, +0.003] m/s³; 0.4 s: −0.029 [−0.040, −0.018] N, +0.07 [−0.04, +0.17] mm, jerk +0.003 [+0.000, +0.006].
#: The cross-fade from the present estimate's rows to the decided way's over 0.05 s instead of 0.1 s: a decision
#: taken as the person turns (the detour's onset, inside the arc) reaches the robot a few ticks sooner. On the same
#: cells (benchmarks/person_filter_cells.py), against the filter before: overshoot −0.034 [−0.053, −0.015] mm, hand
#: force −0.005 [−0.006, −0.003] N, jerk −0.001 [−0.003, +0.001] m/s³ (0.02 s: −0.037 [−0.081, +0.006] mm, −0.007 N).
#: While undecided and the person leaves their line (the present estimate beyond the dead zone), the hedge rows carry
#: half their progress along the plan (hedge_leaving = 0.5): in-family the largest overshoot left against the oracle's
#: was at the detour's onset, the hedge's progress along the plan carrying the tool on as the person turned (0.57 of
#: the 0.95 mm a trial between the two). On the same cells against the filter with the 0.05 s cross-fade: overshoot
#: −0.047 [−0.076, −0.018] mm, hand force +0.011 [+0.005, +0.017] N, jerk −0.002 [−0.004, −0.001] m/s³ (0: −0.076
#: [−0.121, −0.031] mm, +0.023 [+0.011, +0.035] N; half the progress everywhere: −0.064 mm for +0.065 N).
#: The rows low-passed over 0.06 s instead of 0.04 once each person gives eight probe trials (the force shares rose
#: enough to pay for it): on the same cells, against 0.04 s, overshoot −0.019 [−0.040, +0.002] mm, hand force +0.040
#: [+0.037, +0.043] N, jerk −0.040 [−0.045, −0.035] m/s³, every cell's force share ≥ 85 % (0.08 s: −0.085 mm, +0.054 N,
#: −0.068 m/s³, but one cell's force share 84 %; docs/person-model.md, "Eight probe trials a person").
#: The lead and the rows' low-pass moved together, 0.06 → 0.09 s each (2026-12-05): alone, a longer lead saves hand
#: force for jerk and a longer low-pass jerk and overshoot for force; together, on the same eight cells against 0.06 /
#: 0.06 s, overshoot −0.139 [−0.283, +0.006] mm, hand force −0.051 [−0.065, −0.037] N, jerk −0.029 [−0.036, −0.021]
#: m/s³, every cell's force share 87–96 % (docs/person-model.md, "The lead and the rows' low-pass together").
#: The side evidence reads an offset toward the way whose mean path lies on that side of the other's there
#: (side_orientation): a person whose paths lean the wrong way before going round (the unseen population's feint) had
#: their lean read as the other way, decided in every one of eight replayed calibration folds and undone some 2 s
#: later. On the eight cells every trial is the same to the last bit (no tuning person's ways cross where the evidence
#: counts), so the cells could not choose it: it was found on the unseen population (docs/person-model.md, "A person
#: who feints"). The curves' log-likelihoods forget over likelihood_memory = 1.5 s: on the eight cells, against the
#: whole trial's, overshoot +0.005 [−0.040, +0.050] mm, hand force −0.013 [−0.018, −0.008] N, jerk −0.003 [−0.006,
#: −0.001] m/s³; 0.3 and 0.5 s saved more force and cost overshoot beyond their intervals (+0.120, +0.092 mm), 2 and
#: 3 s saved less (docs/person-model.md, "The curves' evidence forgets"). With the memory, the evidence's discount
#: κ (kappa) 0.2 → 0.05: on the eight cells overshoot −0.106 [−0.243, +0.030] mm, hand force −0.005 [−0.021, +0.010]
#: N, jerk −0.008 [−0.015, −0.001] m/s³; from 0.15 down to 0.02 the overshoot and jerk lower, the force within
#: ±0.007 N; 0.3 and 0.5 higher on all three (docs/person-model.md, "The evidence's discount again"). The rows lag
#: the tool by brake_time = 0.015 s of its velocity (a linear damper through the game): a trade of force for overshoot,
#: chosen by the rule the application's source was (the most overshoot share while every one of the eight cells keeps
#: ≥ 85 % of the oracle's force saving and jerk ≤ 1.2 × MG's): on the eight cells overshoot −0.155 [−0.192, −0.118] mm,
#: hand force +0.063 [+0.059, +0.066] N, jerk −0.015 [−0.018, −0.012] m/s³; 0.02 s left a cell at 84.7 % of the force
#: saving (docs/person-model.md, "A brake in the rows").
PERSON_FILTER = PersonFilterSettings(
    kappa=0.05,
    blend_time=0.05,
    hedge_leaving=0.5,
    reaction_lead=0.09,
    object_yaw=True,
    row_smoothing=0.09,
    follow_mirror=False,
    side_rule="onset",
    evidence_gap=0.005,
    hedge_lateral=False,
    dead_zone_noise=3.0,
    residual_time=0.2,
    side_orientation=True,
    likelihood_memory=1.5,
    brake_time=0.015,
)
_FORMAT = "coassist-person-model-2"
#: The formats :func:`read_person_model` reads: the current, and ``-1`` (written before a check kept ``worse``: its
#: checks read with ``worse`` None). A reader of ``-1`` alone refuses a ``-2`` file by its format, in one line.
_READS = (_FORMAT, "coassist-person-model-1")


#: The low-pass of the reconstructed intent paths [Hz] (zero phase; step 2 of the module docstring).
INTENT_SMOOTHING = 1.5


@dataclass(frozen=True)
class LeadCheck:
    """Whether the person model leads this person along their paths (:func:`coassist.sim.person_twin.lead_check`:
    their calibration replayed against a twin of them, leave-one-out).

    follow : lead along their paths (True), or give them the present estimate held (False: the twin overshot more
        with the lead than under MG, beyond the trials' spread, or in too many of the trials to be chance). folds :
        the trials replayed. person_mm, mg_mm : the twin's mean overshoot [mm] with the person model and under MG;
        low_mm : the lower end of the 95 % Student-t interval of their paired difference [mm]; worse : in how many
        of the trials the twin overshot more with the lead (each None where not checked; ``worse`` also in a file
        written before it was kept). note : "checked", or why not.
    """

    follow: bool = True
    folds: int = 0
    person_mm: float | None = None
    mg_mm: float | None = None
    low_mm: float | None = None
    note: str = "checked"
    worse: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.follow, bool):
            raise ValueError(f"LeadCheck.follow must be true or false, got {self.follow!r}")
        object.__setattr__(self, "folds", check_int(self.folds, "LeadCheck.folds", 0, 1000))
        for name, lo in (("person_mm", 0.0), ("mg_mm", 0.0), ("low_mm", -1e4)):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, check_real(value, f"LeadCheck.{name}", lo, 1e4))
        if not isinstance(self.note, str):
            raise ValueError(f"LeadCheck.note must be text, got {self.note!r}")
        if self.worse is not None:
            object.__setattr__(self, "worse", check_int(self.worse, "LeadCheck.worse", 0, self.folds))

    @property
    def line(self) -> str:
        """What the check found, in a few words (the calibrate line)."""
        if self.person_mm is None or self.mg_mm is None:
            return f"lead {self.note}"
        verdict = "led along their paths" if self.follow else "present estimate held (the lead did not pay)"
        low = "" if self.low_mm is None else f", the difference's 95 % interval from {self.low_mm:+.1f} mm"
        worse = "" if self.worse is None else f", more with the lead in {self.worse}"
        return (
            f"{verdict}: their twin overshot {self.person_mm:.1f} mm with the lead, {self.mg_mm:.1f} mm under MG "
            f"({self.folds} trials replayed{worse}{low})"
        )


@dataclass(frozen=True, eq=False)
class PersonFit:
    """One person's fit: their arm, their path model on one task and, where checked, whether to lead them."""

    arm: ArmEstimate
    paths: PathModel
    lead: LeadCheck | None = None


def _nominal_of(trial) -> np.ndarray:
    """The nominal path of a trial: its planner reference's distinct points, in order."""
    ref = np.asarray(trial.reference[:, :2], dtype=float)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(ref, axis=0), axis=1) > 1e-9])
    return ref[keep]


def intent_estimate(trial, arm: ArmEstimate, *, smoothing: float = INTENT_SMOOTHING) -> tuple[np.ndarray, np.ndarray]:
    """(q, its low-pass): the present estimate q = p + (w + Ĉ v)/K̂ of ``trial`` on its whole time course, (T, 2) [m],
    and q low-passed at ``smoothing`` Hz with zero phase (module docstring, step 2). The handle's sensor reads the
    hand's force (no inertia put back)."""
    from scipy.signal import butter, sosfiltfilt

    q = trial.pose[:, :2] + (trial.wrench[:, :2] + arm.damping * trial.velocity[:, :2]) / arm.stiffness
    sos = butter(2, smoothing, "lowpass", fs=1.0 / float(trial.meta.dt), output="sos")
    return q, sosfiltfilt(sos, q, axis=0)


def intent_paths(
    trials: Sequence, arm: ArmEstimate, *, smoothing: float = INTENT_SMOOTHING
) -> tuple[list[np.ndarray], float]:
    """Each trial's reconstructed intent path (module docstring, step 2: :func:`intent_estimate`, from leaving the
    start to reaching the end of the plan) and the present estimate's noise σ [m] about it: (paths, σ)."""
    paths, resid = [], []
    for trial in trials:
        q, smooth = intent_estimate(trial, arm, smoothing=smoothing)
        # the part the person moved: from leaving the start to reaching the end of the plan
        start, end = trial.reference[0, :2], trial.reference[-1, :2]
        moved = np.flatnonzero(np.linalg.norm(trial.pose[:, :2] - start, axis=1) > 0.005)
        first = int(moved[0]) if moved.size else 0
        at_end = np.flatnonzero(np.linalg.norm(smooth - end, axis=1) < 0.01)
        last = int(at_end[at_end > first][0]) if np.any(at_end > first) else len(smooth) - 1
        paths.append(smooth[first : last + 1])
        resid.append((q - smooth)[first : last + 1])
    r = np.concatenate(resid)
    return paths, float(math.sqrt(float(np.mean(np.sum(r * r, axis=1)) / 2.0)))


def fit_person(
    trials: Sequence,
    *,
    settings: PathModelSettings | None = None,
    arm: ArmEstimate | None = None,
    smoothing: float = INTENT_SMOOTHING,
) -> PersonFit:
    """One person's :class:`PersonFit` from their calibration trials on one task (module docstring).
    ``arm``: use this arm instead of measuring it (e.g. to study what a wrong arm costs); None: measured from the
    trials' probe and used as a lab uses it (:func:`~coassist.scenario.arm_identification.measured_arm`: the
    typical arm where the measurement says too little, as ``coassist calibrate`` and a study decide)."""
    if not trials:
        raise ValueError("fit_person needs at least one trial")
    nominal = _nominal_of(trials[0])
    frame = PathFrame(nominal)
    for t in trials[1:]:
        if frame.distance_to(_nominal_of(t)) > 0.01:
            raise ValueError(
                f"fit_person: the trials follow different nominal paths ({trials[0].meta.task!r}, {t.meta.task!r}); "
                "fit each task apart"
            )
    arm = measured_arm(identify_arm(trials))[0] if arm is None else arm
    ways = [asked_way(t) for t in trials]
    paths, noise = intent_paths(trials, arm, smoothing=smoothing)
    model = fit_path_model(nominal, paths, noise=max(noise, 1e-4), settings=settings)
    # A path asked for one way counts for that way but not in the prior; one that went the other way (or round
    # neither) is what the person chose against the lab's asking: in the prior, as every chosen path
    asked = [way != 0 and way == side for way, side in zip(ways, model.sides.tolist())]
    return PersonFit(arm=arm, paths=replace(model, asked=np.asarray(asked)) if any(asked) else model)


def without_trial(fit: PersonFit, trials: Sequence, leave: int) -> PersonFit:
    """``fit`` (of ``trials``, by :func:`fit_person`) as fitted to the same trials less trial ``leave``, without
    fitting the others' paths again: each demonstration's primitive is fitted alone, so dropping its row is the refit
    of the rest, weights and way bit for bit; the noise σ is the others' (:func:`intent_paths`, as
    :func:`fit_person` takes it); the arm and the plan stay the fit's (the plan is the first trial's)."""
    n = len(fit.paths.sides)
    if len(trials) != n or not 0 <= leave < n:
        raise ValueError(f"without_trial: {len(trials)} trials for a fit of {n} paths, leave {leave}")
    keep = np.arange(n) != leave
    rest = [t for j, t in enumerate(trials) if j != leave]
    _, noise = intent_paths(rest, fit.arm)
    asked = None if fit.paths.asked is None or not np.any(fit.paths.asked[keep]) else fit.paths.asked[keep]
    paths = replace(
        fit.paths,
        weights=fit.paths.weights[keep],
        sides=fit.paths.sides[keep],
        noise=max(noise, 1e-4),
        asked=asked,
    )
    return replace(fit, paths=paths, lead=None)


def asked_way(trial) -> int:
    """The way round the lab asked for in ``trial`` (its ``meta.extra`` :data:`ASKED_WAY`): +1 left, −1 right, 0 none
    asked (the person chose)."""
    return check_way(
        trial.meta.extra.get(ASKED_WAY, 0), f"trial {trial.meta.user} seed {trial.meta.seed}: meta.extra[{ASKED_WAY!r}]"
    )


def fit_people(trials: Sequence) -> dict[str, PersonFit]:
    """Each person's fit (:func:`fit_person`) from their own trials among ``trials`` (grouped by
    ``meta.user``), keyed by that name, in name order: what a person-model folder holds."""
    by_user: dict[str, list] = {}
    for trial in trials:
        by_user.setdefault(str(trial.meta.user), []).append(trial)
    return {user: fit_person(own) for user, own in sorted(by_user.items())}


def _model_doc(model: PathModel) -> dict:
    return {
        "nominal": model.nominal.tolist(),
        "noise": model.noise,
        "settings": asdict(model.settings),
        "weights": model.weights.tolist(),
        "sides": model.sides.tolist(),
        # written only where a way was asked for: a model fitted to chosen ways alone is written as before
        **({"asked": np.asarray(model.asked).tolist()} if np.any(model.asked) else {}),
    }


def _model_from(doc: Mapping) -> PathModel:
    return PathModel(
        nominal=np.asarray(doc["nominal"], dtype=float),
        weights=np.asarray(doc["weights"], dtype=float),
        sides=np.asarray(doc["sides"], dtype=int),
        noise=float(doc["noise"]),
        settings=PathModelSettings(**doc["settings"]),
        asked=np.asarray(doc["asked"]) if "asked" in doc else None,
    )


#: The worlds (``TrialMeta.origin``) that hold every object rigidly: the MuJoCo UR5 (:mod:`coassist.robot.ur5_mjcf`)
#: has no yaw mode, so there the hand moves with the tip and a board's probe measures the arm as the handle's does.
RIGID_HOLD_ORIGINS = frozenset({"mujoco"})


#: The kinds of world a person model serves, by the ``TrialMeta.origin`` of its trials: the person's arm was measured
#: through that world's hand (the browser's pointer spring, a simulated operator, a person at a real handle) and their
#: paths in its frame, so a model of one kind is refused in a world of another.
ORIGIN_KINDS = {
    "sim": "a simulation (the point-mass world or the browser page)",
    "mujoco": "the MuJoCo UR5",
    "ur5": "an arm (a UR, a Franka, their recordings)",
    "franka": "an arm (a UR, a Franka, their recordings)",
    "real": "an arm (a UR, a Franka, their recordings)",
}


def origin_kind(origin: str) -> str:
    """The kind of world (:data:`ORIGIN_KINDS`) trials of ``origin`` come from, in words."""
    return ORIGIN_KINDS.get(str(origin), str(origin))


def _check_origins(origins: Sequence[str], where: str) -> tuple[str, ...]:
    if isinstance(origins, str) or not all(isinstance(o, str) and o in ORIGIN_KINDS for o in origins):
        raise ValueError(f"{where} must be a list of {tuple(ORIGIN_KINDS)}, got {origins!r}")
    return tuple(sorted(set(origins)))


def person_filter_for(origin: str) -> PersonFilterSettings:
    """The online filter for a person model calibrated on trials from ``origin`` (``TrialMeta.origin``): on the MuJoCo
    UR5 (``mujoco``), which holds every object rigidly (:mod:`coassist.robot.ur5_mjcf`), the hand moves with the tip:
    no yaw mode (``object_yaw`` off; with it the tool's jerk about doubled on the board); elsewhere
    :data:`PERSON_FILTER`."""
    return replace(PERSON_FILTER, object_yaw=False) if origin in RIGID_HOLD_ORIGINS else PERSON_FILTER


def write_person_model(
    folder: str | Path,
    fits: Mapping[str, PersonFit],
    *,
    settings: PersonFilterSettings | None = None,
    default: str | None = None,
    origins: Sequence[str] = (),
) -> Path:
    """Write a person-model folder (``person-model.json``, atomically); returns the folder. ``default``: the
    person (a key of ``fits``) whose model anyone else at the handle gets (module docstring). ``origins``: the worlds
    its trials came from (``TrialMeta.origin``), recorded so that a run in a world of another kind refuses it
    (:func:`origin_kind`); empty: not recorded (as before 2026-12-07)."""
    if default is not None and default not in fits:
        raise ValueError(f"default must be one of the people fitted ({', '.join(fits)}), got {default!r}")
    origins = _check_origins(origins, "origins")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {
        "filter": asdict(settings or PERSON_FILTER),
        "people": {
            name: {
                "arm": asdict(f.arm),
                "paths": _model_doc(f.paths),
                # written only where it was checked: a model fitted without the check is written as before
                **({} if f.lead is None else {"lead": asdict(f.lead)}),
            }
            for name, f in fits.items()
        },
    }
    if default is not None:
        doc["default"] = default
    if origins:
        doc["origins"] = list(origins)
    # the file carries its own SHA-256: a person model is something the robot obeys, an edit by hand is refused
    write_hashed_json(folder / PERSON_MODEL_FILE, doc, format=_FORMAT)
    return folder


#: What :func:`read_person_model` read, per file content (its bytes' SHA-256): a run's simulation processes build a
#: fresh source for every trial (its state is the trial's) from the same few folders, and parsing the file and
#: rebuilding the path models was about 80 ms of CPU a trial (issue 44). Content that was not read before (an edit,
#: a rewrite) is read and its own hash checked. Bounded.
_READ_MEMO: dict[bytes, tuple[dict, dict, str | None, PersonFilterSettings, frozenset[str], tuple[str, ...]]] = {}
_READ_MEMO_SIZE = 32


def read_person_model(folder: str | Path, horizon: int = 50) -> PersonPathsIntent:
    """The intent source a person-model folder holds (errors name the file and field)."""
    path = Path(folder) / PERSON_MODEL_FILE
    try:
        key: bytes | None = hashlib.sha256(path.read_bytes()).digest()
    except OSError:
        key = None  # read_hashed_json says what is wrong with it
    read = None if key is None else _READ_MEMO.get(key)
    if read is None:
        read = _read_people(path)
        if key is not None:
            if len(_READ_MEMO) >= _READ_MEMO_SIZE:
                _READ_MEMO.pop(next(iter(_READ_MEMO)))
            _READ_MEMO[key] = read
    paths, arms, default, settings, held, origins = read
    return PersonPathsIntent(
        horizon,
        paths=paths,
        arms=arms,
        default_paths=None if default is None else paths[default],
        default_arm=None if default is None else arms[default],
        settings=settings,
        held=held | ({PersonPathsIntent.DEFAULT} if default in held else set()),
        default_person=default,
        origins=origins,
        # the folder's name and the file's digest: two calibrations written to folders of one name (or one
        # folder rewritten with --overwrite) give their trials different ids, as a trained model's do
        model_id=f"person:{Path(folder).name}@{'' if key is None else key.hex()[:12]}",
    )


def _read_people(
    path: Path,
) -> tuple[dict, dict, str | None, PersonFilterSettings, frozenset[str], tuple[str, ...]]:
    """A person-model file's people's path models and arms, its default person, its filter, the people it does
    not lead (their :class:`LeadCheck` said so) and the worlds its trials came from (errors name the file and
    field)."""
    doc = read_hashed_json(path, format=_READS)  # one line naming the file: missing, edited, another format
    try:
        people = dict(doc["people"])
        paths = {name: _model_from(p["paths"]) for name, p in people.items()}
        arms = {name: ArmEstimate(**p["arm"]) for name, p in people.items()}
        leads = {name: LeadCheck(**p["lead"]) for name, p in people.items() if "lead" in p}
        default = doc.get("default")
        if default is not None and default not in people:
            raise ValueError(f"default {default!r} is not one of its people ({', '.join(people)})")
        held = frozenset(name for name, lead in leads.items() if not lead.follow)
        origins = _check_origins(doc.get("origins", []), "origins")
        return paths, arms, default, PersonFilterSettings(**doc.get("filter", {})), held, origins
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None
