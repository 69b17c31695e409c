"""Datasets on disk (docs/architecture.md, *Formats*): a folder of trial files and its manifest.

A dataset (the thesis' D_k, Algorithm 4.1) is a folder of trial files plus
``manifest.json`` (id, description, the trial files with their meta, creation time,
coassist version). Its paths must stay inside the folder. A new dataset is written in
a folder beside the old one and swapped in whole at the end, under the output's lock,
so a crash leaves either the old dataset or the new one (:mod:`coassist._io`, the one
writer of the project: every file is written to a temporary file, fsync'ed, renamed,
and the folder fsync'ed). :class:`DatasetWriter` writes trials as they finish and lets
an interrupted collection continue.

Each trial is one Parquet file (:mod:`coassist.data.trial_file`). Every defect of a file is one
:class:`~coassist.data.trial_file.TrialFileError` naming the file and the problem; a manifest
that cannot be used, one :class:`ManifestError`.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import shutil
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

import coassist
from coassist._checks import check_int, is_integer
from coassist._io import (
    OutputLock,
    atomic_write,
    no_constant,
    no_duplicate_keys,
    partial_folder,
    remove_stale,
    staged_folder,
    swap_in,
)
from coassist.data.trial import Trial, TrialMeta
from coassist.data.trial_file import FORMAT_VERSION, META_KEY, TrialFileError, read_trial, write_trial

__all__ = [
    "MANIFEST_NAME",
    "ManifestError",
    "Dataset",
    "DatasetWriter",
    "append_to_dataset",
    "digest",
    "manifest_files",
    "read_dataset",
    "read_dataset_trial",
    "unfinished_collection",
    "write_dataset",
]

MANIFEST_NAME = "manifest.json"
DATASET_FORMAT = "coassist.dataset"


class ManifestError(TrialFileError):
    """A dataset's ``manifest.json`` that cannot be used (the whole dataset, not one trial)."""


# --------------------------------------------------------------------------- datasets


@dataclass(frozen=True, eq=False)
class Dataset:
    """A dataset D_k: its id, its trials (in manifest order) and the manifest itself.

    ``files`` names the trial file of each loaded trial; ``skipped`` lists
    ``(file, reason)`` for the trials :func:`read_dataset` left out with ``skip_bad``.
    """

    id: str
    trials: tuple[Trial, ...]
    manifest: Mapping[str, Any]
    files: tuple[str, ...] = ()
    skipped: tuple[tuple[str, str], ...] = ()

    @property
    def description(self) -> str:
        return str(self.manifest.get("description", ""))

    def __len__(self) -> int:
        return len(self.trials)


def _trial_file_name(index: int) -> str:
    return f"trial_{index:05d}.parquet"


def _check_id(dataset_id: str) -> str:
    if not isinstance(dataset_id, str) or not dataset_id.strip():
        raise ValueError(f"dataset_id must be a non-empty string, got {dataset_id!r}")
    return dataset_id


def _collect_trials(trials: Iterable[Trial]) -> list[Trial]:
    out = list(trials)
    for i, t in enumerate(out):
        if not isinstance(t, Trial):
            raise ValueError(f"trials[{i}] is a {type(t).__name__}, expected Trial")
    return out


def _write_manifest(folder: Path, manifest: Mapping[str, Any]) -> None:
    text = json.dumps(manifest, indent=2, allow_nan=False) + "\n"
    atomic_write(folder / MANIFEST_NAME, lambda fh: fh.write(text.encode()))


def _confined(folder: Path, name: Any, where: str, path: Path) -> str:
    """A manifest's trial file name, refused unless it stays inside the dataset folder."""
    if not isinstance(name, str) or not name.strip() or "\0" in name:  # a NUL: no file name (os refuses it)
        raise ManifestError(f"{path}: {where} 'file' must be a file name, got {name!r}")
    root = folder.resolve()
    target = (folder / name).resolve()
    if Path(name).is_absolute() or not target.is_relative_to(root) or target == root:
        raise ManifestError(f"{path}: {where} 'file' {name!r} points outside the dataset folder {folder}")
    return name


