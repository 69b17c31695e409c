"""The study folder: the plan and its hash, who took part in which order, and what has run.

::

    studies/<name>/
      plan.toml                  the plan as given, byte for byte
      study.json                 its SHA-256, the blinding key (condition → label), the
                                 weights' SHA-256 of every model it names, the Latin square
      participants.json          pseudonymous id → number, Latin-square row, simulated or not
      participants/<id>/
        order.json               the participant's steps, fixed at their first run
        progress.jsonl           the manifest of what ran: one line per finished step
        <block>/                 a dataset per condition or round (coassist train, evaluate and
                                 show read it): manifest.json + trial_*.parquet
        practice/                the practice trials (a dataset too; not analysed)
        models/<name>/           the models the study trained for this participant

Nothing personal is stored: an id is 1–32 letters, digits, ``-`` or ``_`` chosen by the
researcher (``P07``), and trials carry it as their user.

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
changed model it names) is refused with one line.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import coassist
from coassist._io import OutputLock, atomic_write_text, fsync_dir
from coassist.data.store import MANIFEST_NAME
from coassist.errors import CoassistError
from coassist.study.design import blinding_labels, latin_square_rows
from coassist.study.plan import StudyPlan, load_plan

__all__ = ["PARTICIPANT_ID", "ParticipantFolder", "StudyFolder", "StudyFolderError", "init_study"]

FORMAT = "coassist-study/1"
PLAN_NAME = "plan.toml"
STUDY_NAME = "study.json"
PARTICIPANTS_NAME = "participants.json"
ORDER_NAME = "order.json"
PROGRESS_NAME = "progress.jsonl"
#: A pseudonymous participant id: it names a folder, and nothing else about the person.
PARTICIPANT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,31}$")


class StudyFolderError(CoassistError, ValueError):
    """A study folder that cannot be used as asked; one line saying why."""


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _json(obj: Any) -> str:
    return json.dumps(obj, indent=1, allow_nan=False, sort_keys=False) + "\n"


def model_weights_hash(path: str | Path) -> str:
    """The ``weights_sha256`` a model's sidecar records (what identifies its weights)."""
    try:
        meta = json.loads((Path(path) / "model.json").read_text("utf-8"))
        return str(meta["weights_sha256"])
    except (OSError, ValueError, KeyError, TypeError):
        raise StudyFolderError(f"{path}: not a readable model folder (model.json with weights_sha256)") from None


def init_study(plan_file: str | Path, out: str | Path) -> StudyFolder:
    """Validate ``plan_file`` and make ``out`` its study folder (module docstring).

    An existing study folder with the same plan is left as it is; with another plan it is
    updated only while no trial has run (else :class:`StudyFolderError`, one line).
    """
    plan_file = Path(plan_file)
    plan = load_plan(plan_file)
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
            if old.any_trial():
                raise StudyFolderError(
                    f"{out}: trials have run under its plan (sha256 {old.record['plan_sha256'][:12]}); a changed plan "
                    "needs a new study folder"
                )
        labels = blinding_labels(max(len(_condition_names(plan)), 1), plan.seed)
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
            "labels": dict(zip(_condition_names(plan), labels)),
            "models": {p: model_weights_hash(p) for p in plan.model_paths()},
            "latin_square": latin_square_rows(max(len(_condition_names(plan)), 1)),
        }
        out.mkdir(parents=True, exist_ok=True)
        (out / "participants").mkdir(exist_ok=True)
        from coassist._io import atomic_write_bytes

        atomic_write_bytes(out / PLAN_NAME, raw)
        atomic_write_text(out / STUDY_NAME, _json(record))
        if not (out / PARTICIPANTS_NAME).is_file():
            atomic_write_text(out / PARTICIPANTS_NAME, _json({}))
    return StudyFolder(out)


