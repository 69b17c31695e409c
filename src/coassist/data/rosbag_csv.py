"""Load real UR5 hand-guiding recordings exported from rosbags as CSV.

A recorded trial is a folder with one CSV per ROS topic (see the recordings' README):

=====================  ===============================  ==========================
file                   topic                            value columns
=====================  ===============================  ==========================
current_pose.csv       measured end-effector pose       pose.position.<ax>
current_velocity.csv   measured end-effector twist      twist.linear.<ax>
human_wrench.csv       wrench measured at the tip       wrench.force.<ax>
robot_ref_pos.csv      nominal reference (planner)      pose.position.<ax>
=====================  ===============================  ==========================

Every file also carries ``header.seq``, ``header.stamp.secs`` and
``header.stamp.nsecs``. What the export does to the data, and what this loader does
about it:

- The four files can start or stop a row or two apart: rows are inner-joined on
  ``header.seq`` and the number of ticks lost is reported in ``meta.extra``.
- The controller runs at 125 Hz but ticks are sometimes late: time comes from the
  header stamps (the controller's clock, not the bag's receive time), ``dt`` is the
  median period, and the largest gap is reported in ``meta.extra``. Gaps are kept,
  not resampled, since resampling would invent measurements.
- Values like 5e-324 or 1e-182 are denormal noise from the export: any value with
  magnitude below 1e-100 is set to 0.
- A value no sensor of this setup can have measured is refused (:class:`RecordingError`,
  one line naming the file, the column, the data row and its ``seq``): a force beyond
  :data:`PLAUSIBLE_FORCE`, a position beyond :data:`PLAUSIBLE_POSITION`, a velocity
  beyond :data:`PLAUSIBLE_SPEED` (each per axis; why these bounds: at the constants).
  Such a value is a fault of the sensor, the driver or the file, and a model trained or
  a controller tuned on it learns the fault.
- A file whose last line ends without a line break is refused: the export was cut off
  mid-write (a kill), and the cut can fall inside a number (−0.6 read for −0.6130), a
  value that parses and is wrong. What is decidable: every line a CSV writer finishes
  ends with a line break, so a missing one marks the cut; a cut that falls exactly on a
  line break leaves whole rows only, which load (the join reports the shorter file). A
  number's count of digits is not a test (``repr`` writes 0.5 as ``0.5``).
- A recording needs :data:`MIN_TICKS` ticks the four topics share (one tick has no period).
- A time gap longer than :data:`coassist.data.trial.GAP_FACTOR` periods loads but warns
  (:class:`RecordingWarning`, naming the folder). Training windows never span a gap
  (:class:`coassist.intent.features.WindowSet`).
"""

from __future__ import annotations

import io
import os
import re
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from coassist.data.trial import GAP_FACTOR, Trial, TrialMeta, time_gaps
from coassist.errors import CoassistError

__all__ = [
    "DENORMAL_THRESHOLD",
    "FRAME_COLUMN",
    "LINEAR_DOFS",
    "MIN_TICKS",
    "PLAUSIBLE_FORCE",
    "PLAUSIBLE_POSITION",
    "PLAUSIBLE_SPEED",
    "TOPIC_FILES",
    "RecordingError",
    "RecordingWarning",
    "assemble_recording",
    "check_plausible",
    "default_real_data",
    "load_ros_trial",
    "load_ros_user",
    "recording_folders",
]

