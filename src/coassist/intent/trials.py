"""Where training and evaluation trials come from: dataset folders or real recordings.

A path may be
- one trial file written by :func:`coassist.data.write_trial` (``.parquet``);
- a dataset folder written by :func:`coassist.data.write_dataset` (has ``manifest.json``);
- a real user's folder of recordings (``trial_*`` subfolders of rosbag CSVs, e.g.
  ``.../ur5-thesis/user-a``);
- one recording folder (``current_pose.csv`` and friends);
- one ROS 1 or ROS 2 bag (``.bag``, ``.mcap``, ``.db3`` or a ROS 2 bag folder), or a
  folder of bags (:mod:`coassist.data.bags`, the same topics as the CSV export);
- a folder of trial files (``drive``'s and ``ros2``'s runs): the files, and a bag beside them only where no trial
  file has its name (``drive --mcap`` writes each run twice: the trial file keeps the whole record).

A folder given as ``.`` is named by its own name. Two trials of one id from two different paths (two folders ``D``)
are both read, the second named by the folder where the paths part (``b/D/…``); one path given twice is refused.

Each trial gets a stable id, ``<dataset id>/<trial name>``, used to split by trial and
recorded in the model's sidecar, with its contents' digest (:func:`content_digest`: a copy of a trial under another
name is still the trial a model trained on).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from coassist.data import RecordingError, Trial, TrialFileError, load_ros_trial, read_dataset, read_trial
from coassist.data.bags import bag_paths, is_bag, load_bag_trial
from coassist.data.datasets import MANIFEST_NAME, unfinished_collection
from coassist.data.rosbag_csv import recording_folders

__all__ = ["LabeledTrial", "content_digest", "hash_arrays", "load_trials"]


class LabeledTrial(NamedTuple):
    id: str  # unique, stable: "<dataset>/<trial>"
    dataset: str  # dataset id ("D0", "ur5-thesis/user-a", …)
    trial: Trial


#: What a trial's contents are, for :func:`content_digest`: what a model's windows read (its features, its plan and
#: the tool's future) and the clock they are on.
DIGEST_ARRAYS = ("time", "pose", "velocity", "wrench", "reference")


def content_digest(trial: Trial) -> str:
    """A fingerprint of ``trial``'s contents (16 hex digits of the SHA-256 of :data:`DIGEST_ARRAYS` as float64, with
    their shapes), not of its name or file: the same trial copied to another folder, file or format that keeps every
    value has the same digest. A training records its trials' digests (``train_digests``) so that ``coassist
    evaluate`` leaves out a copy of a training trial as it leaves out the trial (what its id alone cannot tell)."""
    h = hashlib.sha256()
    hash_arrays(h, trial, DIGEST_ARRAYS)
    return h.hexdigest()[:16]


def hash_arrays(h: Any, trial: Trial, names: Iterable[str]) -> None:
    """Feed ``h`` (a hashlib object) each of ``trial``'s arrays ``names`` that it has (None: left out), as float64
    with its name and shape: what :func:`content_digest` and a checkpoint's ``trials_digest`` hash."""
    for name in names:
        value = getattr(trial, name, None)
        if value is not None:
            arr = np.ascontiguousarray(value, dtype=np.float64)
            h.update(name.encode() + str(arr.shape).encode())
            h.update(arr.data)


