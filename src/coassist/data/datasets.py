"""Trials and datasets on disk (docs/architecture.md, *Formats*).

One trial = one Parquet file. Columns, for the d controlled DOFs named
``x, y, z, rx, ry, rz`` in order::

    time                                   float64   s
    pose_<ax>, vel_<ax>, wrench_<ax>, ref_<ax>   float64   m, m/s, N, m
    intent_<ax>, effort_h_<ax>, effort_r_<ax>    float64   optional
    fault                                  int64     optional
    q_<j>, qd_cmd_<j>  (j = 0 … J−1)       float64   rad, rad/s  optional (arm worlds)
    prediction_<ax>                        fixed_size_list<float64>[H]   optional

The :class:`~coassist.data.trial.TrialMeta` is JSON in the Arrow schema metadata under
``coassist.trial_meta``, next to ``coassist.format_version`` and ``coassist.sha256``, a
SHA-256 of the columns' values written with them: a read recomputes it, so bytes
damaged inside a page that Parquet still decodes (into a 6e307 N wrench) are refused.
Files written before the checksum load with a plausibility check only (every value
within :data:`PLAUSIBLE_MAGNITUDE`). Values are stored as raw float64, so a read gives
back the written arrays bit for bit.

A dataset (the thesis' D_k, Algorithm 4.1) is a folder of trial files plus
``manifest.json`` (id, description, the trial files with their meta, creation time,
coassist version). Its paths must stay inside the folder. A new dataset is written in
a folder beside the old one and swapped in whole at the end, under the output's lock,
so a crash leaves either the old dataset or the new one (:mod:`coassist._io`, the one
writer of the project: every file is written to a temporary file, fsync'ed, renamed,
and the folder fsync'ed). :class:`DatasetWriter` writes trials as they finish and lets
an interrupted collection continue.

Every defect of a file is one :class:`TrialFileError` naming the file and the problem.
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

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import coassist
from coassist._checks import check_int, is_integer
from coassist._io import OutputLock, atomic_write, partial_folder, remove_stale, staged_folder, swap_in
from coassist.data.trial import MAX_DOF, Trial, TrialMeta
from coassist.errors import CoassistError

__all__ = [
    "AXES",
    "FORMAT_VERSION",
    "MANIFEST_NAME",
    "ManifestError",
    "META_KEY",
    "VERSION_KEY",
    "Dataset",
    "DatasetWriter",
    "TrialFileError",
    "append_to_dataset",
    "digest",
    "manifest_files",
    "read_dataset",
    "read_dataset_trial",
    "read_trial",
    "write_dataset",
    "write_trial",
]

#: Axis names, in DOF order.
AXES = ("x", "y", "z", "rx", "ry", "rz")[:MAX_DOF]
META_KEY = b"coassist.trial_meta"
VERSION_KEY = b"coassist.format_version"
#: SHA-256 of the columns' values (:func:`_table_checksum`), recorded at write time.
CHECKSUM_KEY = b"coassist.sha256"
#: Largest magnitude of any value in a trial [SI units]: 1000 km, 1 MN, 1e6 s. Finite
#: values beyond it (a wrench of 6e307 N from damaged bytes) are not a recording.
PLAUSIBLE_MAGNITUDE = 1e6
FORMAT_VERSION = 1
MANIFEST_NAME = "manifest.json"
DATASET_FORMAT = "coassist.dataset"

# Trial field -> column prefix, for the (T, d) arrays.
_REQUIRED = {"pose": "pose", "velocity": "vel", "wrench": "wrench", "reference": "ref"}
_OPTIONAL = {"intent": "intent", "effort_h": "effort_h", "effort_r": "effort_r"}
# Trial field -> column prefix, for the (T, J) joint arrays of arm worlds.
_JOINT = {"joints": "q", "joint_velocity": "qd_cmd"}


class TrialFileError(CoassistError, ValueError):
    """A trial file or dataset folder that cannot be read; the message names the file."""


class ManifestError(TrialFileError):
    """A dataset's ``manifest.json`` that cannot be used (the whole dataset, not one trial)."""