def manifest_files(folder: str | os.PathLike[str]) -> list[str]:
    """The trial files a dataset folder's validated manifest lists, in order."""
    return [str(e["file"]) for e in _read_manifest(Path(folder))["trials"]]


def _read_manifest(folder: Path) -> dict[str, Any]:
    """The validated manifest; every defect is a :class:`TrialFileError` naming the file."""
    path = folder / MANIFEST_NAME
    if not path.is_file():
        raise FileNotFoundError(f"no dataset at {folder}: {MANIFEST_NAME} not found")
    try:
        data = path.read_bytes()
    except OSError as exc:  # unreadable (its permissions, a dead mount): named, not a traceback
        raise ManifestError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    try:
        # a key given twice (a hand edit: plain JSON keeps the last silently), NaN or ±Infinity: refused
        manifest = json.loads(data.decode("utf-8"), object_pairs_hook=no_duplicate_keys, parse_constant=no_constant)
    except UnicodeDecodeError as exc:
        raise ManifestError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise ManifestError(f"{path}: malformed JSON: {exc}") from None
    except RecursionError:  # nested deeper than the parser goes: no manifest coassist writes
        raise ManifestError(f"{path}: malformed JSON: nested too deep") from None
    except ValueError as exc:  # the hooks' refusals, an integer of more digits than Python converts
        raise ManifestError(f"{path}: {exc}") from None
    if not isinstance(manifest, dict):
        raise ManifestError(f"{path}: must hold a JSON object, got {type(manifest).__name__}")
    for key in ("dataset_id", "trials", "format_version"):
        if key not in manifest:
            raise ManifestError(f"{path}: missing key {key!r}")
    if manifest.get("format") != DATASET_FORMAT:
        raise ManifestError(f"{path}: 'format' is {manifest.get('format')!r}, expected {DATASET_FORMAT!r}")
    version = manifest["format_version"]
    if not is_integer(version) or version < 1:
        raise ManifestError(f"{path}: 'format_version' must be an integer >= 1, got {json.dumps(version)}")
    if version > FORMAT_VERSION:
        raise ManifestError(f"{path}: format version {version} is newer than this coassist reads ({FORMAT_VERSION})")
    if not isinstance(manifest["dataset_id"], str) or not manifest["dataset_id"].strip():
        raise ManifestError(
            f"{path}: 'dataset_id' must be a non-empty string, got {json.dumps(manifest['dataset_id'])}"
        )
    entries = manifest["trials"]
    if not isinstance(entries, list):
        raise ManifestError(f"{path}: 'trials' must be a list, got {json.dumps(entries)}")
    seen: set[str] = set()
    for i, entry in enumerate(entries):
        where = f"trials[{i}]"
        if not isinstance(entry, dict):
            raise ManifestError(f"{path}: {where} must be an object, got {json.dumps(entry)}")
        if "file" not in entry:
            raise ManifestError(f"{path}: {where} has no 'file'")
        name = _confined(folder, entry["file"], where, path)
        # the file it names, not its spelling: "./trial_00000.parquet" is "trial_00000.parquet" a second time
        target = str((folder / name).resolve())
        if target in seen:
            raise ManifestError(f"{path}: {where} lists {name!r} a second time")
        seen.add(target)
        if not isinstance(entry.get("meta"), dict):
            raise ManifestError(f"{path}: {where} ({name}) has no 'meta' object")
    n = manifest.get("n_trials", len(entries))
    if n != len(entries):
        raise ManifestError(f"{path}: 'n_trials' is {json.dumps(n)} but 'trials' lists {len(entries)}")
    return manifest


def _entry(name: str, trial: Trial) -> dict[str, Any]:
    return {"file": name, "n_samples": trial.n_samples, "meta": trial.meta.to_dict()}


def _new_manifest(dataset_id: str, description: str, entries: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "format": DATASET_FORMAT,
        "format_version": FORMAT_VERSION,
        "dataset_id": dataset_id,
        "description": description,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "coassist_version": coassist.__version__,
        "n_trials": len(entries),
        "trials": entries,
    }


