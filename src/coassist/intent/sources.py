"""Where training and evaluation trials come from: dataset folders or real recordings.

A path may be
- a dataset folder written by :func:`coassist.data.write_dataset` (has ``manifest.json``);
- a real user's folder of recordings (``trial_*`` subfolders of rosbag CSVs, e.g.
  ``.../ur5-thesis/user-a``);
- one recording folder (``current_pose.csv`` and friends).

Each trial gets a stable id, ``<dataset id>/<trial name>``, used to split by trial and
recorded in the model's sidecar.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

from coassist.data import Trial, load_ros_trial, load_ros_user, read_dataset
from coassist.data.store import MANIFEST_NAME

__all__ = ["LabeledTrial", "load_trials"]


class LabeledTrial(NamedTuple):
    id: str  # unique, stable: "<dataset>/<trial>"
    dataset: str  # dataset id ("D0", "ur5-thesis/user-a", …)
    trial: Trial


def _load_one(path: Path) -> list[LabeledTrial]:
    if (path / MANIFEST_NAME).is_file():
        ds = read_dataset(path)
        files = [Path(e["file"]).stem for e in ds.manifest["trials"]]
        return [LabeledTrial(f"{ds.id}/{f}", ds.id, t) for f, t in zip(files, ds.trials)]
    if (path / "current_pose.csv").is_file():
        dataset = f"{path.absolute().parent.parent.name}/{path.absolute().parent.name}"
        t = load_ros_trial(path)
        return [LabeledTrial(f"{dataset}/{path.name}", dataset, t)]
    if path.is_dir() and any(p.is_dir() and p.name.startswith("trial_") for p in path.iterdir()):
        dataset = f"{path.absolute().parent.name}/{path.name}"
        return [LabeledTrial(f"{dataset}/{t.meta.extra['recording']}", dataset, t) for t in load_ros_user(path)]
    raise FileNotFoundError(
        f"{path}: not a dataset folder ({MANIFEST_NAME}), a recording folder (current_pose.csv) "
        "or a folder of trial_* recordings"
    )


def load_trials(paths: Iterable[str | os.PathLike[str]]) -> list[LabeledTrial]:
    """Load every trial under ``paths``, in the order given; ids must not repeat."""
    out: list[LabeledTrial] = []
    for p in paths:
        out.extend(_load_one(Path(p)))
    if not out:
        raise ValueError("no trials given")
    seen: set[str] = set()
    for lt in out:
        if lt.id in seen:
            raise ValueError(f"trial {lt.id!r} is given twice")
        seen.add(lt.id)
    return out
