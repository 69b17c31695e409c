"""The calibration block's fit: a participant's own person model, from their calibration trials.

A plan's ``[calibration]`` block records ``trials`` trials (at most 10) under manual guidance
with the calibration probe (controller ``manual-probe``, :mod:`coassist.control.probe`: small
known pushes, 2.5 N RMS per axis at 1.3–5.6 Hz, that the person feels and does not plan), the
plan's tasks in turn. Then :func:`fit_job` fits the participant's person model
(:mod:`coassist.scenario.person_model`) from them, in the study's background worker
(:class:`coassist.study.training.BackgroundTraining`), and writes it into their folder::

    participants/<id>/models/P0/
      fit.json                      what it was fitted from (below), written with it
      <task>/person-model.json      the intent source of one task (``intent = "calibrated"``)
      <task>/person-model.png       its paths and arm, drawn (:mod:`coassist.experiments.person_figure`)

What is fitted, told only what the trials recorded (the tool's pose and velocity, the wrench
at the handle, the robot's effort, the nominal plan shown; no obstacle, no intent label, no
model of how people detour):

1. the arm, K̂ and Ĉ, from every calibration trial of the attempt
   (:func:`~coassist.scenario.arm_identification.identify_arm`: the probe's lags as
   instruments). The typical arm is assumed instead
   (:data:`~coassist.scenario.arm_identification.ASSUMED_ARM`), and the record says why, where
   the trials hold no probe, or where the measurement says too little to be used: K̂ or Ĉ at the
   bound of a person's range, or K̂'s jackknife error above :data:`~coassist.scenario.arm_identification.ARM_SE_MAX` of it (a few short
   trials: a K̂ of 100 ± 715 N/m, clipped at the bound, would turn the present estimate's hand
   force into 8 times the displacement it is);
2. per task, the person's paths (:func:`~coassist.scenario.person_model.fit_person` with that
   arm) from the trials of the task that ended in the target (a demonstration of the way there;
   the others still measure the arm).

A calibration fails, with one line naming the task and how far the tool moved, when a task
has no trial that ended in the target (no motion, a hand that let go) or its paths cannot be
fitted; the runner then records the failure and runs the block again
(:func:`coassist.study.protocols.calibration_steps`).

An iterative study of the person model (``[iterative] source = "calibrated"``) refits it after
each round (``base``: P0): the paths from P0's demonstrations and every round's trials that
ended in the target; the arm stays P0's, since the rounds ran under assistance, without the
probe, and the arm cannot be measured from them (the intent is still reconstructed from them
with that arm: eq. 4.1 holds under any controller).

Each task's folder names the participant as its ``default`` person, so it applies whatever name
the world gives the person at the handle. The study records the SHA-256 of each task's
``person-model.json`` in the fit's progress line and checks it before every trial that uses it
and on every run (:meth:`coassist.study.folder.ParticipantFolder.audit`). The fit is
deterministic: a fit cut off by a kill is fitted again, the same.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from coassist.errors import CoassistError
from coassist.scenario.arm_identification import measured_arm

__all__ = [
    "FIT_FILE",
    "CalibrationFailed",
    "FitJob",
    "fit_job",
    "lead_lines",
    "model_hashes",
    "person_model_folder",
]

#: What a person-model folder of the study was fitted from (beside the task folders).
FIT_FILE = "fit.json"
#: [m] the tool counts as having moved once it left the start by this much (the failure's line).
MOVED = 0.005


class CalibrationFailed(CoassistError, ValueError):
    """A calibration that gave no person model; the text is one line saying why."""


def lead_lines(record: Mapping[str, Any]) -> dict[str, str]:
    """Per task of a fit's record (:func:`fit_job`'s), what its twin check decided, in a few words
    (:attr:`~coassist.scenario.person_model.LeadCheck.line`: "led along their paths: …" or "present estimate held
    (the lead did not pay): …"); tasks of a record written before the check left out."""
    from coassist.scenario.person_model import LeadCheck

    out = {}
    for task, paths in (record.get("paths") or {}).items():
        lead = paths.get("lead") if isinstance(paths, Mapping) else None
        if isinstance(lead, Mapping):
            out[task] = LeadCheck(**lead).line
    return out


@dataclass(frozen=True)
class FitJob:
    """One person model to fit for the participant ``person`` whose folder is ``root``: from the trials
    of its blocks ``data``, into ``root/models/<model>``; ``base`` the name of a person model of theirs
    whose arm is kept and whose demonstrations are added (an iterative refit), or None (a calibration:
    the arm measured): ``base_fit``, that model's fit as the progress log records it (its ``model``, ``arm``,
    ``arm_measured``, ``blocks`` and ``demonstrations``): what the refit builds on is the record the folder's
    audit checks, not a ``fit.json`` on disk, which nothing checks."""

    root: str
    data: tuple[str, ...]
    model: str
    person: str
    base_fit: Mapping[str, Any] | None = None

    @property
    def base(self) -> str | None:
        """The name of the person model the refit builds on (``base_fit``'s), or None (a calibration)."""
        return None if self.base_fit is None else str(self.base_fit["model"])

    @property
    def out(self) -> Path:
        return Path(self.root) / "models" / self.model


def person_model_folder(models: str | Path, task: str) -> Path:
    """The folder of a study's person model ``models`` (``…/models/P0``) for ``task``."""
    return Path(models) / task


def model_hashes(folder: str | Path, tasks: list[str]) -> dict[str, str]:
    """SHA-256 of each task's ``person-model.json`` in the study's person-model ``folder``."""
    from coassist.scenario.person_model import PERSON_MODEL_FILE

    out = {}
    for task in tasks:
        path = person_model_folder(folder, task) / PERSON_MODEL_FILE
        out[task] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def _moved(trial) -> float:
    """[m] how far the tool got from where it started."""
    p = np.asarray(trial.pose[:, :2], dtype=float)
    return float(np.max(np.linalg.norm(p - p[0], axis=1))) if len(p) else 0.0


def _read(root: str, blocks: tuple[str, ...] | list[str]) -> list[tuple[str, Any]]:
    """(block/file, trial) of every trial of the participant's ``blocks``, in order."""
    from coassist.data import read_dataset

    out = []
    for block in blocks:
        ds = read_dataset(Path(root) / block)
        out += [(f"{block}/{f}", t) for f, t in zip(ds.files, ds.trials)]
    return out


def fit_job(job: FitJob) -> dict[str, Any]:
    """Fit and write one person model (module docstring); returns what the study records of it.
    :class:`CalibrationFailed` (one line) where a task has no demonstration or cannot be fitted."""
    from coassist._io import OutputLock, atomic_write_text, staged_folder
    from coassist.experiments.person_calibration import probes_for_arm
    from coassist.experiments.person_figure import PERSON_FIGURE_FILE, write_person_figure
    from coassist.scenario.arm_identification import ArmEstimate, identify_arm
    from coassist.scenario.person_model import fit_person, person_filter_for, write_person_model
    from coassist.sim.person_twin import lead_check

    t0, c0 = time.perf_counter(), time.process_time()
    trials = _read(job.root, job.data)
    if not trials:
        raise CalibrationFailed("no calibration trial to fit the person model from")
    base = job.base_fit
    if base is not None:
        arm = ArmEstimate(**base["arm"])
        demos_of_base = {f for files in base["demonstrations"].values() for f in files}
        trials = [(f, t) for f, t in _read(job.root, base["blocks"]) if f in demos_of_base] + trials
        arm_note = f"{job.base}'s (the rounds ran without pushes)"
        measured = base.get("arm_measured", False)
    else:  # from the probe trials whose mount does not twist, as coassist calibrate measures it
        rigid, twisting = probes_for_arm([t for _, t in trials])
        estimate = identify_arm(rigid)
        arm, arm_note = measured_arm(estimate)
        measured = not arm_note
        arm_note = arm_note or f"measured from {arm.trials} trials with pushes"
        if twisting:
            arm_note = f"{arm_note}; {twisting}"
    tasks = list(dict.fromkeys(t.meta.task for _, t in trials))
    fits, demos, left_out = {}, {}, {}
    for task in tasks:
        of_task = [(f, t) for f, t in trials if t.meta.task == task]
        use = [(f, t) for f, t in of_task if t.meta.extra.get("ended") == "target"]
        used = {f for f, _ in use}
        left_out[task] = {f: str(t.meta.extra.get("ended")) for f, t in of_task if f not in used}
        if not use:
            ended = ", ".join(sorted({str(t.meta.extra.get("ended")) for _, t in of_task}))
            moved = max(_moved(t) for _, t in of_task)
            raise CalibrationFailed(
                f"no calibration trial of task {task!r} ended in the target ({len(of_task)} ended: {ended}; the tool "
                f"moved {100 * moved:.1f} cm from the start at most{': no motion' if moved < MOVED else ''}): the "
                "person model cannot learn the way there"
            )
        try:
            fit = fit_person([t for _, t in use], arm=arm)
        except ValueError as exc:
            raise CalibrationFailed(f"the paths of task {task!r} could not be fitted: {exc}") from None
        # whether to lead the person along their paths: their calibration replayed against their twin
        origin = str(use[0][1].meta.origin)
        fits[task] = replace(fit, lead=lead_check([t for _, t in use], fit, person_filter_for(origin)))
        demos[task] = [f for f, _ in use]
    blocks = list(dict.fromkeys(f.split("/", 1)[0] for f, _ in trials))
    record = {
        "model": job.model,
        "person": job.person,
        "base": job.base,
        "blocks": blocks,
        "tasks": tasks,
        "demonstrations": demos,
        "left_out": left_out,
        "arm": asdict(arm),
        "arm_measured": measured,
        "arm_note": arm_note,
        "paths": {
            task: {
                "demonstrations": len(demos[task]),
                "sides": [int(s) for s in fit.paths.sides],
                "noise_m": float(fit.paths.noise),
                # how far the demonstrations repeat (PathModel.repeatability; None: no way taken twice)
                "repeatability": fit.paths.repeatability(),
                # whether the model leads them along their paths (the calibration's twin check, LeadCheck)
                "lead": None if fit.lead is None else asdict(fit.lead),
            }
            for task, fit in fits.items()
        },
    }
    with OutputLock(job.out), staged_folder(job.out) as stage:
        for task, fit in fits.items():
            folder = person_model_folder(stage, task)
            # the filter of the study's world (one world a study: its trials' origin; the MuJoCo UR5's has no yaw)
            settings = person_filter_for(trials[0][1].meta.origin)
            origins = sorted({t.meta.origin for _, t in trials})
            write_person_model(folder, {job.person: fit}, default=job.person, settings=settings, origins=origins)
            heading = f"{job.person}, {job.model} ({task}, {len(demos[task])} demonstrations)"
            write_person_figure([(heading, fit)], folder / PERSON_FIGURE_FILE)
        atomic_write_text(stage / FIT_FILE, json.dumps(record, indent=1, allow_nan=False) + "\n")
    record["sha256"] = model_hashes(job.out, tasks)
    record["fit_seconds"] = round(time.perf_counter() - t0, 3)
    record["fit_cpu_seconds"] = round(time.process_time() - c0, 3)
    return record
