"""One trial as one Parquet file (docs/architecture.md, *Formats*): :func:`write_trial`, :func:`read_trial`.

Columns, for the d controlled DOFs named ``x, y, z, rx, ry, rz`` in order::

    time                                   float64   s
    pose_<ax>, vel_<ax>, wrench_<ax>, ref_<ax>   float64   m, m/s, N, m
    intent_<ax>, effort_h_<ax>, effort_r_<ax>    float64   optional
    fault                                  int64     optional
    alpha                                  float64   optional (the game's α each tick)
    q_<j>, qd_cmd_<j>  (j = 0 … J−1)       float64   rad, rad/s  optional (arm worlds)
    prediction_<ax>                        fixed_size_list<float64>[H]   optional

The :class:`~coassist.data.trial.TrialMeta` is JSON in the Arrow schema metadata under
``coassist.trial_meta``, next to ``coassist.format_version`` and ``coassist.sha256``, a
SHA-256 of the columns' values written with them: a read recomputes it, so bytes
damaged inside a page that Parquet still decodes (into a 6e307 N wrench) are refused.
Files written before the checksum load with a plausibility check only (every value
within :data:`PLAUSIBLE_MAGNITUDE`). Values are stored as raw float64, so a read gives
back the written arrays bit for bit. A file is written atomically (:mod:`coassist._io`).
Datasets, folders of such files with a manifest, are :mod:`coassist.data.datasets`.

Every defect of a file is one :class:`TrialFileError` naming the file and the problem.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from coassist._io import atomic_write
from coassist.data.trial import MAX_DOF, Trial, TrialMeta
from coassist.errors import CoassistError

__all__ = [
    "AXES",
    "FORMAT_VERSION",
    "META_KEY",
    "VERSION_KEY",
    "TrialFileError",
    "read_trial",
    "write_trial",
]

#: Axis names, in DOF order.
AXES = ("x", "y", "z", "rx", "ry", "rz")[:MAX_DOF]
META_KEY = b"coassist.trial_meta"
VERSION_KEY = b"coassist.format_version"
#: SHA-256 of the columns' values (:func:`_table_checksum`), recorded at write time.
CHECKSUM_KEY = b"coassist.sha256"
#: SHA-256 of the metadata's bytes (:data:`META_KEY`): the column checksum does not cover them, and a bit flipped in
#: the schema's metadata read back as another trial's (a controller "cooparative", another seed). Files written
#: before it have none.
META_CHECKSUM_KEY = b"coassist.meta_sha256"
#: Largest magnitude of any value in a trial [SI units]: 1000 km, 1 MN, 1e6 s. Finite
#: values beyond it (a wrench of 6e307 N from damaged bytes) are not a recording.
PLAUSIBLE_MAGNITUDE = 1e6
FORMAT_VERSION = 1

# Trial field -> column prefix, for the (T, d) arrays.
_REQUIRED = {"pose": "pose", "velocity": "vel", "wrench": "wrench", "reference": "ref"}
_OPTIONAL = {"intent": "intent", "effort_h": "effort_h", "effort_r": "effort_r"}
# Trial field -> column prefix, for the (T, J) joint arrays of arm worlds.
_JOINT = {"joints": "q", "joint_velocity": "qd_cmd"}


class TrialFileError(CoassistError, ValueError):
    """A trial file or dataset folder that cannot be read; the message names the file."""


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
    if trial.alpha is not None:
        cols["alpha"] = pa.array(trial.alpha, type=pa.float64())
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
    meta = trial.meta.to_json().encode()
    return table.replace_schema_metadata(
        {
            META_KEY: meta,
            VERSION_KEY: str(FORMAT_VERSION).encode(),
            CHECKSUM_KEY: _table_checksum(table).encode(),
            META_CHECKSUM_KEY: hashlib.sha256(meta).hexdigest().encode(),
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
        # the array's own buffer (no bytes copy: 4.6 GB of the main job's trials are hashed as they are written)
        h.update(np.ascontiguousarray(col.to_numpy(zero_copy_only=False)).data)
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
    """Column ``name`` as numpy, of the type :func:`write_trial` writes it with (int64 ``fault``, else float64): a
    timestamp column failed numpy's stacking with a traceback, and strings, integers or decimals loaded as if
    they were the floats written."""
    if name not in table.column_names:
        raise TrialFileError(f"{path}: missing column {name!r}")
    col = table.column(name).combine_chunks()
    expected = pa.int64() if name == "fault" else pa.float64()
    if col.type != expected:
        raise TrialFileError(f"{path}: column {name!r} has type {col.type}, expected {expected}")
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
    meta_sha = md.get(META_CHECKSUM_KEY)
    if meta_sha is not None and meta_sha.decode("ascii", "replace") != hashlib.sha256(md[META_KEY]).hexdigest():
        raise TrialFileError(f"{path}: the metadata do not match the checksum written with them (damaged bytes)")
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
    if "alpha" in names:
        kwargs["alpha"] = _column(table, "alpha", path)
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
            if not pa.types.is_fixed_size_list(col.type) or col.type.value_type != pa.float64():
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
