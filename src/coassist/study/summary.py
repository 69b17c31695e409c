"""The study's summary as a typed result: :class:`StudySummary`, what ``coassist study report`` shows.

:func:`coassist.study.summarise.summarise_study` computes it from a study folder (what each field
means and how it is computed is said there); :mod:`coassist.study.report` renders it, and writes
:meth:`StudySummary.to_json` as ``summary.json`` (its keys and their order are the file's since
the first study report; :meth:`StudySummary.from_json` reads the file back).

A number that cannot be computed (a measure with no finite value, a test with too few pairs) is
None here and null in the JSON, except in :class:`~coassist.analysis.paired.PairedComparison`,
which keeps its NaN (null in the JSON too: :meth:`StudySummary.from_json` reads it back as NaN).
Units are SI (m, N, s) as :data:`~coassist.study.measures.MEASURES` states them; the report scales
them to its display units.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

import numpy as np

from coassist.analysis.paired import PairedComparison
from coassist.study.folder import finite_json

__all__ = [
    "AnswerStat",
    "ArmFit",
    "Calibration",
    "Collection",
    "ConditionInfo",
    "CriterionCheck",
    "ForceTrace",
    "OrderEffect",
    "ParticipantRow",
    "PersonModelFit",
    "PooledMeasure",
    "QuestionnaireSummary",
    "StudySummary",
    "TrainedModel",
    "TrialCount",
    "finite_number",
]


def finite_number(v: Any) -> float | None:
    """``v``, None where it is missing or not a finite number (what the JSON holds as null); an int stays
    an int (as :func:`~coassist.study.folder.finite_json` leaves it: the JSON writes ``3``, not ``3.0``)."""
    v = finite_json(v)
    if v is None or isinstance(v, int):
        return v
    return float(v)


@dataclass(frozen=True)
class PooledMeasure:
    """One measure in one block over participants: the mean and sample sd (ddof = 1) of the participants'
    means, in the measure's SI unit (:data:`coassist.study.measures.MEASURES`); ``n`` participants with a
    finite value. None where ``n`` is 0 (the mean) or below 2 (the sd)."""

    mean: float | None
    sd: float | None
    n: int

    def to_json(self) -> dict[str, Any]:
        return {"mean": self.mean, "sd": self.sd, "n": self.n}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PooledMeasure:
        return cls(mean=finite_number(d["mean"]), sd=finite_number(d["sd"]), n=int(d["n"]))


@dataclass(frozen=True)
class AnswerStat:
    """One questionnaire score (raw TLX 0–100, a TLX item, a Likert item) in one block over the participants
    who answered: mean, median, ``n``; None where no one did."""

    mean: float | None
    n: int
    median: float | None

    def to_json(self) -> dict[str, Any]:
        return {"mean": self.mean, "n": self.n, "median": self.median}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> AnswerStat:
        return cls(mean=finite_number(d["mean"]), n=int(d["n"]), median=finite_number(d["median"]))


@dataclass(frozen=True)
class CriterionCheck:
    """The iterative protocol's stop criterion at one round (eq. 4.13), as the participant's log records it:
    the in-loop e_RMS [m] at ``criterion_horizon`` samples of this round and the one before, ``delta`` =
    |e_RMS − e_RMS_before| [m] against ``tolerance`` [m]; ``stop``: the study stopped here."""

    step: int
    key: str
    round: int
    e_rms: float | None
    e_rms_before: float | None
    delta: float | None
    tolerance: float
    criterion_horizon: int
    met: bool
    stop: bool
    t: str
    kind: str = "check"

    def to_json(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "kind": self.kind,
            "key": self.key,
            "round": self.round,
            "e_rms": self.e_rms,
            "e_rms_before": self.e_rms_before,
            "delta": self.delta,
            "tolerance": self.tolerance,
            "criterion_horizon": self.criterion_horizon,
            "met": self.met,
            "stop": self.stop,
            "t": self.t,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CriterionCheck:
        return cls(
            step=int(d["step"]),
            kind=str(d["kind"]),
            key=str(d["key"]),
            round=int(d["round"]),
            e_rms=finite_number(d["e_rms"]),
            e_rms_before=finite_number(d["e_rms_before"]),
            delta=finite_number(d["delta"]),
            tolerance=float(d["tolerance"]),
            criterion_horizon=int(d["criterion_horizon"]),
            met=bool(d["met"]),
            stop=bool(d["stop"]),
            t=str(d["t"]),
        )


@dataclass(frozen=True)
class ArmFit:
    """The arm of a person model: measured from the probe's ``trials`` (pushes), taken ``from`` its base
    model, or assumed (``note`` says why); K̂ [N/m] and Ĉ [N·s/m] with their standard errors."""

    measured: bool
    note: str | None
    from_: str | None  # "from" in the JSON: the base model's, when the arm was not measured again
    trials: int | None
    stiffness: float | None
    stiffness_se: float | None
    damping: float | None
    damping_se: float | None

    def to_json(self) -> dict[str, Any]:
        return {
            "measured": self.measured,
            "note": self.note,
            "from": self.from_,
            "trials": self.trials,
            "stiffness": self.stiffness,
            "stiffness_se": self.stiffness_se,
            "damping": self.damping,
            "damping_se": self.damping_se,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ArmFit:
        return cls(
            measured=bool(d["measured"]),
            note=d["note"],
            from_=d["from"],
            trials=d["trials"],
            stiffness=finite_number(d["stiffness"]),
            stiffness_se=finite_number(d["stiffness_se"]),
            damping=finite_number(d["damping"]),
            damping_se=finite_number(d["damping_se"]),
        )


@dataclass(frozen=True)
class PersonModelFit:
    """One attempt at fitting a participant's person model (a progress line of kind ``fit``).

    Failed: ``reason`` and ``redo`` (the block run again). Otherwise what it was fitted from (``trials``
    per task, ``left_out`` per task: not in the target, of the ``blocks``), its ``arm``, what it was
    ``told`` (:class:`~coassist.scenario.intent_registry.Told`), ``used_in``: the blocks whose trials ran
    with its files (their lines' ``model_sha256`` among its ``sha256``), the fit's wall time [s], and per task a way
    round shown in too few of its trials to follow (``thin_ways``:
    :func:`~coassist.experiments.person_calibration.thin_ways`; tasks with none left out), and per task whether the
    model leads them along their paths (``lead``: its twin check's line, :func:`~coassist.study.calibration.lead_lines`;
    a participant turned away was assisted with the present estimate held)."""

    model: str | None
    attempt: int | None
    failed: bool
    reason: str | None = None
    redo: str | None = None
    told: str | None = None
    used_in: tuple[str, ...] = ()
    base: str | None = None
    blocks: tuple[str, ...] | None = None
    trials: Mapping[str, int] = field(default_factory=dict)
    left_out: Mapping[str, int] = field(default_factory=dict)
    arm: ArmFit | None = None
    sha256: Mapping[str, str] | None = None
    fit_seconds: float | None = None
    thin_ways: Mapping[str, str] = field(default_factory=dict)
    lead: Mapping[str, str] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"model": self.model, "attempt": self.attempt, "failed": self.failed}
        if self.failed:
            return {**out, "reason": self.reason, "redo": self.redo}
        return {
            **out,
            "told": self.told,
            "used_in": list(self.used_in),
            "base": self.base,
            "blocks": None if self.blocks is None else list(self.blocks),
            "trials": dict(self.trials),
            "left_out": dict(self.left_out),
            "arm": None if self.arm is None else self.arm.to_json(),
            "sha256": None if self.sha256 is None else dict(self.sha256),
            "fit_seconds": self.fit_seconds,
            "thin_ways": dict(self.thin_ways),
            "lead": dict(self.lead),
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> PersonModelFit:
        if d["failed"]:
            return cls(model=d["model"], attempt=d["attempt"], failed=True, reason=d["reason"], redo=d["redo"])
        return cls(
            model=d["model"],
            attempt=d["attempt"],
            failed=False,
            told=d["told"],
            used_in=tuple(d["used_in"]),
            base=d["base"],
            blocks=None if d["blocks"] is None else tuple(d["blocks"]),
            trials=dict(d["trials"]),
            left_out=dict(d["left_out"]),
            arm=None if d["arm"] is None else ArmFit.from_json(d["arm"]),
            sha256=None if d["sha256"] is None else dict(d["sha256"]),
            fit_seconds=finite_number(d["fit_seconds"]),
            thin_ways=dict(d.get("thin_ways", {})),  # summaries written before it: none said
            lead=dict(d.get("lead", {})),  # summaries written before the twin check: none said
        )


@dataclass(frozen=True)
class TrialCount:
    """The measured trials of one block (one participant's, or all participants' summed): ``n`` trials, ``reached``
    of them entered the target's ε-ball (a finite time to target), ``missed`` = n − reached never did, and
    ``covered``: per measure, how many trials gave it a finite value, the trials its mean is over (σ, overshoot and
    time to target are undefined for a trial that missed the target: left out of their means); ``repeated``: how many
    were started more than once (the person aborted it, or their hand left, and it was shown again); ``unfinished``:
    how many ended otherwise than held in the target for the dwell (the time limit, a safety stop): a trial whose tool
    entered the ball once and left it again counts as reached, and its σ and time to target are a trial's that did
    not finish (a trial that never reached it is missed, not unfinished)."""

    n: int
    reached: int
    covered: Mapping[str, int] = field(default_factory=dict)
    repeated: int = 0  # of the n, trials started more than once (aborted on the page, or the hand left, first)
    unfinished: int = 0  # of the reached, trials that ended otherwise than held in the target (the time limit, a stop)

    @property
    def missed(self) -> int:
        return self.n - self.reached

    @property
    def miss_rate(self) -> float | None:
        return self.missed / self.n if self.n else None

    def to_json(self) -> dict[str, Any]:
        return {
            "n": self.n,
            "reached": self.reached,
            "missed": self.missed,
            "miss_rate": self.miss_rate,
            "covered": dict(self.covered),
            "repeated": self.repeated,
            "unfinished": self.unfinished,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TrialCount:
        return cls(
            n=int(d["n"]),
            reached=int(d["reached"]),
            covered={k: int(v) for k, v in d["covered"].items()},
            repeated=int(d.get("repeated", 0)),  # summaries written before it was counted
            unfinished=int(d.get("unfinished", 0)),  # the same
        )


@dataclass(frozen=True)
class ConditionInfo:
    """What a compared condition was, as the plan set it: its ``controller``
    (:data:`coassist.control.presets.CONTROLLERS`), its ``intent`` (a named source, ``calibrated``: the
    participant's own person model, or the absolute path of a folder) and, for a folder, ``intent_sha256``: what
    ``study init`` recorded of it (a model's ``weights_sha256``, a calibration's marker file's SHA-256)."""

    controller: str
    intent: str
    intent_sha256: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {"controller": self.controller, "intent": self.intent, "intent_sha256": self.intent_sha256}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ConditionInfo:
        return cls(controller=str(d["controller"]), intent=str(d["intent"]), intent_sha256=d.get("intent_sha256"))


@dataclass(frozen=True)
class ParticipantRow:
    """One participant: their number and Latin-square row, how far they got, the block ``order`` they met,
    their ``means`` (block → measure → mean over their measured trials, SI units; None where no trial
    gave a finite value), their questionnaire ``answers`` (block → item → answer), the criterion checks,
    the person models fitted, and ``trials``: block → :class:`TrialCount` (the trials each mean is over, those
    that missed the target)."""

    number: int
    row: int
    simulated: bool
    complete: bool
    steps_done: int
    steps: int
    order: tuple[str, ...]
    means: Mapping[str, Mapping[str, float | None]]
    answers: Mapping[str, Mapping[str, int]]
    checks: tuple[CriterionCheck, ...]
    person_models: tuple[PersonModelFit, ...]
    trials: Mapping[str, TrialCount] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "number": self.number,
            "row": self.row,
            "simulated": self.simulated,
            "complete": self.complete,
            "steps_done": self.steps_done,
            "steps": self.steps,
            "order": list(self.order),
            "means": {b: dict(m) for b, m in self.means.items()},
            "answers": {b: dict(a) for b, a in self.answers.items()},
            "checks": [c.to_json() for c in self.checks],
            "person_models": [f.to_json() for f in self.person_models],
            "trials": {b: c.to_json() for b, c in self.trials.items()},
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ParticipantRow:
        return cls(
            number=d["number"],
            row=d["row"],
            simulated=bool(d["simulated"]),
            complete=bool(d["complete"]),
            steps_done=int(d["steps_done"]),
            steps=int(d["steps"]),
            order=tuple(d["order"]),
            means={b: {k: finite_number(v) for k, v in m.items()} for b, m in d["means"].items()},
            answers={b: dict(a) for b, a in d["answers"].items()},
            checks=tuple(CriterionCheck.from_json(c) for c in d["checks"]),
            person_models=tuple(PersonModelFit.from_json(f) for f in d["person_models"]),
            # a summary written before the trials were counted has none
            trials={b: TrialCount.from_json(c) for b, c in d.get("trials", {}).items()},
        )


@dataclass(frozen=True)
class Calibration:
    """The plan's calibration block: its ``trials`` per participant, the blocks that ran with the
    participant's own person model (:func:`calibrated_blocks`) and the most trials it may ask for more
    (``[calibration] asked``: a way shown too seldom; each participant's count is in their fit)."""

    trials: int
    calibrated: tuple[str, ...]
    asked: int = 0

    def to_json(self) -> dict[str, Any]:
        return {"trials": self.trials, "calibrated": list(self.calibrated), "asked": self.asked}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Calibration:
        # a summary written before the asked trials were counted has none
        return cls(trials=int(d["trials"]), calibrated=tuple(d["calibrated"]), asked=int(d.get("asked", 0)))


@dataclass(frozen=True)
class QuestionnaireSummary:
    """The questionnaire pooled (block → score → :class:`AnswerStat`) and its own family of paired
    comparisons (raw TLX and each Likert item, Holm-corrected together)."""

    pooled: Mapping[str, Mapping[str, AnswerStat]]
    comparisons: tuple[PairedComparison, ...]

    def to_json(self) -> dict[str, Any]:
        return {
            "pooled": {b: {k: s.to_json() for k, s in q.items()} for b, q in self.pooled.items()},
            "comparisons": [finite_json(c.to_json()) for c in self.comparisons],
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> QuestionnaireSummary:
        return cls(
            pooled={b: {k: AnswerStat.from_json(s) for k, s in q.items()} for b, q in d["pooled"].items()},
            comparisons=tuple(_comparison_from_json(c) for c in d["comparisons"]),
        )


@dataclass(frozen=True)
class OrderEffect:
    """The position's F test on one measure (:func:`~coassist.study.stats.order_effect`): F with (df1, df2)
    degrees of freedom and its p (None where the design leaves no degrees of freedom), the means per
    condition and position (position as a string, as in the JSON), ``n`` rows."""

    F: float | None
    df1: int
    df2: int
    p: float | None
    means: Mapping[str, Mapping[str, float | None]]
    n: int

    def to_json(self) -> dict[str, Any]:
        return {
            "F": self.F,
            "df1": self.df1,
            "df2": self.df2,
            "p": self.p,
            "means": {c: dict(m) for c, m in self.means.items()},
            "n": self.n,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> OrderEffect:
        return cls(
            F=finite_number(d["F"]),
            df1=int(d["df1"]),
            df2=int(d["df2"]),
            p=finite_number(d["p"]),
            means={str(c): {str(pos): finite_number(v) for pos, v in m.items()} for c, m in d["means"].items()},
            n=int(d["n"]),
        )


@dataclass(frozen=True)
class Collection:
    """A transfer or online collection block: its trials' e_RMS [m] at 0.4 s and the model in the loop of each."""

    e_rms: tuple[float | None, ...]
    models: tuple[str | None, ...]

    def to_json(self) -> dict[str, Any]:
        return {"e_rms": list(self.e_rms), "models": list(self.models)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Collection:
        return cls(e_rms=tuple(finite_number(v) for v in d["e_rms"]), models=tuple(d["models"]))


@dataclass(frozen=True)
class TrainedModel:
    """A model the study trained for a participant (its ``model.json``): how it was initialised, its
    training wall time [s], the trials it saw (train + test) and its last test loss."""

    init: str | None
    train_seconds: float | None
    trials: int
    test_loss: float | None

    def to_json(self) -> dict[str, Any]:
        return {
            "init": self.init,
            "train_seconds": self.train_seconds,
            "trials": self.trials,
            "test_loss": self.test_loss,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TrainedModel:
        return cls(
            init=d["init"],
            train_seconds=finite_number(d["train_seconds"]),
            trials=int(d["trials"]),
            test_loss=finite_number(d["test_loss"]),
        )


@dataclass(frozen=True)
class StudySummary:
    """Everything ``coassist study report`` shows (module docstring); :meth:`to_json` is ``summary.json``.

    ``blocks``: the conditions in the plan's order, or the rounds (``round-k``) of the iterative
    protocol; ``labels``: the blinding key (condition → label on the page). Mappings are keyed by
    participant id, block and measure (:data:`~coassist.study.measures.MEASURES`' keys) in the
    order the report lists them. ``conditions``: what each compared condition was (the comparison protocol's;
    empty for the others, whose blocks the protocol sets); ``trials``: block → :class:`TrialCount` over the
    participants whose means are pooled (the trials that reached the target, and the measures' counts)."""

    study: str
    protocol: str
    world: str
    plan_sha256: str
    labels: Mapping[str, str]
    blocks: tuple[str, ...]
    participants: Mapping[str, ParticipantRow]
    calibration: Calibration | None
    n_participants: int
    n_complete: int
    pooled: Mapping[str, Mapping[str, PooledMeasure]]
    comparisons: tuple[PairedComparison, ...]
    questionnaire: QuestionnaireSummary
    order_effects: Mapping[str, OrderEffect]
    simulated: bool
    limits: tuple[str, ...]
    collections: Mapping[str, Mapping[str, Collection]]
    models: Mapping[str, Mapping[str, TrainedModel]]
    conditions: Mapping[str, ConditionInfo] = field(default_factory=dict)
    trials: Mapping[str, TrialCount] = field(default_factory=dict)

    def name(self, block: str) -> str:
        """A block as the report names it: ``block (label)``, or the block alone where it has no label."""
        label = self.labels.get(block)
        return f"{block} ({label})" if label else block

    def to_json(self) -> dict[str, Any]:
        """The JSON-ready summary (strict JSON: no NaN), its keys in ``summary.json``'s order."""
        return {
            "study": self.study,
            "protocol": self.protocol,
            "world": self.world,
            "plan_sha256": self.plan_sha256,
            "labels": dict(self.labels),
            "blocks": list(self.blocks),
            "participants": {pid: p.to_json() for pid, p in self.participants.items()},
            "calibration": None if self.calibration is None else self.calibration.to_json(),
            "n_participants": self.n_participants,
            "n_complete": self.n_complete,
            "pooled": {b: {k: s.to_json() for k, s in m.items()} for b, m in self.pooled.items()},
            "comparisons": [finite_json(c.to_json()) for c in self.comparisons],
            "questionnaire": self.questionnaire.to_json(),
            "order_effects": {k: o.to_json() for k, o in self.order_effects.items()},
            "simulated": self.simulated,
            "limits": list(self.limits),
            "collections": {pid: {b: c.to_json() for b, c in cs.items()} for pid, cs in self.collections.items()},
            "models": {pid: {n: m.to_json() for n, m in ms.items()} for pid, ms in self.models.items()},
            "conditions": {b: c.to_json() for b, c in self.conditions.items()},
            "trials": {b: c.to_json() for b, c in self.trials.items()},
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> StudySummary:
        """The summary back from :meth:`to_json`'s data (``summary.json`` as read); a key missing at the top
        is a ValueError naming it."""
        required = [f for f in fields(cls) if f.default is MISSING and f.default_factory is MISSING]
        missing = [f.name for f in required if f.name not in d]  # a key added since (a default) may be absent
        if missing:
            raise ValueError(f"a study summary without {missing}: not a summary.json of coassist study report")
        return cls(
            study=d["study"],
            protocol=d["protocol"],
            world=d["world"],
            plan_sha256=d["plan_sha256"],
            labels=dict(d["labels"]),
            blocks=tuple(d["blocks"]),
            participants={pid: ParticipantRow.from_json(p) for pid, p in d["participants"].items()},
            calibration=None if d["calibration"] is None else Calibration.from_json(d["calibration"]),
            n_participants=int(d["n_participants"]),
            n_complete=int(d["n_complete"]),
            pooled={b: {k: PooledMeasure.from_json(s) for k, s in m.items()} for b, m in d["pooled"].items()},
            comparisons=tuple(_comparison_from_json(c) for c in d["comparisons"]),
            questionnaire=QuestionnaireSummary.from_json(d["questionnaire"]),
            order_effects={k: OrderEffect.from_json(o) for k, o in d["order_effects"].items()},
            simulated=bool(d["simulated"]),
            limits=tuple(d["limits"]),
            collections={
                pid: {b: Collection.from_json(c) for b, c in cs.items()} for pid, cs in d["collections"].items()
            },
            models={pid: {n: TrainedModel.from_json(m) for n, m in ms.items()} for pid, ms in d["models"].items()},
            conditions={b: ConditionInfo.from_json(c) for b, c in d.get("conditions", {}).items()},
            trials={b: TrialCount.from_json(c) for b, c in d.get("trials", {}).items()},
        )


def _comparison_from_json(d: Mapping[str, Any]) -> PairedComparison:
    """A :class:`PairedComparison` back from its JSON, field by field: null is NaN again, a list its
    interval's tuple; a field missing is a ValueError naming it."""

    def value(v: Any) -> Any:
        if v is None:
            return math.nan
        if isinstance(v, list):
            return tuple(math.nan if x is None else float(x) for x in v)
        return v

    names = [f.name for f in fields(PairedComparison)]
    missing = [n for n in names if n not in d]
    if missing:
        raise ValueError(f"a paired comparison without {missing}: not a study summary's")
    return PairedComparison(**{n: value(d[n]) for n in names})


@dataclass(frozen=True)
class ForceTrace:
    """One measured trial's hand force in the plane: ``force`` [N] = ‖wrench[:, :2]‖ at ``time`` [s] from
    the trial's start; both (T,)."""

    time: np.ndarray
    force: np.ndarray
