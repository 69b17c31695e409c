"""Trials and datasets on disk (DESIGN.md §6).

One trial = one Parquet file. Columns, for the d controlled DOFs named
``x, y, z, rx, ry, rz`` in order::

    time                                   float64   s
    pose_<ax>, vel_<ax>, wrench_<ax>, ref_<ax>   float64   m, m/s, N, m
    intent_<ax>, effort_h_<ax>, effort_r_<ax>    float64   optional
    fault                                  int64     optional
    q_<j>, qd_cmd_<j>  (j = 0 … J−1)       float64   rad, rad/s  optional (arm worlds)
    prediction_<ax>                        fixed_size_list<float64>[H]   optional

The :class:`~coassist.data.trial.TrialMeta` is JSON in the Arrow schema metadata under
``coassist.trial_meta``, next to ``coassist.format_version``. Values are stored as
raw float64, so a read gives back the written arrays bit for bit.

A dataset (the thesis' D_k, Algorithm 4.1) is a folder of trial files plus
``manifest.json`` (id, description, the trial files with their meta, creation time,
coassist version). The manifest is the commit point: it is written last and
atomically, so a crash leaves either the old dataset or the new one.

Every write goes to a temporary file in the destination folder, is fsync'ed and then
``os.replace``'d into place, so readers never see a half-written file.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import tempfile
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import coassist
from coassist.data.trial import MAX_DOF, Trial, TrialMeta

__all__ = [
    "AXES",
    "FORMAT_VERSION",
    "MANIFEST_NAME",
    "META_KEY",
    "VERSION_KEY",
    "Dataset",
    "TrialFileError",
    "append_to_dataset",
    "read_dataset",
    "read_trial",
    "write_dataset",
    "write_trial",
]

#: Axis names, in DOF order.
AXES = ("x", "y", "z", "rx", "ry", "rz")[:MAX_DOF]
META_KEY = b"coassist.trial_meta"
VERSION_KEY = b"coassist.format_version"
FORMAT_VERSION = 1
MANIFEST_NAME = "manifest.json"
DATASET_FORMAT = "coassist.dataset"

# Trial field -> column prefix, for the (T, d) arrays.
_REQUIRED = {"pose": "pose", "velocity": "vel", "wrench": "wrench", "reference": "ref"}
_OPTIONAL = {"intent": "intent", "effort_h": "effort_h", "effort_r": "effort_r"}
# Trial field -> column prefix, for the (T, J) joint arrays of arm worlds.
_JOINT = {"joints": "q", "joint_velocity": "qd_cmd"}


class TrialFileError(ValueError):
    """A trial file or dataset folder that cannot be read; the message names the file."""


# --------------------------------------------------------------------------- atomic I/O


def _atomic_write(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` through a temp file in the same folder, fsync, ``os.replace``."""
    path = Path(path)
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    # Persist the rename itself (POSIX); not available everywhere, hence best effort.
    try:
        dir_fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dir_fd)
    except OSError:
        pass
    finally:
        os.close(dir_fd)


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
        {META_KEY: trial.meta.to_json().encode(), VERSION_KEY: str(FORMAT_VERSION).encode()}
    )


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
    # zstd: lossless and compact; the float64 bits are stored unchanged.
    _atomic_write(path, lambda fh: pq.write_table(table, fh, compression="zstd"))
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
        raise TrialFileError(f"{path}: not a readable Parquet file: {exc}") from None
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
    d = 0
    while d < MAX_DOF and f"pose_{AXES[d]}" in names:
        d += 1
    if d == 0:
        raise TrialFileError(f"{path}: missing column 'pose_x'")

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
    try:
        return Trial(**kwargs)
    except ValueError as exc:
        raise TrialFileError(f"{path}: inconsistent trial: {exc}") from None


# --------------------------------------------------------------------------- datasets


@dataclass(frozen=True, eq=False)
class Dataset:
    """A dataset D_k: its id, its trials (in manifest order) and the manifest itself."""

    id: str
    trials: tuple[Trial, ...]
    manifest: Mapping[str, Any]

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
    _atomic_write(folder / MANIFEST_NAME, lambda fh: fh.write(text.encode()))