# --------------------------------------------------------------------------- one trial


def _trial_table(trial: Trial) -> pa.Table:
    d = trial.n_dof
    cols: dict[str, pa.Array] = {"time": pa.array(trial.time, type=pa.float64())}
    for group in (_REQUIRED, _OPTIONAL):
        for field_name, prefix in group.items():
            arr = getattr(trial, field_name)
            if arr is None:
                continue
            for j in range(d):
                cols[f"{prefix}_{AXES[j]}"] = pa.array(np.ascontiguousarray(arr[:, j]), type=pa.float64())
    if trial.fault is not None:
        cols["fault"] = pa.array(trial.fault, type=pa.int64())
    for field_name, prefix in _JOINT.items():
        arr = getattr(trial, field_name)
        if arr is not None:
            for j in range(arr.shape[1]):
                cols[f"{prefix}_{j}"] = pa.array(np.ascontiguousarray(arr[:, j]), type=pa.float64())
    if trial.prediction is not None:
        horizon = trial.prediction.shape[1]
        for j in range(d):
            # from_pandas=False (the default) keeps NaN as a value, not a null.
            flat = pa.array(np.ascontiguousarray(trial.prediction[:, :, j]).ravel(), type=pa.float64())
            cols[f"prediction_{AXES[j]}"] = pa.FixedSizeListArray.from_arrays(flat, horizon)
    table = pa.table(cols)
    return table.replace_schema_metadata(
        {
            META_KEY: trial.meta.to_json().encode(),
            VERSION_KEY: str(FORMAT_VERSION).encode(),
            CHECKSUM_KEY: _table_checksum(table).encode(),
        }
    )


def _table_checksum(table: pa.Table) -> str:
    """SHA-256 over every column's name and values (the float64/int64 bytes, in order),
    so a read can tell damaged bytes that Parquet itself decoded into other numbers."""
    h = hashlib.sha256()
    for name in table.column_names:
        col = table.column(name).combine_chunks()
        if pa.types.is_fixed_size_list(col.type):
            col = col.flatten()
        h.update(name.encode())
        h.update(np.ascontiguousarray(col.to_numpy(zero_copy_only=False)).tobytes())
    return h.hexdigest()


def write_trial(trial: Trial, path: str | os.PathLike[str]) -> Path:
    """Write one trial to a Parquet file, atomically.

    Parameters
    ----------
    trial : Trial
    path : path-like
        Destination file (conventionally ``*.parquet``); parent folders are created.

    Returns
    -------
    Path
        The path written.
    """
    if not isinstance(trial, Trial):
        raise ValueError(f"write_trial expects a Trial, got {type(trial).__name__}")
    path = Path(path)
    table = _trial_table(trial)
    # zstd: lossless and compact; the float64 bits are stored unchanged. No dictionary
    # encoding: measured on 40 of the main job's trials, dictionaries of float samples that
    # hardly repeat cost 3x the write time (0.65 s against 0.23 s) for larger files (76 MB
    # against 60 MB), and reading them back took 0.18 s against 0.13 s.
    atomic_write(path, lambda fh: pq.write_table(table, fh, compression="zstd", use_dictionary=False))
    return path


def _column(table: pa.Table, name: str, path: Path) -> np.ndarray:
    if name not in table.column_names:
        raise TrialFileError(f"{path}: missing column {name!r}")
    col = table.column(name).combine_chunks()
    if col.null_count:
        raise TrialFileError(f"{path}: column {name!r} has {col.null_count} null values")
    return col.to_numpy(zero_copy_only=False)