#: Trial field -> (CSV file, value column pattern).
TOPIC_FILES: dict[str, tuple[str, str]] = {
    "pose": ("current_pose.csv", "pose.position.{ax}"),
    "velocity": ("current_velocity.csv", "twist.linear.{ax}"),
    "wrench": ("human_wrench.csv", "wrench.force.{ax}"),
    "reference": ("robot_ref_pos.csv", "pose.position.{ax}"),
}
#: The linear DOFs a recording provides, in the order the files name them (coassist.data.trial_file).
LINEAR_DOFS = ("x", "y", "z")
#: Magnitudes below this are export noise and read as 0.
DENORMAL_THRESHOLD = 1e-100
#: Largest plausible hand force per axis in N: the Robotiq FT300 the thesis used and the
#: CB3's own force estimate both saturate at ±327.67 N, so a larger value is no
#: measurement (the recordings peak at 31 N; ISO/TS 15066's quasi-static hand limit is 140 N).
PLAUSIBLE_FORCE = 330.0
#: Largest plausible tool (or reference) position per axis in m: a UR-class arm reaches
#: 0.85 m (UR5, Panda 0.855 m) to 1.75 m (UR20) from its base; 5 m leaves room for a frame
#: placed away from the base (a table or world frame). The recordings stay within 0.8 m.
PLAUSIBLE_POSITION = 5.0
#: Largest plausible tool speed per axis in m/s: a UR5 at its 180 °/s joint limits moves a
#: tool at 0.85 m about 3 m/s, the Panda's Cartesian limit is 1.7 m/s. The recordings stay
#: within 0.55 m/s.
PLAUSIBLE_SPEED = 5.0
#: Fewest ticks a recording's four topics must share: one tick has no period.
MIN_TICKS = 2
#: Trial field -> (bound, unit) of :func:`check_plausible`.
PLAUSIBLE_BOUNDS: dict[str, tuple[float, str]] = {
    "pose": (PLAUSIBLE_POSITION, "m"),
    "velocity": (PLAUSIBLE_SPEED, "m/s"),
    "wrench": (PLAUSIBLE_FORCE, "N"),
    "reference": (PLAUSIBLE_POSITION, "m"),
}

#: The header columns of the thesis' CSV export (the bag reader, data/bags.py, builds its tables with them).
SEQ_COLUMN = "header.seq"
SECS_COLUMN = "header.stamp.secs"
NSECS_COLUMN = "header.stamp.nsecs"
RECEIVE_COLUMN = "Time"
#: The frame a topic's message is expressed in (empty in the thesis lab's exports: unset).
FRAME_COLUMN = "header.frame_id"


class RecordingError(CoassistError, ValueError):
    """A recording folder that cannot be loaded; the message names the file and column."""


class RecordingWarning(UserWarning):
    """A recording that loads but has time gaps (training windows skip them); the message names the folder."""


def check_plausible(
    field_name: str, values: np.ndarray, columns: Sequence[str], where: str, row: Callable[[int], str]
) -> None:
    """Refuse values beyond the field's physical bound (:data:`PLAUSIBLE_BOUNDS`), in one line.

    ``values`` (n, k) are the rows of one topic in the order of its file, ``columns`` their
    names, ``where`` the file (and topic), ``row(r)`` how row r is named (``"data row 12 (seq
    57481)"``, ``"message 12"``). The first offending row is named, and the count.
    """
    bound, unit = PLAUSIBLE_BOUNDS[field_name]
    bad = np.abs(values) > bound
    if bad.any():
        r, c = (int(i) for i in np.argwhere(bad)[0])
        raise RecordingError(
            f"{where}: {row(r)}: {columns[c]} = {values[r, c]:.6g} {unit} is beyond the plausible "
            f"±{bound:g} {unit} ({int(bad.any(axis=1).sum())} such row(s)): no measurement of this "
            "setup; a fault of the sensor, the driver or the file"
        )


def _warn_gaps(where: str, time: np.ndarray, dt: float) -> None:
    gaps = time_gaps(time, dt)
    if gaps.size:
        k = int(gaps[np.argmax(np.diff(time)[gaps])])
        warnings.warn(
            f"{where}: {gaps.size} time gap(s) longer than {GAP_FACTOR:g} periods; the longest, "
            f"{time[k + 1] - time[k]:.4g} s, at t = {time[k]:.3f} s (training windows do not span gaps)",
            RecordingWarning,
            stacklevel=4,
        )


#: The share of the longest topic's rows the join may drop before it is said: the thesis lab's recordings drop at most
#: 0.7 % (a few rows at the ends); a topic that stopped early drops most of the others' (review, 2026-12-06: 95 %)
DROPPED_SHARE_WARN = 0.05