def _destination(folder: str | os.PathLike[str]) -> Path:
    """The folder a dataset is written into: a symlink's target (a dataset kept on another disk), so that it is
    staged, swapped and locked where its data are; the link was swapped out for a new folder beside it, the linked
    data left as they were."""
    folder = Path(folder)
    return folder.resolve() if folder.is_symlink() else folder


def _check_destination(folder: Path, overwrite: bool) -> None:
    """Refuse a destination that is a file, or a non-empty folder without ``overwrite``."""
    if folder.exists() or folder.is_symlink():
        if not folder.is_dir():
            raise FileExistsError(f"{folder} exists and is not a folder")
        if any(folder.iterdir()) and not overwrite:
            raise FileExistsError(f"{folder} exists and is not empty; pass overwrite=True to replace it")
    elif any(p.exists() and not p.is_dir() for p in folder.parents):
        bad = next(p for p in reversed(folder.parents) if p.exists() and not p.is_dir())
        raise NotADirectoryError(f"{folder}: {bad} is a file, not a folder")


def _keep_unlisted(old: Path, new: Path) -> None:
    """Carry the files of ``old`` that its manifest does not list (notes, figures) into ``new``, but those named
    after a trial file of either (``trial_00000.mcap`` beside ``trial_00000.parquet``: the replaced trial's, which
    beside the new trial of that name looked like its own)."""
    listed = {MANIFEST_NAME}
    try:
        listed |= {e["file"] for e in _read_manifest(old)["trials"]}
    except (FileNotFoundError, TrialFileError):
        pass
    trials = {name.partition(".")[0] for name in listed - {MANIFEST_NAME}}
    trials |= {e["file"].partition(".")[0] for e in _read_manifest(new)["trials"]}
    for p in old.iterdir():
        if p.name in listed or p.name.partition(".")[0] in trials or (new / p.name).exists():
            continue
        if p.is_dir():
            shutil.copytree(p, new / p.name)
        else:
            try:
                os.link(p, new / p.name)
            except OSError:
                shutil.copy2(p, new / p.name)


def write_dataset(
    trials: Iterable[Trial],
    folder: str | os.PathLike[str],
    dataset_id: str,
    description: str = "",
    *,
    overwrite: bool = False,
) -> Path:
    """Write trials as a dataset folder (trial files + ``manifest.json``).

    The new dataset is written into a folder beside ``folder`` and swapped in whole at
    the end (:func:`coassist._io.swap_in`): a crash at any point leaves the old dataset
    (or nothing) intact. ``folder`` is locked while written (:class:`coassist._io.OutputLock`).

    Parameters
    ----------
    trials : iterable of Trial
    folder : path-like
        Created if needed.
    dataset_id : str
        The dataset's id (e.g. ``"D0"``), recorded in the manifest and in models
        trained on it.
    description : str
    overwrite : bool
        A folder that exists and is not empty is refused unless True. With True, the
        new dataset replaces the old one; files the old manifest did not list (notes,
        figures) are carried over.

    Returns
    -------
    Path
        The dataset folder.
    """
    folder = _destination(folder)
    _check_id(dataset_id)
    if not isinstance(description, str):
        raise ValueError(f"description must be a string, got {type(description).__name__}")
    items = _collect_trials(trials)
    _check_destination(folder, overwrite)
    with OutputLock(folder):
        _check_destination(folder, overwrite)  # again, now that no other run can write it
        with staged_folder(folder) as staging:
            entries = []
            for i, trial in enumerate(items):
                name = _trial_file_name(i)
                write_trial(trial, staging / name)
                entries.append(_entry(name, trial))
            _write_manifest(staging, _new_manifest(dataset_id, description, entries))
            if folder.is_dir():
                _keep_unlisted(folder, staging)
    return folder