def _read_manifest(folder: Path) -> dict[str, Any]:
    path = folder / MANIFEST_NAME
    if not path.is_file():
        raise FileNotFoundError(f"no dataset at {folder}: {MANIFEST_NAME} not found")
    try:
        manifest = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise TrialFileError(f"{path}: malformed JSON: {exc}") from None
    for key in ("dataset_id", "trials", "format_version"):
        if key not in manifest:
            raise TrialFileError(f"{path}: missing key {key!r}")
    if manifest.get("format") != DATASET_FORMAT:
        raise TrialFileError(f"{path}: 'format' is {manifest.get('format')!r}, expected {DATASET_FORMAT!r}")
    if int(manifest["format_version"]) > FORMAT_VERSION:
        raise TrialFileError(f"{path}: format version {manifest['format_version']} is newer than this coassist reads")
    return manifest


def _entry(name: str, trial: Trial) -> dict[str, Any]:
    return {"file": name, "n_samples": trial.n_samples, "meta": trial.meta.to_dict()}


def write_dataset(
    trials: Iterable[Trial],
    folder: str | os.PathLike[str],
    dataset_id: str,
    description: str = "",
    *,
    overwrite: bool = False,
) -> Path:
    """Write trials as a dataset folder (trial files + ``manifest.json``).

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
        new trial files and manifest replace the old ones, and the old dataset's trial
        files that the new one does not reuse are removed. Files that no manifest
        lists are never deleted.

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
    old_files: set[str] = set()
    if folder.exists():
        if not folder.is_dir():
            raise FileExistsError(f"{folder} exists and is not a folder")
        if any(folder.iterdir()):
            if not overwrite:
                raise FileExistsError(f"{folder} exists and is not empty; pass overwrite=True to replace it")
            if (folder / MANIFEST_NAME).is_file():
                old_files = {e["file"] for e in _read_manifest(folder)["trials"]}
    folder.mkdir(parents=True, exist_ok=True)

    entries = []
    for i, trial in enumerate(items):
        name = _trial_file_name(i)
        write_trial(trial, folder / name)
        entries.append(_entry(name, trial))
    manifest = {
        "format": DATASET_FORMAT,
        "format_version": FORMAT_VERSION,
        "dataset_id": dataset_id,
        "description": description,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "coassist_version": coassist.__version__,
        "n_trials": len(entries),
        "trials": entries,
    }
    _write_manifest(folder, manifest)
    for name in old_files - {e["file"] for e in entries}:
        (folder / name).unlink(missing_ok=True)
    return folder


def append_to_dataset(trials: Iterable[Trial], folder: str | os.PathLike[str]) -> Path:
    """Add trials to an existing dataset (new files after the existing ones).

    The manifest is rewritten atomically after the new trial files are in place.
    """
    folder = Path(folder)
    manifest = _read_manifest(folder)
    items = _collect_trials(trials)
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
    manifest["modified"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    _write_manifest(folder, manifest)
    return folder


def read_dataset(folder: str | os.PathLike[str]) -> Dataset:
    """Read a dataset folder written by :func:`write_dataset`.

    Every trial listed in the manifest is loaded, and its meta must equal the one in
    the manifest (a mismatch means the folder was edited by hand).
    """
    folder = Path(folder)
    manifest = _read_manifest(folder)
    trials = []
    for entry in manifest["trials"]:
        path = folder / entry["file"]
        trial = read_trial(path)
        try:
            listed = TrialMeta.from_dict(entry["meta"])
        except (KeyError, ValueError) as exc:
            raise TrialFileError(f"{folder / MANIFEST_NAME}: bad meta for {entry.get('file')!r}: {exc}") from None
        if listed != trial.meta:
            raise TrialFileError(f"{path}: meta differs from the one listed in {folder / MANIFEST_NAME}")
        trials.append(trial)
    return Dataset(id=str(manifest["dataset_id"]), trials=tuple(trials), manifest=manifest)
