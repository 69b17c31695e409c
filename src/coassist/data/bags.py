"""Load hand-guiding trials straight from ROS 1 and ROS 2 bags (sqlite3 or MCAP).

The thesis recorded its runs as rosbags and exported them to CSV
(:mod:`coassist.data.rosbag_csv`). This module reads the bags themselves, with the
same topic mapping, the same alignment and the same clean-up, so a bag and its CSV
export load to the same :class:`~coassist.data.trial.Trial`:

=====================  ==================================  =========================
field                  default topic                       message type, value read
=====================  ==================================  =========================
pose                   ``/current_pose``                   PoseStamped, pose.position
velocity               ``/current_velocity``               TwistStamped, twist.linear
wrench                 ``/human_wrench``                   WrenchStamped, wrench.force
reference              ``/robot_ref_pos``                  PoseStamped, pose.position
=====================  ==================================  =========================

(all ``geometry_msgs``). The topic names are configurable (``topics=``), the types are
not: a topic of another type is an error, since ``Pose`` has no stamp to align on and
``Wrench`` no header.

Alignment. A ROS 1 header carries ``seq``: the four topics are inner-joined on it,
exactly as the CSV export's ``header.seq`` column. A ROS 2 header has no ``seq``: the
topics are joined on the header stamp [ns] (the controller publishes the four topics of
one tick with one stamp; on the UR5 recordings the two joins give the same rows), and
``seq_first``/``seq_last``/``seq_gaps`` in ``meta.extra`` are None. Time comes from the
header stamps, the receive time (``Time`` in the CSV) from the bag's log time, and
``rows_dropped_per_file`` is keyed by topic name.

Bad input gets one line naming the bag, the topic and the problem
(:class:`~coassist.data.rosbag_csv.RecordingError`): a missing or empty topic, a topic
of the wrong type, a NaN or infinite value, an implausible one
(:func:`~coassist.data.rosbag_csv.check_plausible`), a repeated or decreasing header
stamp (or ``seq``), topics whose stamps never align, a malformed ``metadata.yaml``.

A damaged file. What each format lets a reader verify is verified: an MCAP chunk's CRC
(rosbags checks it; ROS 2's own writer and :func:`coassist.data.trial_mcap.write_trial_mcap`
write it), and for every format the number of messages of each topic the bag's index
records (a ROS 2 bag's ``metadata.yaml``, an MCAP's summary, a ROS 1 bag's chunk
index) against the number read: a file that lost messages is refused, never loaded
short. Whatever else a damaged file makes the reader raise (its internals: ``OverflowError``,
``struct.error``, a decoder's error) is one line naming the file. Not decidable: a
value changed inside a message of a format without checksums (ROS 1, sqlite3, an MCAP
written without CRCs) loads if it is finite and plausible. Reading needs the ``bags``
extra (``rosbags``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from coassist.data.rosbag_csv import (
    FRAME_COLUMN,
    NSECS_COLUMN,
    RECEIVE_COLUMN,
    SECS_COLUMN,
    SEQ_COLUMN,
    TOPIC_FILES,
    RecordingError,
    assemble_recording,
    check_dofs,
    check_plausible,
    natural_key,
)
from coassist.data.trial import Trial

__all__ = ["BAG_SUFFIXES", "BAG_TOPICS", "BAG_TYPES", "bag_paths", "is_bag", "load_bag_trial", "resolve_topics"]

#: Trial field -> default topic (the thesis' topic names, as in the CSV export).
BAG_TOPICS: Mapping[str, str] = {
    "pose": "/current_pose",
    "velocity": "/current_velocity",
    "wrench": "/human_wrench",
    "reference": "/robot_ref_pos",
}
#: Trial field -> the message type its topic must have (rosbags' normalised names).
BAG_TYPES: Mapping[str, str] = {
    "pose": "geometry_msgs/msg/PoseStamped",
    "velocity": "geometry_msgs/msg/TwistStamped",
    "wrench": "geometry_msgs/msg/WrenchStamped",
    "reference": "geometry_msgs/msg/PoseStamped",
}
#: File suffixes read as bags: ROS 1, ROS 2 MCAP, ROS 2 sqlite3.
BAG_SUFFIXES = (".bag", ".mcap", ".db3")
_INSTALL_HINT = "reading bags needs rosbags: pip install 'coassist[bags]'"
_STAMP = "stamp_ns"  # the CSV export's column names (SEQ_COLUMN … RECEIVE_COLUMN) are the CSV loader's: one assembly reads both


def is_bag(path: str | os.PathLike[str]) -> bool:
    """True for a bag file (:data:`BAG_SUFFIXES`) or a ROS 2 bag folder (``metadata.yaml``)."""
    path = Path(path)
    if path.is_file():
        return path.suffix in BAG_SUFFIXES
    return path.is_dir() and (path / "metadata.yaml").is_file()


def bag_paths(folder: str | os.PathLike[str]) -> list[Path]:
    """The bags directly inside ``folder`` (files and ROS 2 bag folders), in natural order.

    A ``.db3`` or ``.mcap`` inside a ROS 2 bag folder belongs to that folder and is not
    listed on its own. Empty when there is none.
    """
    folder = Path(folder)
    if not folder.is_dir() or is_bag(folder):
        return []
    return sorted((p for p in folder.iterdir() if is_bag(p)), key=natural_key)


def resolve_topics(topics: Mapping[str, str] | None) -> dict[str, str]:
    """:data:`BAG_TOPICS` with ``topics`` (field -> topic name) over it; ValueError naming a bad entry."""
    out = dict(BAG_TOPICS)
    if topics is None:
        return out
    if not isinstance(topics, Mapping):
        raise ValueError(f"topics must map a field to a topic name, got {type(topics).__name__}")
    for name, topic in topics.items():
        if name not in BAG_TOPICS:
            raise ValueError(f"topics: unknown field {name!r}; the fields are {tuple(BAG_TOPICS)}")
        if not isinstance(topic, str) or not topic.startswith("/") or len(topic) < 2:
            raise ValueError(f"topics[{name!r}] must be a topic name starting with '/', got {topic!r}")
        out[name] = topic
    if len(set(out.values())) != len(out):
        raise ValueError(f"topics must name four different topics, got {out}")
    return out


def _receive_seconds(ns: list[int]) -> np.ndarray:
    # int / int is correctly rounded in Python: a log time written from a CSV's float
    # receive time (rounded to ns) reads back as that very float. numpy's int64 → float64
    # conversion would round twice and can miss by one ulp.
    return np.array([n / 1_000_000_000 for n in ns], dtype=np.float64)


def _read_topic(
    reader: Any, connections: list, where: str, field_name: str, topic: str, columns: list[str], ros1: bool
) -> pd.DataFrame:
    paths = [c.split(".") for c in columns]
    rows: list[list[float]] = []
    secs: list[int] = []
    nsecs: list[int] = []
    seqs: list[int] = []
    log_ns: list[int] = []
    frame_ids: list[str] = []
    for connection, timestamp, raw in reader.messages(connections=connections):
        try:
            msg = reader.deserialize(raw, connection.msgtype)
        except Exception as exc:  # noqa: BLE001 - a corrupt message, named below
            raise RecordingError(f"{where}: topic {topic}: message {len(rows)} cannot be decoded ({exc})") from None
        values = []
        for col, attrs in zip(columns, paths):
            v = msg
            for a in attrs:
                v = getattr(v, a)
            v = float(v)
            if not math.isfinite(v):
                raise RecordingError(f"{where}: topic {topic}: message {len(rows)} has {col} = {v} (NaN or infinite)")
            values.append(v)
        rows.append(values)
        secs.append(int(msg.header.stamp.sec))
        nsecs.append(int(msg.header.stamp.nanosec))
        seqs.append(int(getattr(msg.header, "seq", 0)))
        frame_ids.append(str(getattr(msg.header, "frame_id", "")))
        log_ns.append(int(timestamp))
    if not rows:
        raise RecordingError(f"{where}: topic {topic} has no messages")
    indexed = sum(int(c.msgcount) for c in connections)
    if len(rows) != indexed:
        raise RecordingError(
            f"{where}: topic {topic}: {len(rows)} messages read, the bag's index records {indexed} "
            "(the file is damaged or was cut off)"
        )
    values = np.asarray(rows, dtype=np.float64)
    check_plausible(field_name, values, columns, f"{where}: topic {topic}", lambda r: f"message {r}")
    df = pd.DataFrame(values, columns=columns)
    df[SECS_COLUMN] = np.asarray(secs, dtype=np.int64)
    df[NSECS_COLUMN] = np.asarray(nsecs, dtype=np.int64)
    df[_STAMP] = df[SECS_COLUMN] * 1_000_000_000 + df[NSECS_COLUMN]
    df[RECEIVE_COLUMN] = _receive_seconds(log_ns)
    df[FRAME_COLUMN] = frame_ids  # one frame for every topic: checked with the others (assemble_recording)
    # In the order received: header stamps (and a ROS 1 seq) must strictly increase.
    checks = [(_STAMP, "header stamp")] + ([(SEQ_COLUMN, "header.seq")] if ros1 else [])
    if ros1:
        df[SEQ_COLUMN] = np.asarray(seqs, dtype=np.int64)
    for col, what in checks:
        step = np.diff(df[col].to_numpy())
        if np.any(step <= 0):
            k = int(np.argmax(step <= 0))
            a, b = int(df[col].iloc[k]), int(df[col].iloc[k + 1])
            if col == _STAMP:
                a_s, b_s = f"{a // 10**9}.{a % 10**9:09d} s", f"{b // 10**9}.{b % 10**9:09d} s"
            else:
                a_s, b_s = str(a), str(b)
            problem = "duplicated" if a == b else "out of order"
            raise RecordingError(f"{where}: topic {topic}: {what} {problem} at message {k + 1} ({a_s} then {b_s})")
    return df


def _one_line(exc: BaseException, limit: int = 200) -> str:
    """An exception's text on one line, at most ``limit`` characters."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _check_metadata_yaml(path: Path) -> None:
    """A ROS 2 bag's ``metadata.yaml`` parses as YAML (else one line: where and what, not the parser's dump)."""
    from ruamel.yaml import YAML
    from ruamel.yaml.error import MarkedYAMLError, YAMLError

    try:
        YAML(typ="safe").load(path.read_bytes())
    except MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise RecordingError(f"{path}: not valid YAML ({exc.problem or exc.context}{at})") from None
    except (YAMLError, UnicodeDecodeError, RecursionError) as exc:
        raise RecordingError(f"{path}: not valid YAML ({_one_line(exc)})") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot be read: {exc.strerror}") from None