def append_to_dataset(trials: Iterable[Trial], folder: str | os.PathLike[str]) -> Path:
    """Add trials to an existing dataset (new files after the existing ones).

    The manifest, the commit point, is rewritten atomically after the new trial files
    are in place; a crash before leaves the old dataset (plus unlisted files).
    """
    folder = _destination(folder)
    items = _collect_trials(trials)
    with OutputLock(folder):
        manifest = _read_manifest(folder)
        entries = list(manifest["trials"])
        used = {e["file"] for e in entries}
        index = len(entries)
        for trial in items:
            while _trial_file_name(index) in used:
                index += 1
            name = _trial_file_name(index)
            write_trial(trial, folder / name)
            entries.append(_entry(name, trial))
            used.add(name)
        manifest["trials"] = entries
        manifest["n_trials"] = len(entries)
        manifest["modified"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
        _write_manifest(folder, manifest)
    return folder


def read_dataset(
    folder: str | os.PathLike[str],
    *,
    skip_bad: bool = False,
) -> Dataset:
    """Read a dataset folder written by :func:`write_dataset`.

    Every trial listed in the manifest is loaded, and its meta must equal the one in
    the manifest (a mismatch means the folder was edited by hand).

    Parameters
    ----------
    folder : the dataset folder (holds ``manifest.json`` and the trial files).
    skip_bad : bool
        False: the first unreadable trial file raises (:class:`TrialFileError` or
        ``FileNotFoundError``, naming it). True: such trials are left out and listed in
        ``Dataset.skipped`` with the reason. A bad manifest always raises.
    """
    folder = Path(folder)
    manifest = _read_manifest(folder)
    trials, files, skipped = [], [], []
    for entry in manifest["trials"]:
        try:
            trial = _read_entry(folder, entry)
        except (TrialFileError, FileNotFoundError) as exc:
            if not skip_bad:
                raise
            skipped.append((entry["file"], str(exc)))
            continue
        trials.append(trial)
        files.append(entry["file"])
    return Dataset(
        id=str(manifest["dataset_id"]),
        trials=tuple(trials),
        manifest=manifest,
        files=tuple(files),
        skipped=tuple(skipped),
    )


def _read_entry(folder: Path, entry: Mapping[str, Any]) -> Trial:
    path = folder / entry["file"]
    trial = read_trial(path)
    try:
        listed = TrialMeta.from_dict(entry["meta"])
    except ValueError as exc:
        raise TrialFileError(f"{folder / MANIFEST_NAME}: bad meta for {entry['file']!r}: {exc}") from None
    if listed != trial.meta:
        raise TrialFileError(f"{path}: meta differs from the one listed in {folder / MANIFEST_NAME}")
    n = entry.get("n_samples")
    if n is not None and n != trial.n_samples:
        raise TrialFileError(f"{path}: holds {trial.n_samples} samples, {folder / MANIFEST_NAME} lists {json.dumps(n)}")
    return trial


def read_dataset_trial(folder: str | os.PathLike[str], index: int) -> Trial:
    """Only trial ``index`` (manifest order) of a dataset folder: other trials are not read."""
    folder = Path(folder)
    entries = _read_manifest(folder)["trials"]
    if not is_integer(index) or not 0 <= index < len(entries):
        raise ValueError(f"{folder}: index must be in [0, {len(entries)}), got {index!r}")
    return _read_entry(folder, entries[index])


def unfinished_collection(folder: str | os.PathLike[str]) -> str:
    """ "" where ``folder`` is not a :class:`DatasetWriter`'s unfinished ``.<name>.partial`` (its ``progress.json``
    there until :meth:`DatasetWriter.finish`); else one line saying it is one, for the commands that would read its
    trials as a folder of trial files: some of a collection would pass for all of it."""
    folder = Path(folder)
    if not (folder / DatasetWriter.PROGRESS).is_file():
        return ""
    done, of, what = _partial_progress(folder)
    return (
        f"{folder}: an unfinished collection ({done}{of} trials written{'; ' + what if what else ''}): the command "
        "that started it finishes it (run it again: it resumes), then read the folder it writes"
    )


def _partial_progress(partial: Path) -> tuple[int, str, str]:
    """What an unfinished collection's ``partial`` folder holds, for a line naming it: its trial files, " of N" (the
    trials it was to write; "" where its progress record does not say) and its description ("" likewise)."""
    done = len(list(partial.glob("trial_*.parquet")))
    try:
        record = json.loads((partial / DatasetWriter.PROGRESS).read_text("utf-8"))
    except (OSError, ValueError):
        record = None
    record = record if isinstance(record, dict) else {}
    of = f" of {record['n_trials']}" if is_integer(record.get("n_trials")) else ""
    what = record["description"] if isinstance(record.get("description"), str) else ""
    return done, of, what


# --------------------------------------------------------------------------- resumable writing


class DatasetWriter:
    """Write a dataset trial by trial as the trials finish, resumably.

    Trials go into ``.<name>.partial`` beside the destination, each file atomic, so a
    killed run keeps every trial it finished. A later writer for the same destination
    and the same ``key`` (a digest of what is being collected) picks them up
    (:meth:`has` tells which); a different key is refused, naming them, unless ``overwrite`` (which discards them:
    :attr:`discarded`). :meth:`finish` writes the
    manifest and swaps the folder in at the destination, replacing an old dataset only
    then. The destination is locked from ``__enter__`` to ``__exit__``.

    ::

        with DatasetWriter(out, "D0", n_trials=60, key=digest, overwrite=True) as w:
            for i, trial in run(todo=[i for i in range(60) if not w.has(i)]):
                w.add(i, trial)
            w.finish()

    ``keep``: the writer also holds each trial it writes, and :meth:`dataset` gives the finished
    dataset as :func:`read_dataset` reads it, those trials as they were written instead of read back.
    """

    PROGRESS = "progress.json"

    def __init__(
        self,
        folder: str | os.PathLike[str],
        dataset_id: str,
        *,
        n_trials: int,
        key: str,
        description: str = "",
        overwrite: bool = False,
        keep: bool = False,
    ) -> None:
        self.folder = _destination(folder)
        self.dataset_id = _check_id(dataset_id)
        self._kept: dict[int, Trial] | None = {} if keep else None
        self._finished = False
        self._created = False  # whether this writer made the partial folder (nothing of another run's in it)
        n_trials = check_int(n_trials, "n_trials", 1)
        if not isinstance(key, str) or not key:
            raise ValueError(f"key must be a non-empty string, got {key!r}")
        self.n_trials, self.key, self.description, self.overwrite = n_trials, key, description, overwrite
        self.partial = partial_folder(self.folder)
        self.resumed: list[int] = []  #: indices found done in a partial folder
        self.discarded: bool = False  #: a partial folder of another collection was removed
        self._lock = OutputLock(self.folder)
        self._done: set[int] = set()
        _check_destination(self.folder, overwrite)

    def __enter__(self) -> DatasetWriter:
        self._lock.__enter__()
        try:
            _check_destination(self.folder, self.overwrite)
            self._open_partial()
        except BaseException:
            self._lock.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            if exc[0] is not None and self._created and not self._done and not self._finished:
                # a run that failed before its first trial (a broken --intent folder, a cluster not reached): its
                # empty partial folder would read as another, unfinished collection and refuse the next command
                shutil.rmtree(self.partial, ignore_errors=True)
        finally:
            self._lock.__exit__(*exc)

    def _open_partial(self) -> None:
        if self.partial.is_dir():
            # The key is in progress.json until finish() moves it into the manifest.
            same = False
            for name, field_name in ((self.PROGRESS, "key"), (MANIFEST_NAME, "collection_key")):
                try:
                    record = json.loads((self.partial / name).read_text("utf-8"))
                except (OSError, ValueError):
                    continue
                same = same or (isinstance(record, dict) and record.get(field_name) == self.key)
            if not same:
                if not self.overwrite:  # hours of another collection's trials are not removed unasked
                    raise FileExistsError(self._other_collection())
                shutil.rmtree(self.partial)
                self.discarded = True
        if not self.partial.is_dir():
            os.mkdir(self.partial)
            self._created = True
            progress = {
                "key": self.key,
                "dataset_id": self.dataset_id,
                "n_trials": self.n_trials,
                "description": self.description,  # what a refusal of another collection names
            }
            atomic_write(self.partial / self.PROGRESS, lambda fh: fh.write(json.dumps(progress).encode()))
            return
        remove_stale(self.partial)
        for i in range(self.n_trials):
            path = self.partial / _trial_file_name(i)
            if path.is_file():
                try:
                    read_trial(path)
                except (TrialFileError, OSError):
                    path.unlink()  # damaged by something other than our atomic writes: redo it
                    continue
                self._done.add(i)
        self.resumed = sorted(self._done)

    def _other_collection(self) -> str:
        """Why :attr:`partial`, another collection's unfinished trials, is not discarded without ``overwrite``."""
        done, total, what = _partial_progress(self.partial)
        return (
            f"{self.partial} holds {done}{total} finished trials of another, unfinished collection"
            + (f" ({what})" if what else "")
            + ": the command that started it continues it; to discard them and collect this one instead, pass "
            "overwrite=True"
        )

    def has(self, index: int) -> bool:
        """Whether trial ``index`` is already written (this run or an interrupted one)."""
        return index in self._done

    def add(self, index: int, trial: Trial) -> Path:
        """Write trial ``index`` (0 … n_trials−1) now."""
        if not is_integer(index) or not 0 <= index < self.n_trials:
            raise ValueError(f"index must be an int in [0, {self.n_trials}), got {index!r}")
        path = write_trial(trial, self.partial / _trial_file_name(index))
        self._done.add(index)
        if self._kept is not None:
            self._kept[index] = trial
        return path

    def finish(self) -> Path:
        """Write the manifest and swap the dataset in at the destination; returns it."""
        missing = [i for i in range(self.n_trials) if i not in self._done]
        if missing:
            raise ValueError(f"{self.folder}: {len(missing)} trial(s) not written yet (first: {missing[0]})")
        entries = []
        for i in range(self.n_trials):
            name = _trial_file_name(i)
            pf = pq.ParquetFile(self.partial / name)
            meta = TrialMeta.from_json(pf.schema_arrow.metadata[META_KEY])
            entries.append({"file": name, "n_samples": pf.metadata.num_rows, "meta": meta.to_dict()})
        manifest = _new_manifest(self.dataset_id, self.description, entries)
        manifest["collection_key"] = self.key
        _write_manifest(self.partial, manifest)
        (self.partial / self.PROGRESS).unlink(missing_ok=True)
        if self.folder.is_dir():
            _keep_unlisted(self.folder, self.partial)
        swap_in(self.partial, self.folder)
        self._finished = True
        return self.folder

    def dataset(self) -> Dataset:
        """The finished dataset (after :meth:`finish`) as :func:`read_dataset` gives it: its manifest read
        back, each trial this writer wrote as it was written (``keep``; a trial whose meta the manifest
        lists otherwise, or an interrupted run's, is read from its file). Saves reading back what was just
        written (a main job's datasets: about 15 CPU-s, issue 44)."""
        if not self._finished:
            raise RuntimeError(f"{self.folder}: DatasetWriter.dataset() before finish()")
        manifest = _read_manifest(self.folder)
        kept = self._kept or {}
        trials = []
        for i, entry in enumerate(manifest["trials"]):
            trial = kept.get(i)
            if (
                trial is None
                or entry["file"] != _trial_file_name(i)
                or TrialMeta.from_dict(entry["meta"]) != trial.meta
            ):
                trial = _read_entry(self.folder, entry)
            trials.append(trial)
        return Dataset(
            id=str(manifest["dataset_id"]),
            trials=tuple(trials),
            manifest=manifest,
            files=tuple(str(e["file"]) for e in manifest["trials"]),
        )


def digest(obj: Any) -> str:
    """A short stable digest of a JSON-ready object (the ``key`` of a :class:`DatasetWriter`)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]