def _warn_short_topic(where: str, lengths: Mapping[str, int], kept: int) -> None:
    longest = max(lengths.values())
    if longest and (longest - kept) > DROPPED_SHARE_WARN * longest:
        short = min(lengths, key=lambda f: lengths[f])
        warnings.warn(
            f"{where}: the topics share {kept} of the longest's {longest} rows ({100 * (longest - kept) / longest:.0f} % "
            f"dropped): {short} holds {lengths[short]}: a topic that stopped early cuts the recording to it",
            RecordingWarning,
            stacklevel=4,
        )


def check_dofs(dofs: Sequence[str]) -> tuple[str, ...]:
    """``dofs`` as a tuple, refused unless a prefix of (x, y, z) (ValueError naming them)."""
    dofs = tuple(dofs)
    # Only prefixes of (x, y, z): a Trial's axis j is stored as AXES[j], so ("x", "z")
    # would be written as pose_x, pose_y and mislabel z as y.
    allowed = [LINEAR_DOFS[:n] for n in range(1, len(LINEAR_DOFS) + 1)]
    if dofs not in allowed:
        raise ValueError(f"dofs must be one of {allowed}, got {dofs}")
    return dofs


def _read_topic(path: Path, field_name: str, value_cols: list[str]) -> pd.DataFrame:
    if not path.is_file():
        raise RecordingError(f"{path}: file not found")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot be read: {exc.strerror}") from None
    if raw and not raw.endswith(b"\n"):
        # The export was cut off mid-line (module docstring): the last values may be cut short.
        line = raw.count(b"\n") + 1
        raise RecordingError(
            f"{path}: line {line}, the last, ends without a line break: the export was cut off "
            "mid-write and its values may be cut short (-0.6 for -0.6130); export the recording "
            "again, or delete that line to load the rest"
        )
    # a name given twice: pandas would read the first as the column and rename the other (a torque read as a force)
    names = [n.strip().strip('"') for n in raw.split(b"\n", 1)[0].decode("utf-8", "replace").rstrip("\r").split(",")]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise RecordingError(f"{path}: the header names column {twice[0]!r} more than once: which is the value?")
    try:
        # pandas 3's default parser reads repr()'d doubles back exactly (checked on all
        # 1.9 M values of the UR5 recordings; ``float_precision`` is deprecated).
        df = pd.read_csv(io.BytesIO(raw))
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot parse CSV: {' '.join(str(exc).split())}") from None
    for col in [SEQ_COLUMN, SECS_COLUMN, NSECS_COLUMN, *value_cols]:
        if col not in df.columns:
            raise RecordingError(f"{path}: missing column {col!r}")
    if len(df) == 0:
        raise RecordingError(f"{path}: no rows")
    # the receive time too where the export has it: a bad cell is named here, not a float() error or a NaN later
    checked = [SEQ_COLUMN, SECS_COLUMN, NSECS_COLUMN, *value_cols] + ([RECEIVE_COLUMN] if RECEIVE_COLUMN in df else [])
    for col in checked:
        values = pd.to_numeric(df[col], errors="coerce")
        bad = values.isna() | ~np.isfinite(values.to_numpy(dtype=float, na_value=np.nan))
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise RecordingError(
                f"{path}: column {col!r} has {int(bad.sum())} missing or non-numeric values (first at data row {row})"
            )
        df[col] = values
    for col, hi in ((SEQ_COLUMN, 2**32 - 1), (SECS_COLUMN, 2**32 - 1), (NSECS_COLUMN, 10**9 - 1)):
        v = df[col].to_numpy()
        if np.any(v != np.round(v)):
            raise RecordingError(f"{path}: column {col!r} must hold integers")
        out = (v < 0) | (v > hi)  # ROS's uint32 fields (nsecs below a second): 1e30 would wrap in int64 silently
        if out.any():
            row = int(np.flatnonzero(out)[0])
            raise RecordingError(f"{path}: column {col!r} must hold integers in 0 … {hi} (data row {row}: {v[row]!r})")
        df[col] = df[col].astype(np.int64)
    dup = df[SEQ_COLUMN].duplicated()
    if dup.any():
        raise RecordingError(f"{path}: column {SEQ_COLUMN!r} repeats value {int(df[SEQ_COLUMN][dup].iloc[0])}")
    seq = df[SEQ_COLUMN].to_numpy()
    check_plausible(
        field_name,
        df[value_cols].to_numpy(np.float64),
        value_cols,
        str(path),
        lambda r: f"data row {r} (seq {int(seq[r])})",
    )
    return df.sort_values(SEQ_COLUMN, kind="stable").reset_index(drop=True)