def load_bag_trial(
    path: str | os.PathLike[str],
    *,
    user: str | None = None,
    dofs: Sequence[str] = ("x", "y"),
    topics: Mapping[str, str] | None = None,
) -> Trial:
    """Load one bag into a :class:`Trial` (module docstring).

    Parameters
    ----------
    path : path-like
        A ROS 1 ``.bag``, a ROS 2 bag folder (``metadata.yaml`` with ``.db3`` or
        ``.mcap``), or a lone ROS 2 ``.mcap`` file.
    user : str, optional
        Operator id; defaults to the name of the bag's parent folder.
    dofs : sequence of str
        ``("x",)``, ``("x", "y")`` (default) or ``("x", "y", "z")``.
    topics : mapping, optional
        Field -> topic name, overriding :data:`BAG_TOPICS` (e.g. ``{"wrench": "/ft"}``).

    Returns
    -------
    Trial
        As :func:`coassist.data.rosbag_csv.load_ros_trial`; ``meta.extra["recording"]``
        is the bag's name without suffix.

    Raises
    ------
    RecordingError
        One line naming the bag, the topic and the problem.
    ImportError
        rosbags is not installed.
    """
    path = Path(path)
    dofs = check_dofs(dofs)
    names = resolve_topics(topics)
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ImportError(f"{_INSTALL_HINT} ({exc})") from exc
    if not path.exists():
        raise RecordingError(f"{path}: bag not found")
    where = str(path)
    if user is None:
        user = path.absolute().parent.name
    recording = path.stem if path.is_file() else path.name
    if path.is_dir():
        _check_metadata_yaml(path / "metadata.yaml")
    frames: dict[str, pd.DataFrame] = {}
    try:
        # The default typestore serves ROS 2 bags that do not carry their message definitions.
        with AnyReader([path], default_typestore=get_typestore(Stores.LATEST)) as reader:
            ros1 = not reader.is2
            by_topic: dict[str, list] = {}
            for c in reader.connections:
                by_topic.setdefault(c.topic, []).append(c)
            for field_name, topic in names.items():
                conns = by_topic.get(topic)
                if not conns:
                    have = ", ".join(sorted(by_topic)) or "none"
                    raise RecordingError(f"{where}: no topic {topic} (the bag has: {have})")
                for c in conns:
                    if c.msgtype != BAG_TYPES[field_name]:
                        raise RecordingError(f"{where}: topic {topic} is {c.msgtype}, expected {BAG_TYPES[field_name]}")
                pattern = TOPIC_FILES[field_name][1]
                frames[field_name] = _read_topic(
                    reader, conns, where, field_name, topic, [pattern.format(ax=ax) for ax in dofs], ros1
                )
    except RecordingError:
        raise
    except AnyReaderError as exc:
        raise RecordingError(f"{where}: cannot read the bag ({_one_line(exc)})") from None
    except Exception as exc:  # noqa: BLE001 - a damaged file makes the reader's internals raise anything
        raise RecordingError(
            f"{where}: cannot read the bag, it is damaged ({type(exc).__name__}: {_one_line(exc)})"
        ) from None
    key = SEQ_COLUMN if ros1 else _STAMP
    sources = {name: f"{where}: topic {topic}" for name, topic in names.items()}
    lengths = {names[name]: len(df) for name, df in frames.items()}
    return assemble_recording(
        frames, where=where, sources=sources, lengths=lengths, user=user, dofs=dofs, recording=recording, key=key
    )