def _condition_names(plan: StudyPlan) -> list[str]:
    """The blinded conditions of the plan's protocol (those shown as A, B, C…), in the plan's order."""
    if plan.protocol == "comparison":
        return [c.name for c in plan.conditions]
    if plan.protocol == "transfer":
        return ["source", "transferred"]
    if plan.protocol == "online":
        return ["online", "offline"]
    return []  # iterative: rounds, not conditions


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

        return plan_from_text((self.folder / PLAN_NAME).read_text("utf-8"), self.record["plan_dir"])

    def check_plan(self) -> None:
        """One line if ``plan.toml`` or a model it names changed since ``study init``."""
        raw = (self.folder / PLAN_NAME).read_bytes()
        if _sha256(raw) != self.record["plan_sha256"]:
            raise StudyFolderError(
                f"{self.folder / PLAN_NAME} changed after study init (sha256 {self.record['plan_sha256'][:12]} recorded, "
                f"{_sha256(raw)[:12]} now): {'trials have run under the old one; start a new study folder' if self.any_trial() else 'run coassist study init again'}"
            )
        for path, digest in self.record["models"].items():
            if model_weights_hash(path) != digest:
                raise StudyFolderError(
                    f"{path}: the model's weights changed after study init (the study compares the "
                    "weights it recorded); start a new study folder"
                )

    @property
    def labels(self) -> dict[str, str]:
        """The blinding key: condition → label (never sent to the page)."""
        return dict(self.record["labels"])

    # ------------------------------------------------------------------ participants
    def participants(self) -> dict[str, dict[str, Any]]:
        try:
            return json.loads((self.folder / PARTICIPANTS_NAME).read_text("utf-8"))
        except FileNotFoundError:
            return {}

    def any_trial(self) -> bool:
        """Whether any participant has a finished step on record."""
        root = self.folder / "participants"
        return root.is_dir() and any(
            (p / PROGRESS_NAME).is_file() and (p / PROGRESS_NAME).stat().st_size > 0 for p in root.iterdir()
        )

    def register(self, participant: str, simulated: bool = False) -> dict[str, Any]:
        """The participant's record, made at their first run: number (1, 2, … in order of arrival),
        Latin-square row (number − 1), and whether a simulated operator stands in (``--simulate``)."""
        if not isinstance(participant, str) or not PARTICIPANT_ID.match(participant):
            raise StudyFolderError(
                f"--participant must be 1-32 letters, digits, '-' or '_' (a pseudonymous id; it "
                f"names a folder), got {participant!r}"
            )
        with OutputLock(self.folder / PARTICIPANTS_NAME):
            table = self.participants()
            if participant in table:
                rec = table[participant]
                if bool(rec.get("simulated")) != bool(simulated):
                    what = "a simulated participant" if rec.get("simulated") else "a person"
                    raise StudyFolderError(
                        f"--participant {participant} is {what} in this study; "
                        f"{'add' if rec.get('simulated') else 'leave out'} --simulate"
                    )
                return rec
            number = len(table) + 1
            rec = {"number": number, "row": number - 1, "simulated": bool(simulated), "registered": utc_now()}
            table[participant] = rec
            atomic_write_text(self.folder / PARTICIPANTS_NAME, _json(table))
            return rec

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
        return json.loads(path.read_text("utf-8"))

    def write_order(self, order: Mapping[str, Any]) -> None:
        """Fix the participant's steps (once, at the first run)."""
        if (self.folder / ORDER_NAME).is_file():
            raise StudyFolderError(
                f"{self.folder / ORDER_NAME} exists: a participant's order is fixed at their first run"
            )
        atomic_write_text(self.folder / ORDER_NAME, _json(dict(order)))

    # ------------------------------------------------------------------ the manifest of what ran
    def progress(self) -> list[dict[str, Any]]:
        """The finished steps, in order; a torn last line (a kill mid-write) is left out."""
        try:
            data = self.progress_file.read_bytes()
        except FileNotFoundError:
            return []
        out = []
        for i, line in enumerate(data.split(b"\n")):
            if not line:
                continue
            try:
                rec = json.loads(line)
            except ValueError:
                if not data.endswith(b"\n") and line == data.rsplit(b"\n", 1)[-1]:
                    break  # the torn last line
                raise StudyFolderError(f"{self.progress_file}: line {i + 1} is not JSON (edited by hand?)") from None
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
        line = (json.dumps(dict(record), allow_nan=False, sort_keys=False) + "\n").encode("utf-8")
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

    def reconcile(self, steps: list[dict[str, Any]]) -> int:
        """Write the line of a trial that was committed to its dataset but not to the progress file
        (a kill between the two); returns how many lines were recovered (0 or 1)."""
        self._cut_torn_tail()
        done = self.progress()
        k = len(done)
        if k >= len(steps) or steps[k]["kind"] != "trial":
            return 0
        step = steps[k]
        folder = self.block(step["block"])
        if not (folder / MANIFEST_NAME).is_file():
            return 0
        manifest = json.loads((folder / MANIFEST_NAME).read_text("utf-8"))
        for entry in manifest["trials"]:
            if entry.get("meta", {}).get("extra", {}).get("study_step") == k:
                self.append(trial_record(k, step, entry["file"], entry["meta"], recovered=True))
                return 1
        return 0


def trial_record(k: int, step: Mapping[str, Any], file: str, meta: Mapping[str, Any], **more: Any) -> dict[str, Any]:
    """The progress line of trial step ``k`` written as ``file`` of its block."""
    extra = meta.get("extra", {})
    return {
        "step": k,
        "kind": "trial",
        "key": step_key(step),
        "block": step["block"],
        "file": file,
        "model_id": meta.get("model_id"),
        "ended": extra.get("ended"),
        "t": utc_now(),
        **more,
    }


def step_key(step: Mapping[str, Any]) -> str:
    """What identifies a step in the recorded order (its kind, block and index)."""
    return f"{step['kind']}:{step.get('block', '')}:{step.get('index', '')}"