def load_ros_trial(
    folder: str | os.PathLike[str],
    *,
    user: str | None = None,
    dofs: Sequence[str] = ("x", "y"),
) -> Trial:
    """Load one recorded trial folder into a :class:`Trial`.

    Parameters
    ----------
    folder : path-like
        Folder holding the four topic CSVs (see the module docstring).
    user : str, optional
        Operator id; defaults to the name of the folder's parent (``"user-a"``).
    dofs : sequence of str
        ``("x",)``, ``("x", "y")`` (default, the thesis' plane) or ``("x", "y", "z")``:
        position, linear velocity and force along those axes.

    Returns
    -------
    Trial
        ``origin="real"``, ``task="real"``, ``object="unknown"``,
        ``controller="unknown"``, ``model_id=None``, ``seed=None``; ``time`` from the
        header stamps of ``current_pose.csv`` minus the first, ``dt`` the median
        period. ``meta.extra`` holds the diagnostics: ``rows_dropped`` (ticks of the
        longest file lost by the join), ``rows_dropped_per_file``, ``max_gap_s``
        (largest stamp period), ``max_receive_gap_s`` (largest gap in the bag's
        receive time), ``seq_gaps`` (missing seq numbers inside the joined range),
        ``stamp_mismatch_max_s`` (largest stamp difference between files for one seq),
        ``n_denormals_zeroed``, ``seq_first``, ``seq_last``, ``recording``, ``dofs``.

    Raises
    ------
    RecordingError
        A missing file or column (both named), unparseable values, repeated seq
        numbers, fewer than :data:`MIN_TICKS` common seq, stamps that do not increase,
        an implausible value (:func:`check_plausible`) or a file cut off mid-line.
    """
    folder = Path(folder)
    dofs = check_dofs(dofs)
    if not folder.is_dir():
        raise RecordingError(f"{folder}: recording folder not found")
    if user is None:
        user = folder.absolute().parent.name

    frames: dict[str, pd.DataFrame] = {}
    for field_name, (file_name, pattern) in TOPIC_FILES.items():
        frames[field_name] = _read_topic(folder / file_name, field_name, [pattern.format(ax=ax) for ax in dofs])
    sources = {name: str(folder / file_name) for name, (file_name, _) in TOPIC_FILES.items()}
    lengths = {TOPIC_FILES[name][0]: len(df) for name, df in frames.items()}
    return assemble_recording(
        frames, where=str(folder), sources=sources, lengths=lengths, user=user, dofs=dofs, recording=folder.name
    )