def _load_one(
    path: Path, on_bad: Callable[[str, str], None] | None, bag_topics: Mapping[str, str] | None
) -> list[LabeledTrial]:
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    # a trial named alone (a file, a bag, a recording folder) is left out as the trials of a folder are where it
    # cannot be read and on_bad is given (--skip-bad-trials)
    if is_bag(path):
        dataset = path.absolute().parent.name
        name = f"{dataset}/{path.stem if path.is_file() else path.name}"
        return _load_each([path], lambda bag: load_bag_trial(bag, topics=bag_topics), dataset, on_bad, name=name)
    if path.is_file():  # one trial file (coassist collect / drive / play write them)
        dataset = path.absolute().parent.name
        return _load_each([path], read_trial, dataset, on_bad, name=f"{dataset}/{path.stem}")
    if (path / MANIFEST_NAME).is_file():
        ds = read_dataset(path, skip_bad=on_bad is not None)
        for name, reason in ds.skipped:
            on_bad(str(path / name), reason)  # type: ignore[misc]
        return [LabeledTrial(f"{ds.id}/{Path(f).stem}", ds.id, t) for f, t in zip(ds.files, ds.trials)]
    unfinished = unfinished_collection(path)
    if unfinished:  # a killed collect's .<out>.partial: some of its trials, no manifest yet
        raise ValueError(unfinished)
    here = path.resolve()  # "." or "./" name the folder by its own name (its user, its dataset)
    if (path / "current_pose.csv").is_file():
        dataset = f"{here.parent.parent.name}/{here.parent.name}"
        return _load_each([path], load_ros_trial, dataset, on_bad, name=f"{dataset}/{here.name}")
    bags = bag_paths(path)
    recordings = path.is_dir() and any(p.is_dir() and p.name.startswith("trial_") for p in path.iterdir())
    loose = sorted(p for p in path.glob("*.parquet") if p.is_file()) if path.is_dir() and not recordings else []
    if loose:
        # trial files side by side (drive's and ros2's, with their .mcap bags beside them): the files, which keep the
        # whole trial record (the controller, the person, the intent); a bag without a trial file of its name too
        out = []
        for file in loose:
            out += _load_each([file], read_trial, here.name, on_bad, name=f"{here.name}/{file.stem}")
        stems = {file.stem for file in loose}
        alone = [bag for bag in bags if Path(bag).stem not in stems]
        for bag in alone:
            name = f"{here.name}/{Path(bag).stem}"
            out += _load_each([bag], lambda b: load_bag_trial(b, topics=bag_topics), here.name, on_bad, name=name)
        return out
    dataset = f"{here.parent.name}/{here.name}"
    if bags:
        return _load_each(bags, lambda bag: load_bag_trial(bag, user=here.name, topics=bag_topics), dataset, on_bad)
    if recordings:
        return _load_each(
            recording_folders(path), lambda folder: load_ros_trial(folder, user=here.name), dataset, on_bad
        )
    raise FileNotFoundError(
        f"{path}: not a dataset folder ({MANIFEST_NAME}), a recording folder (current_pose.csv), "
        "a folder of trial_* recordings, a bag or a folder of bags"
    )


def _load_each(
    paths,
    load: Callable[[Path], Trial],
    dataset: str,
    on_bad: Callable[[str, str], None] | None,
    name: str | None = None,
) -> list[LabeledTrial]:
    """``load`` each recording, bag or trial file of ``paths``; an unreadable one (a :class:`RecordingError` or
    :class:`TrialFileError`) raises, or goes to ``on_bad`` and is left out. ``name``: the id of a trial named alone
    (else ``dataset/<its recording>``)."""
    out = []
    for item in paths:
        try:
            t = load(item)
        except (RecordingError, TrialFileError) as exc:
            if on_bad is None:
                raise
            on_bad(str(item), str(exc))
            continue
        out.append(LabeledTrial(name or f"{dataset}/{t.meta.extra['recording']}", dataset, t))
    return out


def load_trials(
    paths: Iterable[str | os.PathLike[str]],
    *,
    on_bad: Callable[[str, str], None] | None = None,
    bag_topics: Mapping[str, str] | None = None,
) -> list[LabeledTrial]:
    """Load every trial under ``paths``, in the order given; ids must not repeat.

    ``on_bad``: None stops at the first unreadable trial (the error names it); a callable
    leaves such trials out and is told ``on_bad(where, reason)`` for each.
    ``bag_topics``: field -> topic name for bags (:func:`coassist.data.bags.load_bag_trial`).
    """
    out: list[LabeledTrial] = []
    seen: dict[str, Path] = {}  # id -> the path given that holds it
    for p in paths:
        given = Path(p)
        for lt in _load_one(given, on_bad, bag_topics):
            if lt.id in seen:
                first = seen[lt.id]
                if first.resolve() == given.resolve():  # the same file or folder, given twice
                    raise ValueError(f"trial {lt.id!r} is given twice ({first} and {given})")
                # another trial of the same name (two folders D, two files x/run): named by the folders above it
                lt = lt._replace(id=_distinct(lt.id, given, first, seen))
            seen[lt.id] = given
            out.append(lt)
    if not out:
        raise ValueError("no trials given")
    return out


def _distinct(tid: str, given: Path, first: Path, seen: Mapping[str, Path]) -> str:
    """``tid`` prefixed with the name in ``given``'s path where it parts from ``first``'s (two folders ``a/D`` and
    ``b/D``: ``b/D/…``), and the names above it while that is an id a trial loaded so far has."""
    mine, theirs = given.resolve().parts, first.resolve().parts
    k = next((k for k in range(1, len(mine) + 1) if k > len(theirs) or mine[-k] != theirs[-k]), len(mine))
    for name in reversed(mine[1 : len(mine) - k + 1]):  # the differing name, then the ones above it
        tid = f"{name}/{tid}"
        if tid not in seen:
            return tid
    raise ValueError(f"trial {tid!r} is given twice ({first} and {given})")
