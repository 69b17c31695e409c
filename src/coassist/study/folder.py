"""The study folder: the plan and its hash, who took part in which order, and what has run.

::

    studies/<name>/
      plan.toml                  the plan as given, byte for byte
      study.json                 its SHA-256, the blinding key (condition → label), the
                                 weights' SHA-256 of every model it names, the Latin square
      participants.json          pseudonymous id → number, Latin-square row, simulated or not
      numbers.json               the highest participant number given (a withdrawn one is not given again)
      participants/<id>/
        order.json               the participant's steps, fixed at their first run
        progress.jsonl           the manifest of what ran: one line per finished step
        <block>/                 a dataset per condition or round (coassist train, evaluate and
                                 show read it): manifest.json + trial_*.parquet
        practice/                the practice trials (a dataset too; not analysed)
        models/<name>/           the models the study trained for this participant

Nothing personal is stored: an id is a pseudonym of the form the plan sets (``P07``;
:mod:`coassist.study.ids` refuses names, dates, ids that differ from another in case only),
and trials carry it as their user.

Lossless: every file is written atomically (:mod:`coassist._io`); a trial is committed in
two steps, its dataset's manifest (:func:`coassist.data.append_to_dataset`) and then its
line in ``progress.jsonl`` (one ``write`` of a whole line on an ``O_APPEND`` file,
fsync'ed). A kill -9 at any point loses at most the trial in progress: a torn last line
is cut off when the file is next opened, and a trial whose manifest entry is in but whose
line is not is recognised by its step number (``meta.extra["study_step"]``) and its line
written then (:meth:`ParticipantFolder.reconcile`), so it is neither lost nor run twice.

A participant's folder is locked while a run uses it (:class:`coassist._io.OutputLock`):
two runs never write the same participant. The plan may be replaced (``study init``
again) until the first trial of anyone has run; after that a changed ``plan.toml`` (or a
changed model it names) is refused with one line, but for its safe fields
(:data:`SAFE_FIELDS`: those that change no finished trial), which :func:`amend_study`
changes with a reason, recorded in ``study.json`` (the plan it replaced kept in ``plans/``).

The folder is evidence, cross-checked on every run and report: the participant table
against the participants' folders (:meth:`StudyFolder.check_table`), each participant's
progress log against their order and their blocks' manifests
(:meth:`ParticipantFolder.audit`). A trial on disk the log does not know, a trial the log
records that its block's manifest or folder lost, a trial file whose bytes are not those its
line recorded (its SHA-256: a flipped byte in a parquet column can still read as numbers), a
participant's folder the table does not list: one :class:`StudyFolderError` line naming the
file and what to do, never a silent re-run or a report on changed data. No JSON file gets a NaN or an infinity (:func:`finite_json`: null).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import coassist
from coassist._io import OutputLock, atomic_write_bytes, atomic_write_text, fsync_dir
from coassist.data.datasets import MANIFEST_NAME
from coassist.errors import CoassistError
from coassist.scenario import intent_registry
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.study.design import blinding_labels, latin_square_rows
from coassist.study.ids import IdError, check_id
from coassist.study.plan import StudyPlan, load_plan
from coassist.study.preflight import SessionEstimate, preflight
from coassist.study.protocols import condition_names, participant_steps

__all__ = [
    "ORDER_NAME",
    "SAFE_FIELDS",
    "STUDY_NAME",
    "ParticipantFolder",
    "StudyFolder",
    "StudyFolderError",
    "amend_study",
    "finite_json",
    "init_study",
    "plan_differences",
]

FORMAT = "coassist-study/1"
PLAN_NAME = "plan.toml"
STUDY_NAME = "study.json"
PARTICIPANTS_NAME = "participants.json"
#: the highest participant number the study has given: a number stays taken after its participant is withdrawn
NUMBERS_NAME = "numbers.json"
ORDER_NAME = "order.json"
PROGRESS_NAME = "progress.jsonl"
PLANS_NAME = "plans"  # the plans an amendment replaced, as <sha256>.toml
#: The plan's fields ``coassist study amend`` may change once trials have run: none changes a
#: finished trial or the steps a participant has been given (their order is fixed at their
#: first run). A rest takes its length from the plan the run loaded, not from the recorded
#: steps; the stop criterion is checked with the plan's values when its step comes (and
#: records them); the thread count of a training is part of the command line recorded with
#: its model. An amendment applies from each participant's next run.
SAFE_FIELDS = (
    "study.participants",
    "study.id_pattern",
    "rest.between_conditions",
    "rest.between_trials",
    "iterative.criterion_horizon",
    "iterative.tolerance",
    "iterative.stop_at_criterion",
    "training.threads",
)
_RESTORE = "restore it from your backup of the study folder"


class StudyFolderError(CoassistError, ValueError):
    """A study folder that cannot be used as asked; one line saying why."""


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def finite_json(obj: Any) -> Any:
    """``obj`` with every NaN and infinity as None (strict JSON; a float a JSON file cannot hold is null)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): finite_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_json(v) for v in obj]
    if hasattr(obj, "dtype") and hasattr(obj, "item"):  # a numpy scalar
        return finite_json(obj.item())
    return obj