def assemble_recording(
    frames: Mapping[str, pd.DataFrame],
    *,
    where: str,
    sources: Mapping[str, str],
    lengths: Mapping[str, int],
    user: str,
    dofs: tuple[str, ...],
    recording: str,
    key: str = SEQ_COLUMN,
) -> Trial:
    """Join the four topics of one recording on ``key`` and build its :class:`Trial`.

    Shared by the CSV export (:func:`load_ros_trial`) and the bag reader
    (:mod:`coassist.data.bags`), so both align and clean the data the same way.
    ``frames[field]`` (field as in :data:`TOPIC_FILES`) holds the integer column
    ``key`` (``header.seq``, or the header stamp in ns where a ROS 2 header has no
    seq), ``header.stamp.secs``/``nsecs``, the value columns of :data:`TOPIC_FILES`
    and optionally ``Time`` (receive time [s]); rows unique in ``key``, sorted by it.
    ``sources[field]`` names the file or topic in errors and warnings, ``where`` the
    recording; ``lengths`` maps a source name to its row count before the join.
    With ``key`` other than ``header.seq``, ``seq_gaps``/``seq_first``/``seq_last``
    in ``meta.extra`` are None.
    """
    _check_frames(frames, sources, where)
    what = "header.seq value" if key == SEQ_COLUMN else "header stamp"
    seqs = np.asarray(frames["pose"][key].to_numpy())
    joined = ["pose"]
    for field_name, df in frames.items():
        if field_name == "pose":
            continue
        common = np.intersect1d(seqs, df[key].to_numpy())
        if common.size == 0:
            others = ", ".join(_name(sources[f], where) for f in joined)
            raise RecordingError(
                f"{where}: {_name(sources[field_name], where)} shares no {what} with {others} "
                "(its stamps never align with theirs)"
            )
        seqs = common
        joined.append(field_name)
    if seqs.size < MIN_TICKS:
        raise RecordingError(
            f"{where}: the topics share {seqs.size} tick(s) ({what}); a recording needs at least "
            f"{MIN_TICKS} (one tick has no period)"
        )
    aligned = {name: df[df[key].isin(seqs)].reset_index(drop=True) for name, df in frames.items()}

    # Integer nanoseconds: a float of 1.67e9 s keeps only ~0.2 µs, so subtract first.
    stamps = {
        name: df[SECS_COLUMN].to_numpy(np.int64) * 1_000_000_000 + df[NSECS_COLUMN].to_numpy(np.int64)
        for name, df in aligned.items()
    }
    ns = stamps["pose"]
    time = (ns - ns[0]).astype(np.float64) * 1e-9
    steps = np.diff(time)
    if np.any(steps <= 0.0):
        k = int(np.argmax(steps <= 0.0))
        raise RecordingError(
            f"{sources['pose']}: header stamps do not increase at {'seq' if key == SEQ_COLUMN else key} {int(seqs[k + 1])}"
        )
    mismatch = max(int(np.max(np.abs(s - ns))) for s in stamps.values()) * 1e-9
    if steps.size and mismatch > 0.5 * float(np.median(steps)):  # rows of one seq that are not one moment
        worst = max(stamps, key=lambda f: int(np.max(np.abs(stamps[f] - ns))))
        k = int(np.argmax(np.abs(stamps[worst] - ns)))
        raise RecordingError(
            f"{sources[worst]}: its header stamp at {'seq' if key == SEQ_COLUMN else key} {int(seqs[k])} is "
            f"{mismatch * 1e3:.1f} ms from the pose's, more than half a period: the topics' rows are not one moment"
        )
    receive = aligned["pose"][RECEIVE_COLUMN].to_numpy(float) if RECEIVE_COLUMN in aligned["pose"] else None

    arrays: dict[str, np.ndarray] = {}
    n_denormals = 0
    for field_name, (_, pattern) in TOPIC_FILES.items():
        values = aligned[field_name][[pattern.format(ax=ax) for ax in dofs]].to_numpy(np.float64)
        tiny = (values != 0.0) & (np.abs(values) < DENORMAL_THRESHOLD)
        n_denormals += int(tiny.sum())
        arrays[field_name] = np.where(tiny, 0.0, values)

    by_seq = key == SEQ_COLUMN
    extra = {
        "recording": recording,
        "dofs": list(dofs),
        "rows_dropped": max(lengths.values()) - int(seqs.size),
        "rows_dropped_per_file": {f: n - int(seqs.size) for f, n in lengths.items()},
        "max_gap_s": float(steps.max()) if steps.size else 0.0,
        "max_receive_gap_s": float(np.max(np.diff(receive))) if receive is not None and receive.size > 1 else None,
        "seq_gaps": int(np.sum(np.diff(seqs) - 1)) if by_seq else None,
        "stamp_mismatch_max_s": mismatch,
        "n_denormals_zeroed": n_denormals,
        "seq_first": int(seqs[0]) if by_seq else None,
        "seq_last": int(seqs[-1]) if by_seq else None,
    }
    dt = float(np.median(steps))  # MIN_TICKS >= 2: a period exists
    _warn_gaps(where, time, dt)
    _warn_short_topic(where, lengths, int(seqs.size))
    meta = TrialMeta(
        user=user,
        task="real",
        object="unknown",
        controller="unknown",
        model_id=None,
        seed=None,
        origin="real",
        dt=dt,
        extra=extra,
    )
    return Trial(meta=meta, time=time, **arrays)