def read_trial(path: str | os.PathLike[str]) -> Trial:
    """Read a trial written by :func:`write_trial`.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    TrialFileError
        If the file lacks the metadata key or a column, or is not a coassist trial;
        the message names the file and what is missing.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"trial file not found: {path}")
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        detail = str(exc).replace(f" '{path}'", "").replace(str(path), "the file")  # pyarrow repeats the path
        raise TrialFileError(f"{path}: not a readable Parquet file (truncated or damaged?): {detail}") from None
    md = table.schema.metadata or {}
    if META_KEY not in md:
        raise TrialFileError(f"{path}: schema metadata key {META_KEY.decode()!r} missing (not a coassist trial file)")
    version_raw = md.get(VERSION_KEY)
    if version_raw is None:
        raise TrialFileError(f"{path}: schema metadata key {VERSION_KEY.decode()!r} missing")
    try:
        version = int(version_raw)
    except ValueError:
        raise TrialFileError(f"{path}: bad format version {version_raw!r}") from None
    if version > FORMAT_VERSION:
        raise TrialFileError(f"{path}: format version {version} is newer than this coassist reads ({FORMAT_VERSION})")
    try:
        meta = TrialMeta.from_json(md[META_KEY])
    except ValueError as exc:
        raise TrialFileError(f"{path}: bad {META_KEY.decode()!r}: {exc}") from None

    names = set(table.column_names)
    # d is the most axes any required group has; every required group must have all d
    # (a file without pose_y but with vel_y is damaged, not a 1-DOF trial).
    present = {p: [j for j, ax in enumerate(AXES) if f"{p}_{ax}" in names] for p in _REQUIRED.values()}
    d = max((js[-1] + 1 for js in present.values() if js), default=1)
    for prefix, js in present.items():
        missing = [f"{prefix}_{AXES[j]}" for j in range(d) if j not in js]
        if missing:
            more = f" (other columns give {d} DOFs)" if d > 1 else ""
            raise TrialFileError(f"{path}: missing column {missing[0]!r}{more}")

    def block(prefix: str) -> np.ndarray:
        return np.column_stack([_column(table, f"{prefix}_{AXES[j]}", path) for j in range(d)])

    kwargs: dict[str, Any] = {"meta": meta, "time": _column(table, "time", path)}
    for field_name, prefix in _REQUIRED.items():
        kwargs[field_name] = block(prefix)
    for field_name, prefix in _OPTIONAL.items():
        # A group is present when its first axis is; then every axis must be.
        if f"{prefix}_{AXES[0]}" in names:
            kwargs[field_name] = block(prefix)
    if "fault" in names:
        kwargs["fault"] = _column(table, "fault", path)
    for field_name, prefix in _JOINT.items():
        n_j = 0
        while f"{prefix}_{n_j}" in names:
            n_j += 1
        if n_j:
            kwargs[field_name] = np.column_stack([_column(table, f"{prefix}_{j}", path) for j in range(n_j)])
    if "prediction_x" in names:
        per_axis = []
        for j in range(d):
            name = f"prediction_{AXES[j]}"
            if name not in names:
                raise TrialFileError(f"{path}: missing column {name!r}")
            col = table.column(name).combine_chunks()
            if not pa.types.is_fixed_size_list(col.type):
                raise TrialFileError(f"{path}: column {name!r} has type {col.type}, expected fixed_size_list<double>")
            horizon = col.type.list_size
            values = col.flatten().to_numpy(zero_copy_only=False)
            per_axis.append(values.reshape(len(col), horizon))
        kwargs["prediction"] = np.stack(per_axis, axis=-1)
    # after the structure's checks, so a missing column is named as such
    recorded = md.get(CHECKSUM_KEY)  # files written before the checksum have none: plausibility only
    try:
        actual = None if recorded is None else _table_checksum(table)
    except (pa.ArrowException, ValueError) as exc:
        raise TrialFileError(f"{path}: columns cannot be read ({exc})") from None
    if recorded is not None and recorded.decode("ascii", "replace") != actual:
        raise TrialFileError(f"{path}: the values do not match the checksum written with them (damaged bytes)")
    # A matching checksum says the values are the ones written; only a file without one
    # (written before the checksum existed) needs the plausibility check.
    for name, value in kwargs.items() if recorded is None else ():
        if isinstance(value, np.ndarray) and value.dtype.kind == "f":
            with np.errstate(invalid="ignore"):
                big = np.abs(value) > PLAUSIBLE_MAGNITUDE  # NaN (an unused prediction row) is not big
            if big.any():
                raise TrialFileError(
                    f"{path}: {name} holds {value[big].flat[0]:.3g}, beyond any recording "
                    f"(|value| <= {PLAUSIBLE_MAGNITUDE:g} in SI units); damaged bytes?"
                )
    try:
        return Trial(**kwargs)
    except ValueError as exc:
        raise TrialFileError(f"{path}: inconsistent trial: {exc}") from None


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
    if not isinstance(name, str) or not name.strip():
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
        manifest = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ManifestError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise ManifestError(f"{path}: malformed JSON: {exc}") from None
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
        if name in seen:
            raise ManifestError(f"{path}: {where} lists {name!r} a second time")
        seen.add(name)
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


def _check_destination(folder: Path, overwrite: bool) -> None:
    """Refuse a destination that is a file, or a non-empty folder without ``overwrite``."""
    if folder.exists() or folder.is_symlink():
        if not folder.is_dir():
            raise FileExistsError(f"{folder} exists and is not a folder")
        if any(folder.iterdir()) and not overwrite:
            raise FileExistsError(
                f"{folder} exists and is not empty; pass overwrite=True (coassist collect --overwrite) to replace it"
            )
    elif any(p.exists() and not p.is_dir() for p in folder.parents):
        bad = next(p for p in reversed(folder.parents) if p.exists() and not p.is_dir())
        raise NotADirectoryError(f"{folder}: {bad} is a file, not a folder")


def _keep_unlisted(old: Path, new: Path) -> None:
    """Carry the files of ``old`` that its manifest does not list (notes, figures) into ``new``."""
    listed = {MANIFEST_NAME}
    try:
        listed |= {e["file"] for e in _read_manifest(old)["trials"]}
    except (FileNotFoundError, TrialFileError):
        pass
    for p in old.iterdir():
        if p.name in listed or (new / p.name).exists():
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
    folder = Path(folder)
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
    folder = Path(folder)
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
    return trial


def read_dataset_trial(folder: str | os.PathLike[str], index: int) -> Trial:
    """Only trial ``index`` (manifest order) of a dataset folder: other trials are not read."""
    folder = Path(folder)
    entries = _read_manifest(folder)["trials"]
    if not is_integer(index) or not 0 <= index < len(entries):
        raise ValueError(f"{folder}: index must be in [0, {len(entries)}), got {index!r}")
    return _read_entry(folder, entries[index])


# --------------------------------------------------------------------------- resumable writing


class DatasetWriter:
    """Write a dataset trial by trial as the trials finish, resumably.

    Trials go into ``.<name>.partial`` beside the destination, each file atomic, so a
    killed run keeps every trial it finished. A later writer for the same destination
    and the same ``key`` (a digest of what is being collected) picks them up
    (:meth:`has` tells which); a different key discards them. :meth:`finish` writes the
    manifest and swaps the folder in at the destination, replacing an old dataset only
    then. The destination is locked from ``__enter__`` to ``__exit__``.

    ::

        with DatasetWriter(out, "D0", n_trials=60, key=digest, overwrite=True) as w:
            for i, trial in run(todo=[i for i in range(60) if not w.has(i)]):
                w.add(i, trial)
            w.finish()
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
    ) -> None:
        self.folder = Path(folder)
        self.dataset_id = _check_id(dataset_id)
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
                shutil.rmtree(self.partial)
                self.discarded = True
        if not self.partial.is_dir():
            os.mkdir(self.partial)
            progress = {"key": self.key, "dataset_id": self.dataset_id, "n_trials": self.n_trials}
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

    def has(self, index: int) -> bool:
        """Whether trial ``index`` is already written (this run or an interrupted one)."""
        return index in self._done

    def add(self, index: int, trial: Trial) -> Path:
        """Write trial ``index`` (0 … n_trials−1) now."""
        if not is_integer(index) or not 0 <= index < self.n_trials:
            raise ValueError(f"index must be an int in [0, {self.n_trials}), got {index!r}")
        path = write_trial(trial, self.partial / _trial_file_name(index))
        self._done.add(index)
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
        return self.folder


def digest(obj: Any) -> str:
    """A short stable digest of a JSON-ready object (the ``key`` of a :class:`DatasetWriter`)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]
