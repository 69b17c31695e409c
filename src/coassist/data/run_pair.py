"""A run's record on disk: its trial file and, on request, its MCAP, written as one pair.

``coassist drive --mcap`` and ``coassist ros2 --mcap`` keep a run as ``<out>.parquet`` (the
trial, :func:`coassist.data.write_trial`) and ``<out>.mcap`` beside it
(:func:`coassist.data.trial_mcap.write_trial_mcap`). The two are one record: an MCAP
beside a trial must be that trial's. Two files cannot be renamed in one step, so
:func:`write_run_pair` orders the steps so that no crash — an exception, Ctrl-C, a
``kill -9`` at any instant — leaves a trial beside another run's MCAP:

1. both files are written whole into a staging folder beside the trial
   (``.<name>.<pid>.<token>.new``, fsync'ed; the MCAP writer's own scratch folder inside it);
2. an old ``<out>.mcap`` is moved aside (``.<out>.mcap.<pid>.<token>.tmp``): from here
   the old trial stands alone, never beside a new MCAP;
3. the new trial replaces the old one (one ``rename``);
4. the new MCAP is renamed into place (with ``mcap``);
5. the folder is fsync'ed, the old MCAP and the staging folder deleted.

The MCAP's stamps are the live view's where one watched the run (``--foxglove``): tick k at
``start + round(k·dt·1e9)`` ns, ``start`` the wall clock the view stamped tick 0 with, which
:meth:`~coassist.runtime.live.LiveFeed.watch` records in the trial (``meta.extra["live_start_ns"]``);
without one, from 0 (the trial's own clock).

After a kill the folder holds the old pair, the old trial alone, the new trial alone, or
the new pair, plus the dead writer's pid-named temporaries, which the next write beside
them removes (:func:`coassist._io.remove_stale`). Without ``mcap``, an old ``<out>.mcap``
is removed in step 2 all the same: it described the trial being replaced.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Sequence
from pathlib import Path

from coassist._io import fsync_dir, remove_stale, temp_name
from coassist.data.trial import Trial
from coassist.data.trial_file import write_trial

__all__ = ["LIVE_START", "write_run_pair"]

#: The trial meta field (``meta.extra``) holding the live view's start [ns since the epoch]: the stamp
#: of tick 0 on the live view, written by :meth:`coassist.runtime.live.LiveFeed.watch`.
LIVE_START = "live_start_ns"


def write_run_pair(
    trial: Trial,
    path: str | os.PathLike[str],
    *,
    mcap: bool = False,
    alpha: float | None = None,
    joint_names: Sequence[str] | None = None,
    frame_id: str = "base",
) -> tuple[Path, Path | None]:
    """Write ``trial`` to ``path`` and, with ``mcap``, to ``path`` with suffix ``.mcap`` (module docstring).

    alpha, joint_names, frame_id : :func:`~coassist.data.trial_mcap.write_trial_mcap`'s (frame_id: the
    robot's base frame). The MCAP's start is the live view's (module docstring). Returns (trial
    path, MCAP path or None). On an exception before step 2 nothing on disk has changed.
    """
    if not isinstance(trial, Trial):
        raise ValueError(f"write_run_pair expects a Trial, got {type(trial).__name__}")
    path = Path(path)
    if path.suffix == ".mcap":
        raise ValueError(f"{path}: the trial file and its MCAP would be the same file")
    mcap_path = path.with_suffix(".mcap")
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    for name in (path.name, mcap_path.name):
        remove_stale(folder, name)
    staging = folder / temp_name(path.name, "new")
    os.mkdir(staging)
    aside: Path | None = None
    replaced = False
    try:
        # 1. both files whole, beside their places (same file system: the renames are atomic)
        staged_trial = write_trial(trial, staging / "trial.parquet")
        staged_mcap = None
        if mcap:
            from coassist.data.trial_mcap import write_trial_mcap

            staged_mcap = write_trial_mcap(
                trial,
                staging / "trial.mcap",
                alpha=alpha,
                joint_names=joint_names,
                frame_id=frame_id,
                # stamped as the live view stamped it, where one watched: its messages are the file's
                start_ns=trial.meta.extra.get(LIVE_START, 0),
            )
        fsync_dir(staging)
        # 2. the old MCAP aside: the old trial is alone from here
        if mcap_path.exists() or mcap_path.is_symlink():
            aside = folder / temp_name(mcap_path.name, "tmp")
            os.rename(mcap_path, aside)
        # 3., 4. the new trial, then its MCAP
        os.replace(staged_trial, path)
        replaced = True
        if staged_mcap is not None:
            os.replace(staged_mcap, mcap_path)
        fsync_dir(folder)
    except BaseException:
        if aside is not None and not replaced:  # the old trial is still there: its MCAP goes back beside it
            os.rename(aside, mcap_path)
            aside = None
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    # 5. what the old pair leaves
    if aside is not None:
        aside.unlink(missing_ok=True)
        fsync_dir(folder)
    return path, (mcap_path if mcap else None)