def _check_frames(frames: Mapping[str, pd.DataFrame], sources: Mapping[str, str], where: str) -> None:
    """Every topic in one frame: the import reads the pose, velocity, wrench and reference as they are, with no
    transform, so a wrench recorded in the sensor's frame would be read as the base frame's (a hand pushing along
    the tool's x taken as a push along the base's). An unset frame (empty, as in the thesis lab's exports) is
    taken to be the others'; a topic whose frame changes within the recording is refused too."""
    named: dict[str, str] = {}
    for field_name, df in frames.items():
        if FRAME_COLUMN not in df:
            continue
        ids = sorted({str(v) for v in df[FRAME_COLUMN].tolist() if not pd.isna(v)} - {""})  # empty reads as NaN
        if len(ids) > 1:
            raise RecordingError(
                f"{sources[field_name]}: {FRAME_COLUMN} changes within the recording ({', '.join(map(repr, ids))}); "
                "a topic's messages must be in one frame"
            )
        if ids:
            named[field_name] = ids[0]
    if len(set(named.values())) > 1:
        said = ", ".join(f"{_name(sources[f], where)} in {frame!r}" for f, frame in named.items())
        raise RecordingError(
            f"{where}: its topics are in different frames ({said}); the import reads them as they are, with no "
            "transform: record or export them in the robot's base frame"
        )


def _name(source: str, where: str) -> str:
    """A source (``<folder>/current_pose.csv``, ``<bag>: topic /x``) without its recording's prefix."""
    if source.startswith(where):
        return source[len(where) :].lstrip("/: ") or source
    return source


def natural_key(path: Path) -> tuple:
    """Sort key of a file name with its digit runs as numbers (``trial_2`` before ``trial_10``)."""
    return natural_text_key(path.name)


def natural_text_key(text: str) -> tuple:
    """Sort key of ``text`` with its digit runs as numbers (``user-a/trial_2`` before ``user-a/trial_10``)."""
    return tuple(int(p) if p.isdigit() else p for p in re.split(r"(\d+)", text))


def load_ros_user(folder: str | os.PathLike[str], *, dofs: Sequence[str] = ("x", "y")) -> list[Trial]:
    """Load every ``trial_*`` subfolder of a user's folder, in natural numeric order.

    ``trial_2`` comes before ``trial_10``. The user id is the folder's name.
    """
    folder = Path(folder)
    return [load_ros_trial(p, user=folder.name, dofs=dofs) for p in recording_folders(folder)]


def recording_folders(folder: str | os.PathLike[str]) -> list[Path]:
    """The ``trial_*`` subfolders of a user's folder, in natural numeric order."""
    folder = Path(folder)
    if not folder.is_dir():
        raise RecordingError(f"{folder}: user folder not found")
    trial_dirs = sorted((p for p in folder.iterdir() if p.is_dir() and p.name.startswith("trial_")), key=natural_key)
    if not trial_dirs:
        raise RecordingError(f"{folder}: no trial_* subfolders")
    return trial_dirs


def default_real_data() -> Path:
    """Where the real UR5 recordings are looked for: ``$COASSIST_REAL_DATA`` if set, else
    ``shared/data/ur5-thesis`` beside this checkout (``<repo>/../shared/...``).

    The folder holds ``user-a/`` and ``user-b/``; it may not exist (callers skip or say so).
    """
    env = os.environ.get("COASSIST_REAL_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3].parent / "shared" / "data" / "ur5-thesis"