def _json(obj: Any) -> str:
    return json.dumps(finite_json(obj), indent=1, allow_nan=False, sort_keys=False) + "\n"


def intent_folder_hash(path: str | Path) -> str:
    """What identifies a folder the plan names: a model's ``weights_sha256`` (its sidecar's), else the
    SHA-256 of the file that marks its kind (a calibration's ``path-hypotheses.json``)."""
    kind = intent_registry.intent_folder_kind(str(path))
    if kind is None or kind == "model":
        try:
            meta = json.loads((Path(path) / "model.json").read_text("utf-8"))
            return str(meta["weights_sha256"])
        except (OSError, ValueError, KeyError, TypeError):
            raise StudyFolderError(f"{path}: not a readable model folder (model.json with weights_sha256)") from None
    marker = Path(path) / intent_registry.INTENT_FOLDERS[kind].marker
    try:
        return _sha256(marker.read_bytes())
    except OSError as exc:
        raise StudyFolderError(f"{marker}: unreadable ({exc.strerror})") from None


def init_study(plan_file: str | Path, out: str | Path) -> StudyFolder:
    """Validate ``plan_file`` whole (:func:`coassist.study.preflight.preflight`) and make ``out`` its
    study folder (module docstring); the session's estimate is recorded in ``study.json``.

    An existing study folder with the same plan is left as it is; with another plan it is
    updated only while no participant has started (an order written: else :class:`StudyFolderError`, one line).
    """
    plan_file = Path(plan_file)
    plan = load_plan(plan_file)
    estimate = preflight(plan)
    raw = plan_file.read_bytes()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise StudyFolderError(f"{out} is a file, not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / STUDY_NAME).is_file():
        raise StudyFolderError(f"{out} is not empty and holds no {STUDY_NAME}: not a study folder; pick another --out")
    with OutputLock(out):
        if (out / STUDY_NAME).is_file():
            old = StudyFolder(out)
            if old.record["plan_sha256"] == _sha256(raw) and old.record["plan_dir"] == str(plan_file.parent.resolve()):
                return old
            if old.any_started():
                raise StudyFolderError(
                    f"{out}: participants have started under its plan (sha256 {old.record['plan_sha256'][:12]}); a changed plan "
                    f"needs a new study folder (its safe fields, {', '.join(SAFE_FIELDS)}: coassist study amend)"
                )
        names = condition_names(plan)
        labels = blinding_labels(max(len(names), 1), plan.seed)
        record = {
            "format": FORMAT,
            "name": plan.name,
            "protocol": plan.protocol,
            "world": plan.world,
            "plan_sha256": _sha256(raw),
            "plan_dir": str(plan_file.parent.resolve()),
            "created": utc_now(),
            "coassist_version": coassist.__version__,
            # the blinding key: condition -> label shown on the page (kept here only)
            "labels": dict(zip(names, labels)),
            "models": {p: intent_folder_hash(p) for p in plan.intent_folders()},
            "latin_square": latin_square_rows(max(len(names), 1)),
            "estimate": estimate.to_json(),
            # what a condition that names no intent runs, fixed for this folder (the parser's default may change)
            "default_intent": DEFAULT_INTENT,
        }
        out.mkdir(parents=True, exist_ok=True)
        (out / "participants").mkdir(exist_ok=True)
        atomic_write_bytes(out / PLAN_NAME, raw)
        atomic_write_text(out / STUDY_NAME, _json(record))
        if not (out / PARTICIPANTS_NAME).is_file():
            atomic_write_text(out / PARTICIPANTS_NAME, _json({}))
    return StudyFolder(out)


def plan_differences(old: StudyPlan, new: StudyPlan) -> dict[str, tuple[Any, Any]]:
    """The plan's fields that differ, as written in the plan (``rest.between_trials``, ``condition``): (old, new)."""
    a, b = asdict(old), asdict(new)
    out: dict[str, tuple[Any, Any]] = {}
    for key in a:
        if key == "conditions":
            if a[key] != b[key]:
                out["condition"] = (a[key], b[key])
        elif isinstance(a[key], dict) or isinstance(b[key], dict):
            sub_a, sub_b = a[key] or {}, b[key] or {}
            for k in dict.fromkeys([*sub_a, *sub_b]):
                if sub_a.get(k) != sub_b.get(k) or (a[key] is None) != (b[key] is None):
                    out[f"{key}.{k}"] = (sub_a.get(k), sub_b.get(k))
        elif a[key] != b[key]:
            out[f"study.{key}"] = (a[key], b[key])
    return out


def amend_study(folder: str | Path, plan_file: str | Path, reason: str) -> dict[str, Any]:
    """Replace the study's plan by ``plan_file``, which may differ in :data:`SAFE_FIELDS` only, for ``reason``
    (one line, recorded). The new plan is checked whole as at init; the one it replaces is kept in
    ``plans/<sha256>.toml``. Returns the amendment's record (:class:`StudyFolderError` naming a field
    that may not change)."""
    if not isinstance(reason, str) or not reason.strip() or "\n" in reason or len(reason) > 500:
        raise StudyFolderError("--reason must say why, on one line of at most 500 characters")
    study = StudyFolder(folder)
    old = study.plan()
    plan_file = Path(plan_file)
    new = load_plan(plan_file, study.default_intent)  # read as the folder's plan is
    raw = plan_file.read_bytes()
    changed = plan_differences(old, new)
    if not changed:
        raise StudyFolderError(f"{plan_file}: nothing to amend (the same plan as {study.folder / PLAN_NAME})")
    for name in changed:
        if name not in SAFE_FIELDS:
            raise StudyFolderError(
                f"{plan_file}: {name} cannot be amended: it would change what participants do or what a finished "
                f"trial means; a study amends only {', '.join(SAFE_FIELDS)} (anything else: a new study folder)"
            )
    estimate = preflight(new)
    not_reached = _rests_not_reached(study, new, changed)
    with OutputLock(study.folder / STUDY_NAME):
        record = dict(study.record)
        old_raw = (study.folder / PLAN_NAME).read_bytes()
        (study.folder / PLANS_NAME).mkdir(exist_ok=True)
        atomic_write_bytes(study.folder / PLANS_NAME / f"{record['plan_sha256']}.toml", old_raw)
        amendment = {
            "t": utc_now(),
            "from_sha256": record["plan_sha256"],
            "to_sha256": _sha256(raw),
            "fields": {k: list(v) for k, v in changed.items()},
            "reason": reason.strip(),
            "trials_before": study.any_started(),
        }
        if not_reached:
            amendment["not_reached"] = not_reached
        record.update(
            plan_sha256=_sha256(raw),
            plan_dir=str(plan_file.parent.resolve()),
            estimate=estimate.to_json(),
            amendments=[*record.get("amendments", []), amendment],
        )
        atomic_write_bytes(study.folder / PLAN_NAME, raw)
        atomic_write_text(study.folder / STUDY_NAME, _json(record))
    return amendment


#: The rests whose length an amendment changes, and the steps' ``why`` that take it (the participants' waits while a
#: model trains take ``between_conditions`` too, but are in every order)
_PLAN_RESTS = {
    "rest.between_trials": ("between trials",),
    "rest.between_conditions": ("between conditions", "after the calibration"),
}


def _rests_not_reached(study: StudyFolder, new: StudyPlan, changed: dict[str, Any]) -> dict[str, list[str]]:
    """Per rest amended from 0 s to more, the participants who began without it: a rest of 0 s is no step of their
    order (fixed at their first run), so the new length reaches only those who begin after the amendment."""
    out: dict[str, list[str]] = {}
    fresh: list[dict[str, Any]] | None = None  # a new participant's steps under the new plan, made once if needed
    for name, whys in _PLAN_RESTS.items():
        if name not in changed or not (changed[name][0] == 0 and changed[name][1] > 0):
            continue
        fresh = participant_steps(new, study.labels, 1, 0) if fresh is None else fresh
        if not any(s["kind"] == "rest" and s.get("why") in whys for s in fresh):
            continue  # the protocol places none (one trial per condition): nobody misses it
        began = [
            pid
            for pid, order in study.started().items()
            if not any(s.get("kind") == "rest" and s.get("why") in whys for s in order.get("steps", []))
        ]
        if began:
            out[name] = began
    return out


class StudyFolder:
    """An initialised study folder (module docstring); :meth:`check_plan` before running anything."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        if not (self.folder / STUDY_NAME).is_file():
            raise StudyFolderError(
                f"{self.folder}: not a study folder (no {STUDY_NAME}); make one with coassist study init"
            )
        try:
            self.record: dict[str, Any] = json.loads((self.folder / STUDY_NAME).read_text("utf-8"))
        except (OSError, ValueError) as exc:
            raise StudyFolderError(f"{self.folder / STUDY_NAME}: unreadable ({exc})") from None
        if self.record.get("format") != FORMAT:
            raise StudyFolderError(f"{self.folder / STUDY_NAME}: not a {FORMAT} record")

    # ------------------------------------------------------------------ the plan
    def plan(self) -> StudyPlan:
        """The plan in the folder, checked against the hash recorded at init (:meth:`check_plan`)."""
        self.check_plan()
        from coassist.study.plan import plan_from_text

        return plan_from_text(
            (self.folder / PLAN_NAME).read_text("utf-8"), self.record["plan_dir"], self.default_intent
        )

    @property
    def default_intent(self) -> str:
        """The intent of a condition that names none (and whose controller reads one) in this folder's plan: the one
        recorded at init, so that a plan on disk keeps its meaning; ``nominal`` for a folder made before it was
        recorded (the default then)."""
        return str(self.record.get("default_intent", "nominal"))

    def check_plan(self) -> None:
        """One line if ``plan.toml`` or a model it names changed since ``study init``."""
        raw = (self.folder / PLAN_NAME).read_bytes()
        if _sha256(raw) != self.record["plan_sha256"]:
            raise StudyFolderError(
                f"{self.folder / PLAN_NAME} changed after study init (sha256 {self.record['plan_sha256'][:12]} recorded, "
                f"{_sha256(raw)[:12]} now): {'trials have run under the old one: put it back, or start a new study folder (coassist study amend changes its safe fields)' if self.any_started() else 'run coassist study init again'}"
            )
        for path, digest in self.record["models"].items():
            if intent_folder_hash(path) != digest:
                raise StudyFolderError(
                    f"{path}: changed after study init (a model's weights, a calibration: the study compares "
                    "what it recorded); put it back, or start a new study folder"
                )

    @property
    def labels(self) -> dict[str, str]:
        """The blinding key: condition → label (never sent to the page)."""
        return dict(self.record["labels"])

    def estimate(self) -> SessionEstimate | None:
        """The session's estimate recorded at init (or at the last amendment); None in an older folder."""
        e = self.record.get("estimate")
        return None if not isinstance(e, dict) else SessionEstimate(**e)

    # ------------------------------------------------------------------ participants
    def participants(self) -> dict[str, dict[str, Any]]:
        """The participant table (id → number, row, simulated); one line naming the file if it is not one."""
        path = self.folder / PARTICIPANTS_NAME
        try:
            table = json.loads(path.read_bytes().decode("utf-8"))
        except FileNotFoundError:
            return {}
        except (UnicodeDecodeError, ValueError):
            raise StudyFolderError(f"{path}: not JSON (edited by hand?); {_RESTORE}") from None
        except OSError as exc:
            raise StudyFolderError(f"{path}: unreadable ({exc.strerror})") from None
        ok = isinstance(table, dict) and all(
            isinstance(rec, dict)
            and isinstance(rec.get("number"), int)
            and isinstance(rec.get("row"), int)
            and isinstance(rec.get("simulated"), bool)
            for rec in table.values()
        )
        if not ok:
            raise StudyFolderError(
                f"{path}: not a participant table (id → number, row, simulated; edited by hand?); {_RESTORE}"
            )
        return table

    def started(self) -> dict[str, dict[str, Any]]:
        """The participants whose folder holds an order (they have started): id → their ``order.json``."""
        root = self.folder / "participants"
        out = {}
        for p in sorted(root.iterdir()) if root.is_dir() else ():
            if p.is_dir() and not p.name.startswith(".") and (p / ORDER_NAME).is_file():
                out[p.name] = ParticipantFolder(p, p.name).order() or {}
        return out

    def check_table(self) -> dict[str, dict[str, Any]]:
        """The participant table, cross-checked against the participants' folders (module docstring):
        every participant who started is listed, with the number and row of their order; numbers unique."""
        path = self.folder / PARTICIPANTS_NAME
        table = self.participants()
        started = self.started()
        if started and not path.is_file():
            raise StudyFolderError(
                f"{path}: missing, but {len(started)} participants have started ({', '.join(started)}): {_RESTORE} "
                "(a new participant would take an occupied number and row)"
            )
        for pid, order in started.items():
            rec = table.get(pid)
            where = self.folder / "participants" / pid / ORDER_NAME
            if rec is None:
                raise StudyFolderError(
                    f"{path} does not list {pid} ({where}: participant {order.get('number')}): {_RESTORE} "
                    "(a new participant would take an occupied number and row)"
                )
            if (rec["number"], rec["row"]) != (order.get("number"), order.get("row")):
                raise StudyFolderError(
                    f"{path}: {pid} is number {rec['number']}, row {rec['row']}, but {where} says number "
                    f"{order.get('number')}, row {order.get('row')} (edited by hand?); {_RESTORE}"
                )
        numbers = [rec["number"] for rec in table.values()]
        if len(set(numbers)) != len(numbers):
            raise StudyFolderError(f"{path}: two participants have the same number (edited by hand?); {_RESTORE}")
        for pid, rec in table.items():
            where = self.folder / "participants" / pid
            if not where.is_dir():  # registration makes it: their data lost, or a participant half taken out
                raise StudyFolderError(
                    f"{where}: missing, but {path} registers {pid} (number {rec['number']}): {_RESTORE}; a "
                    f"participant whose data was deleted on purpose (withdrawn) is taken out of {path.name} too, "
                    "and the report names their number"
                )
        return table

    def any_started(self) -> bool:
        """Whether any participant has started: a finished step on record, or their order written (a run stopped
        during its first trial has an order, and maybe a trial file, but no step on record yet)."""
        root = self.folder / "participants"
        return root.is_dir() and any(
            (p / ORDER_NAME).is_file() or ((p / PROGRESS_NAME).is_file() and (p / PROGRESS_NAME).stat().st_size > 0)
            for p in root.iterdir()
        )

    def register(self, participant: str, simulated: bool = False) -> dict[str, Any]:
        """The participant's record, made at their first run: number (1, 2, … in order of arrival),
        Latin-square row (number − 1), and whether a simulated operator stands in (``--simulate``).
        A new id must be a pseudonym of the plan's form (:func:`coassist.study.ids.check_id`)."""
        pattern = self.plan().id_pattern
        with OutputLock(self.folder / PARTICIPANTS_NAME):
            table = self.check_table()
            if participant not in table:
                try:
                    check_id(participant, pattern, table, simulated=simulated)
                except IdError as exc:
                    raise StudyFolderError(str(exc)) from None
            if participant in table:
                rec = table[participant]
                if bool(rec.get("simulated")) != bool(simulated):
                    what = "a simulated participant" if rec.get("simulated") else "a person"
                    raise StudyFolderError(
                        f"--participant {participant} is {what} in this study; "
                        f"{'add' if rec.get('simulated') else 'leave out'} --simulate"
                    )
                return rec
            # one kind a folder: a rehearsal's simulated operators pooled with people would be reported as people
            other = sorted(pid for pid, r in table.items() if bool(r.get("simulated")) != bool(simulated))
            if other:
                shown = ", ".join(other[:3]) + (f" and {len(other) - 3} more" if len(other) > 3 else "")
                raise StudyFolderError(
                    f"--participant {participant}: this study folder holds "
                    + (
                        f"people ({shown}); rehearse with --simulate in a folder of its own "
                        f"(coassist study init PLAN.toml --out {self.folder}-rehearsal)"
                        if simulated
                        else f"simulated participants ({shown}), a rehearsal; people take part in a folder of "
                        "their own (coassist study init PLAN.toml --out <new folder>)"
                    )
                    + ": the report pools everyone in a folder"
                )
            # a withdrawn participant's number (and row) is not given again, even the highest one
            number = max(self.numbers_issued(), *(r["number"] for r in table.values()), 0) + 1
            rec = {"number": number, "row": number - 1, "simulated": bool(simulated), "registered": utc_now()}
            # the folder first: a registered participant always has one (the table's check names a lost one)
            self.participant(participant).folder.mkdir(parents=True, exist_ok=True)
            table[participant] = rec
            atomic_write_text(self.folder / PARTICIPANTS_NAME, _json(table))
            atomic_write_text(self.folder / NUMBERS_NAME, _json({"issued": number}))  # after: a kill between is safe
            return rec

    def numbers_issued(self) -> int:
        """The highest participant number this study has given (0: none, or a folder of an older version, which
        kept no count: its table's numbers are then all there is)."""
        try:
            record = json.loads((self.folder / NUMBERS_NAME).read_bytes().decode("utf-8"))
        except FileNotFoundError:
            return 0
        except (OSError, UnicodeDecodeError, ValueError):
            raise StudyFolderError(
                f"{self.folder / NUMBERS_NAME}: not readable JSON (edited by hand?); {_RESTORE}"
            ) from None
        issued = record.get("issued") if isinstance(record, dict) else None
        if isinstance(issued, bool) or not isinstance(issued, int) or issued < 0:
            raise StudyFolderError(
                f"{self.folder / NUMBERS_NAME}: not the study's count of participant numbers (edited by hand?); {_RESTORE}"
            )
        return issued

    def participant(self, participant: str) -> ParticipantFolder:
        return ParticipantFolder(self.folder / "participants" / participant, participant)


class ParticipantFolder:
    """One participant's folder: the recorded steps, the progress manifest, the blocks' datasets."""

    def __init__(self, folder: Path, participant: str) -> None:
        self.folder = Path(folder)
        self.id = participant

    @property
    def progress_file(self) -> Path:
        return self.folder / PROGRESS_NAME

    def lock(self) -> OutputLock:
        """Held while a run uses this participant (a second run gets one line: OutputBusyError)."""
        return OutputLock(self.folder)

    # ------------------------------------------------------------------ the recorded order
    def order(self) -> dict[str, Any] | None:
        path = self.folder / ORDER_NAME
        if not path.is_file():
            return None
        try:
            order = json.loads(path.read_bytes().decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            raise StudyFolderError(f"{path}: not JSON (edited by hand?); {_RESTORE}") from None
        if not isinstance(order, dict) or not isinstance(order.get("steps"), list):
            raise StudyFolderError(f"{path}: not a participant's order (no steps; edited by hand?); {_RESTORE}")
        return order

    def write_order(self, order: Mapping[str, Any]) -> None:
        """Fix the participant's steps (once, at the first run)."""
        if (self.folder / ORDER_NAME).is_file():
            raise StudyFolderError(
                f"{self.folder / ORDER_NAME} exists: a participant's order is fixed at their first run"
            )
        atomic_write_text(self.folder / ORDER_NAME, _json(dict(order)))

    def insert_steps(self, after: int, steps: list[dict[str, Any]]) -> list[dict[str, Any]]:
        """Put ``steps`` into the recorded order right after step ``after`` (a calibration run again: the
        only change an order takes, and only to steps not yet run); returns the new steps. Done already
        (a kill between this and the step's line): the order as it is."""
        order = self.order()
        if order is None:
            raise StudyFolderError(f"{self.folder / ORDER_NAME}: missing; {_RESTORE}")
        old = order["steps"]
        if len(self.progress()) > after:
            raise StudyFolderError(f"{self.progress_file}: step {after} is recorded; its order cannot change now")
        keys = [step_key(s) for s in steps]
        if [step_key(s) for s in old[after + 1 : after + 1 + len(steps)]] == keys:
            return old
        new = [*old[: after + 1], *steps, *old[after + 1 :]]
        atomic_write_text(
            self.folder / ORDER_NAME,
            _json({**order, "steps": new, "inserted": [*order.get("inserted", []), {"after": after, "keys": keys}]}),
        )
        return new

    # ------------------------------------------------------------------ the manifest of what ran
    def progress(self) -> list[dict[str, Any]]:
        """The finished steps, in order; a torn last line (a kill mid-write) is left out."""
        try:
            data = self.progress_file.read_bytes()
        except FileNotFoundError:
            return []
        out: list[dict[str, Any]] = []
        for i, line in enumerate(data.split(b"\n")):
            if not line:
                continue
            try:
                rec = json.loads(line)
            except ValueError:
                if not data.endswith(b"\n") and line == data.rsplit(b"\n", 1)[-1]:
                    break  # the torn last line
                raise StudyFolderError(
                    f"{self.progress_file}: line {i + 1} is not JSON (edited by hand?); {_RESTORE}"
                ) from None
            if not isinstance(rec, dict) or rec.get("step") != len(out) or not isinstance(rec.get("kind"), str):
                raise StudyFolderError(
                    f"{self.progress_file}: line {i + 1} is not the record of step {len(out)} (edited by hand?); "
                    f"{_RESTORE}"
                )
            out.append(rec)
        return out

    def _cut_torn_tail(self) -> None:
        path = self.progress_file
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            return
        if data and not data.endswith(b"\n"):
            keep = data.rfind(b"\n") + 1
            with open(path, "r+b") as fh:
                fh.truncate(keep)
                fh.flush()
                os.fsync(fh.fileno())

    def append(self, record: Mapping[str, Any]) -> None:
        """Commit one finished step: one whole line, appended and fsync'ed."""
        self.folder.mkdir(parents=True, exist_ok=True)
        self._cut_torn_tail()
        line = (json.dumps(finite_json(dict(record)), allow_nan=False, sort_keys=False) + "\n").encode("utf-8")
        new = not self.progress_file.exists()
        fd = os.open(self.progress_file, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
        try:
            os.write(fd, line)
            os.fsync(fd)
        finally:
            os.close(fd)
        if new:
            fsync_dir(self.folder)

    def block(self, name: str) -> Path:
        return self.folder / name

    def _manifest(self, block: str) -> dict[str, Any] | None:
        path = self.block(block) / MANIFEST_NAME
        if not path.is_file():
            return None
        try:
            manifest = json.loads(path.read_bytes().decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            raise StudyFolderError(f"{path}: not JSON (edited by hand?); {_RESTORE}") from None
        if not isinstance(manifest, dict) or not isinstance(manifest.get("trials"), list):
            raise StudyFolderError(f"{path}: not a dataset manifest (edited by hand?); {_RESTORE}")
        return manifest

    def audit(self, steps: list[dict[str, Any]], done: list[dict[str, Any]] | None = None) -> None:
        """Cross-check the progress log against the order and the blocks' manifests (module docstring);
        one :class:`StudyFolderError` line naming the file and what to do. The one trial on disk the log
        may not know is the next step's (a kill between its two commits; :meth:`reconcile` records it)."""
        done = self.progress() if done is None else done
        where = self.folder / ORDER_NAME
        if len(done) > len(steps):
            raise StudyFolderError(
                f"{self.progress_file}: {len(done)} steps recorded, {where} has {len(steps)}; {_RESTORE}"
            )
        for i, rec in enumerate(done):
            if rec.get("key") != step_key(steps[i]):
                raise StudyFolderError(
                    f"{self.progress_file}: line {i + 1} is not step {i} of {where} (edited by hand?); {_RESTORE}"
                )
        on_disk: dict[int, tuple[str, str]] = {}  # step -> (block, file) of every study trial in the blocks
        for block in dict.fromkeys(s["block"] for s in steps if s["kind"] == "trial"):
            manifest = self._manifest(block)
            recorded = [r for r in done if r["kind"] == "trial" and r.get("block") == block]
            path = self.block(block) / MANIFEST_NAME
            if manifest is None:
                if recorded:
                    raise StudyFolderError(
                        f"{path}: missing, but {self.progress_file} records {len(recorded)} trials of block {block!r} "
                        f"(deleted?); {_RESTORE} (nothing is run again)"
                    )
                continue
            for entry in manifest["trials"]:
                meta = entry.get("meta") if isinstance(entry, dict) else None
                k = ((meta or {}).get("extra") or {}).get("study_step")
                if not isinstance(k, int) or k in on_disk or not isinstance(entry.get("file"), str):
                    raise StudyFolderError(
                        f"{path}: an entry that is not one of this participant's trials, or one listed twice "
                        f"(edited by hand?); {_RESTORE}"
                    )
                on_disk[k] = (block, entry["file"])
        for k, (block, file) in sorted(on_disk.items()):
            if (
                k < len(done)
                and done[k]["kind"] == "trial"
                and (done[k].get("block"), done[k].get("file")) == (block, file)
            ):
                path = self.block(block) / file
                if not path.is_file():
                    raise StudyFolderError(
                        f"{path}: missing (step {k}, listed in {MANIFEST_NAME} and "
                        f"{PROGRESS_NAME}); {_RESTORE} (nothing is run again)"
                    )
                recorded_sha = done[k].get("sha256")  # absent in lines written before the digest was kept
                on_disk_sha = None if recorded_sha is None else file_sha256(path)
                if on_disk_sha != recorded_sha:
                    raise StudyFolderError(
                        f"{path}: changed after it was recorded (step {k}: sha256 {str(recorded_sha)[:12]} in "
                        f"{PROGRESS_NAME}, {str(on_disk_sha)[:12]} on disk); {_RESTORE} (nothing is run again)"
                    )
                continue
            if k == len(done) and k == max(on_disk) and k < len(steps) and steps[k]["kind"] == "trial":
                continue  # the next step's trial, committed without its line: reconcile records it
            raise StudyFolderError(
                f"{self.progress_file}: records {len(done)} steps, but {self.block(block) / MANIFEST_NAME} holds "
                f"{file}, the trial of step {k}, which it does not record (the log was truncated or emptied?); "
                f"{_RESTORE} (nothing is run again)"
            )
        for i, rec in enumerate(done):
            if rec["kind"] == "trial" and on_disk.get(i) != (rec.get("block"), rec.get("file")):
                raise StudyFolderError(
                    f"{self.block(str(rec.get('block'))) / MANIFEST_NAME}: does not list {rec.get('file')}, the trial "
                    f"of step {i} that {self.progress_file} records (lost?); {_RESTORE} (nothing is run again)"
                )
        self._audit_person_models(done, steps)

    def _audit_person_models(self, done: list[dict[str, Any]], steps: list[dict[str, Any]]) -> None:
        """Every person model the log records as fitted is on disk as it was (its files' SHA-256): each model's last
        fit (a calibration that asked for more trials fits P0 again, over the first fit's files). A model the next
        step fits again is left out: a kill after that fit's files were swapped in and before its line was written
        leaves them the next fit's, which the resumed run fits again (the same trials, the same model) and records."""
        from coassist.scenario.person_model import PERSON_MODEL_FILE

        pending = steps[len(done)] if len(done) < len(steps) else {}
        refitting = pending.get("model") if pending.get("kind") == "fit" else None
        last = {rec.get("model"): i for i, rec in enumerate(done) if rec["kind"] == "fit" and not rec.get("failed")}
        for i, rec in enumerate(done):
            if rec["kind"] != "fit" or rec.get("failed"):
                continue
            digests = rec.get("sha256")
            if not isinstance(digests, dict) or not isinstance(rec.get("model"), str):
                raise StudyFolderError(
                    f"{self.progress_file}: line {i + 1} is not a person model's record (edited by hand?); {_RESTORE}"
                )
            if last[rec["model"]] != i or rec["model"] == refitting:  # fitted again later, or being fitted again
                continue
            for task, digest in digests.items():
                path = self.folder / "models" / rec["model"] / str(task) / PERSON_MODEL_FILE
                try:
                    now = _sha256(path.read_bytes())
                except OSError:
                    now = None
                if now != digest:
                    raise StudyFolderError(
                        f"{path}: {'missing' if now is None else 'changed'} since it was fitted (step {i}, sha256 "
                        f"{str(digest)[:12]} in {PROGRESS_NAME}); {_RESTORE} (nothing is fitted again)"
                    )

    def reconcile(self, steps: list[dict[str, Any]]) -> int:
        """Write the line of a trial that was committed to its dataset but not to the progress file
        (a kill between the two); returns how many lines were recovered (0 or 1)."""
        self._cut_torn_tail()
        done = self.progress()
        k = len(done)
        if k >= len(steps) or steps[k]["kind"] != "trial":
            return 0
        step = steps[k]
        manifest = self._manifest(step["block"])
        if manifest is None:
            return 0
        for entry in manifest["trials"]:
            extra = entry.get("meta", {}).get("extra", {})
            if extra.get("study_step") == k:
                file = entry["file"]
                sha = file_sha256(self.block(step["block"]) / file)
                more = _recovered_model_fields(done, step, extra)
                self.append(trial_record(k, step, file, entry["meta"], sha256=sha, recovered=True, **more))
                return 1
        return 0


def _recovered_model_fields(done: list[dict[str, Any]], step: Mapping[str, Any], extra: Mapping[str, Any]) -> dict:
    """The model fields of a recovered trial's line, as the run writes them (``model``, ``model_sha256`` where a person
    model assisted, ``waited_for_model_s``): from the trial's own meta (``study_model``, ``study_model_sha256``), else
    (a trial written before the meta held it) the digest for the trial's task that the model's last fit line records
    (the run checks the file against it before every trial). The wait was not kept: None."""
    model = extra.get("study_model")
    more: dict[str, Any] = {"model": model, "waited_for_model_s": None}
    digest = extra.get("study_model_sha256")
    if digest is None and str(step.get("intent", "")).startswith("person:"):
        fits = [r for r in done if r.get("kind") == "fit" and not r.get("failed") and r.get("model") == model]
        digest = fits[-1].get("sha256", {}).get(step.get("task")) if fits else None
    if digest is not None:
        more["model_sha256"] = digest
    return more


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's bytes (hex): what a trial's progress line records of its parquet file."""
    return _sha256(path.read_bytes())


def trial_record(
    k: int, step: Mapping[str, Any], file: str, meta: Mapping[str, Any], *, sha256: str, **more: Any
) -> dict[str, Any]:
    """The progress line of trial step ``k`` written as ``file`` of its block, whose bytes hash to ``sha256``
    (checked by :meth:`ParticipantFolder.audit` on every run and report)."""
    extra = meta.get("extra", {})
    return {
        "step": k,
        "kind": "trial",
        "key": step_key(step),
        "block": step["block"],
        "file": file,
        "sha256": sha256,
        "model_id": meta.get("model_id"),
        "ended": extra.get("ended"),
        "t": utc_now(),
        **more,
    }


def step_key(step: Mapping[str, Any]) -> str:
    """What identifies a step in the recorded order (its kind, block and index)."""
    return f"{step['kind']}:{step.get('block', '')}:{step.get('index', '')}"
