"""A lab's calibration: recorded trials → one person model per person (``coassist calibrate``).

A lab records a few trials of each person on a task (``coassist collect`` / ``drive`` / ``play``
with the controller ``manual-probe``: manual guidance plus the probe that measures the arm),
then fits them here. The trials are grouped by person (``TrialMeta.user``); each person's
trials must be of one task (one nominal path, one control rate, the planar x-y motion); each
group is fitted by :func:`~coassist.scenario.person_model.fit_person`:

- the arm (K̂, Ĉ) from the person's probe trials alone (controller ``manual-probe``): the probe
  is a push the person does not plan, which is what makes the arm measurable. A trial under
  any other controller carries the robot's own effort, which follows the person's motion and
  would bias the estimate; without a probe trial the arm is *assumed*
  (:data:`~coassist.scenario.arm_identification.ASSUMED_ARM`), and the summary says so. So it is where
  the measurement says too little to be used (:func:`~coassist.scenario.arm_identification.measured_arm`:
  at the bound of a person's range, or too uncertain), as in a study's calibration block. Probe trials on an
  object whose mount twists (the board) are left out of the arm's fit: the twist is a spring in series
  with the arm (docs/person-model.md, "The hand, not the tip"), which the online filter puts back itself;
- the person's paths from all of their trials (the intent each pursued, reconstructed with that arm).

:func:`calibrate_people` checks and fits, :func:`summary_line` says in one line what was
learnt of each person, and :func:`~coassist.scenario.person_model.write_person_model` writes
the folder ``--intent`` takes. Every refusal is a :class:`CalibrationError` in one line that
names the person and the trial.
"""

from __future__ import annotations

import bisect
import hashlib
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from coassist._checks import check_int
from coassist.data import Trial
from coassist.errors import CoassistError
from coassist.interfaces import MOTION_LIMITED, Fault
from coassist.scenario.arm_identification import identify_arm, measured_arm
from coassist.scenario.objects import get_object
from coassist.scenario.path_model import (
    ASKED_WAY,
    FEW_PATHS,
    WAY_SIGNS,
    PathFrame,
    PathModel,
    check_way,
    few_paths,
)
from coassist.scenario.person_model import RIGID_HOLD_ORIGINS, PersonFit, fit_person, person_filter_for
from coassist.sim.person_twin import lead_check

__all__ = [
    "MIN_TRIALS",
    "PROBE_CONTROLLER",
    "UNRECORDED_CONTROLLER",
    "CalibrationError",
    "PersonCalibration",
    "calibrate_people",
    "mount_twists",
    "probes_for_arm",
    "summary_line",
    "thin_ways",
    "ways_to_ask",
]

#: The fewest trials a person is calibrated from: the arm's standard error is a jackknife over trials
#: (it needs three), and one or two demonstrations say little of the ways round an obstacle.
MIN_TRIALS = 3
#: The controller kind whose trials carry the probe (coassist.control.presets).
PROBE_CONTROLLER = "manual-probe"
#: The controller a trial records where its file does not say (a bag or a ROS recording: coassist.data.rosbag_csv).
UNRECORDED_CONTROLLER = "unknown"
#: [m] two trials follow one nominal path when no point of one lies further than this from the other
#: (the person model's own test: coassist.scenario.person_intent).
SAME_PATH = 0.01
#: A calibration trial moves the tool along at least this share of the plan's length.
MIN_PROGRESS = 0.5
#: [m] how far along the plan the tool's nearest point may move from one sample to the next when its progress is
#: followed (a tool out on a detour near another stretch of the plan, the Z's legs, is not taken to be there); the
#: tool moves about 2 mm a sample at 125 Hz.
PROGRESS_STEP = 0.02
#: [m] a trial whose tool ends this near the plan's end reached it, whatever its progress read on the way (a
#: person model's trials end at the target; a person stopped on the Z's last leg at 92 % is 10 cm from it).
END_REACHED = 0.03
#: [N] a sample of the hand force out of line with both its neighbours, the same way, by more than this is a
#: sensor spike, not a hand: refused (one 300 N sample made the person's noise 3 mm for 0.7 and their dead zone
#: 9 mm). The thesis lab's recordings have at most 2 N, simulated trials 0.4 N.
WRENCH_SPIKE = 20.0
#: Trials whose periods differ by less than this share are of one control rate: a recording's period is measured
#: from its timestamps (the thesis lab's 125 Hz recordings: 7.963–8.007 ms, 0.6 % apart), another rate is 4 × away.
RATE_TOLERANCE = 0.02
#: A plan whose end is nearer its start than this share of its length is a loop: refused (the real recordings'
#: user-b followed one, 1.5 m long, ending where it started).
LOOP_GAP = 0.1


class CalibrationError(CoassistError, ValueError):
    """Trials a person model cannot be fitted from (the message names the person and the trial)."""


class NamedTrial(Protocol):
    """A trial and where it came from (``coassist.intent.LabeledTrial`` is one)."""

    @property
    def id(self) -> str: ...

    @property
    def trial(self) -> Trial: ...


@dataclass(frozen=True, eq=False)
class PersonCalibration:
    """One person's calibration: their fit, the task, the trials it was fitted from (ids), how many of
    them carried the probe, and the fit's wall-clock and CPU time [s]."""

    person: str
    task: str
    fit: PersonFit
    trials: tuple[str, ...]
    probe_trials: int
    seconds: float
    cpu_seconds: float
    #: trials in which the lab asked for a way round and the person went the other way (or round neither): their
    #: paths count as the person's own choice
    asked_other_way: int = 0
    #: why the arm is assumed though the probe measured one, or what was left out of its fit ("" where neither)
    arm_note: str = ""
    #: trials that do not record which controller ran (a bag, a ROS recording: controller "unknown"), so that a
    #: probe in them cannot be known
    unrecorded: int = 0


def _nominal(trial: Trial) -> np.ndarray:
    ref = np.asarray(trial.reference[:, :2], dtype=float)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(ref, axis=0), axis=1) > 1e-9])
    return ref[keep]


def _check_trial(person: str, tid: str, trial: Trial) -> None:
    """Refuse a trial that is no calibration trial of a planar task (one line naming it)."""
    d = trial.pose.shape[1]
    if d < 2 or trial.reference.shape[1] < 2:
        raise CalibrationError(
            f"{person}: trial {tid} has {d} DOF; a person model needs the planar x-y motion (2 or more DOF)"
        )
    nominal = _nominal(trial)
    if len(nominal) < 2:
        raise CalibrationError(f"{person}: trial {tid} has no nominal path (its reference never moves)")
    try:  # a value written by hand is refused naming this trial, before anything is fitted
        check_way(trial.meta.extra.get(ASKED_WAY, 0), f"{person}: trial {tid}: meta.extra[{ASKED_WAY!r}]")
    except ValueError as exc:
        raise CalibrationError(str(exc)) from None
    moved = float(np.max(np.linalg.norm(trial.pose[:, :2] - trial.pose[0, :2], axis=1)))
    frame = PathFrame(nominal)
    gap = float(np.linalg.norm(nominal[-1] - nominal[0]))
    if gap < LOOP_GAP * frame.length:
        # a path's offset from a loop is not defined along it (the nearest point may be on the way out or back)
        raise CalibrationError(
            f"{person}: trial {tid}: its plan ends {100 * gap:.1f} cm from where it starts ({frame.length:.2f} m "
            "long, a loop); a person model learns paths from a start to a target"
        )
    reached = _progress(frame, trial.pose[:, :2]) / frame.length
    if float(np.linalg.norm(trial.pose[-1, :2] - nominal[-1])) <= END_REACHED:
        # at the target: the task was followed to its end, whatever the detour (one round a large obstacle on the
        # Z's far side goes back along the first leg, where followed progress reads going back: 48 % of the plan)
        reached = 1.0
    if moved < 0.005 or reached < MIN_PROGRESS:
        raise CalibrationError(
            f"{person}: trial {tid}: the tool moved {1e3 * moved:.0f} mm and reached {100 * reached:.0f} % of the "
            f"plan ({frame.length:.2f} m); a calibration trial follows the task to its end"
        )
    limited = _limited(trial)
    if limited is not None:
        share, flags = limited
        raise CalibrationError(
            f"{person}: trial {tid}: the safety layer limited the tool's motion on {100 * share:.0f} % of its ticks "
            f"({flags}): the arm's answer to the probe is then the limit's, not the person's (a clipped response "
            "reads as another arm); record it again within the limits (a higher --tool-speed, a slower motion), or "
            "leave it out"
        )
    spike = _wrench_spike(trial.wrench[:, :2])
    if spike is not None:
        k, size = spike
        raise CalibrationError(
            f"{person}: trial {tid}: at sample {k} the hand force is {size:.0f} N out of line with the samples either "
            f"side of it (more than {WRENCH_SPIKE:.0f} N: a sensor spike, not a hand); it would widen the person's "
            "noise and bend their path: leave the trial out, or record it again"
        )


#: The faults of a tick whose commanded motion was not the controller's (the safety layer scaled, clipped or stopped it)
LIMITING = MOTION_LIMITED | Fault.SATURATED
#: The share of a calibration trial's ticks that may be limited (:data:`LIMITING`): a brief clip at a fast turn
#: moves the fit little; a trial held to a speed limit for long stretches measures the limit (review, 2026-12-06: a
#: MuJoCo probe trial speed-limited on half its ticks gave K̂ 453 N/m where the same trials unlimited gave 727)
MAX_LIMITED = 0.05


def _limited(trial: Trial) -> tuple[float, str] | None:
    """(share of ticks, the flags' names) where more than :data:`MAX_LIMITED` of ``trial``'s ticks were limited by the
    safety layer (its ``fault`` column; a trial without one, a recording's, was not), else None."""
    if trial.fault is None or len(trial.fault) == 0:
        return None
    hit = (np.asarray(trial.fault, dtype=np.int64) & int(LIMITING)) != 0
    share = float(np.mean(hit))
    if share <= MAX_LIMITED:
        return None
    seen = int(np.bitwise_or.reduce(np.asarray(trial.fault, dtype=np.int64)[hit]) & int(LIMITING))
    return share, ", ".join(f.name for f in Fault if f and f & LIMITING and seen & int(f) and f.name)


def _progress(frame: PathFrame, xy: np.ndarray) -> float:
    """[m] how far along the plan the tool got, followed sample by sample: each sample's nearest vertex of the plan
    within :data:`PROGRESS_STEP` of arc length of the last one's, plus as far as the tool moved since the last sample
    (and always the next and the one before; on a tie
    the later: a plan that doubles back on itself goes on along its return), so a tool out on a detour that passes
    near a later stretch of the plan (the Z's legs) is not counted there; the sample's place is its projection on the
    nearer of that vertex's two segments (a plan of a few waypoints is not read half a segment ahead). The first
    sample's nearest vertex over the whole plan."""
    arc, pts = frame.arc, frame.points
    n = len(arc)
    j = int(frame.nearest_vertex(xy[:1])[0])
    plist, alist = pts.tolist(), arc.tolist()
    best = 0.0
    px, py = xy[0].tolist()
    for x, y in xy.tolist():
        # the step, and as far as the tool moved since the last sample (a trial recorded at a few hertz)
        reach = PROGRESS_STEP + math.hypot(x - px, y - py)
        px, py = x, y
        lo = min(bisect.bisect_left(alist, alist[j] - reach), max(j - 1, 0))
        hi = max(bisect.bisect_right(alist, alist[j] + reach), min(j + 2, n))
        d2 = (pts[lo:hi, 0] - x) ** 2 + (pts[lo:hi, 1] - y) ** 2
        j = hi - 1 - int(np.argmin(d2[::-1]))  # the last of the nearest
        s, gap = alist[j], math.inf
        for a in (j - 1, j):  # the segments before and after vertex j
            if 0 <= a < n - 1:
                (ax, ay), (bx, by) = plist[a], plist[a + 1]
                ux, uy = bx - ax, by - ay
                t = min(max(((x - ax) * ux + (y - ay) * uy) / (ux * ux + uy * uy), 0.0), 1.0)
                g = (ax + t * ux - x) ** 2 + (ay + t * uy - y) ** 2
                if g < gap:
                    s, gap = alist[a] + t * (alist[a + 1] - alist[a]), g
        best = max(best, s)
    return best


def _wrench_spike(w: np.ndarray) -> tuple[int, float] | None:
    """(sample, N) of the largest sample of the hand force ``w`` (T, 2) out of line with both its neighbours the same
    way by more than :data:`WRENCH_SPIKE` on a channel, or None."""
    if len(w) < 3:
        return None
    up, down = w[1:-1] - w[:-2], w[1:-1] - w[2:]
    out = np.where(np.sign(up) == np.sign(down), np.minimum(np.abs(up), np.abs(down)), 0.0).max(axis=1)
    k = int(np.argmax(out))
    return (k + 1, float(out[k])) if out[k] > WRENCH_SPIKE else None


def _group(trials: Sequence[NamedTrial], task: str | None) -> dict[str, list[NamedTrial]]:
    groups: dict[str, list[NamedTrial]] = {}
    for item in trials:
        if task is not None and item.trial.meta.task != task:
            continue
        groups.setdefault(item.trial.meta.user, []).append(item)
    return groups


def _check_person(person: str, items: list[NamedTrial], min_trials: int) -> str:
    """The person's task, once their trials are checked to be of one task, rate and nominal path."""
    first = items[0]
    meta0 = first.trial.meta
    tasks = sorted({it.trial.meta.task for it in items})
    if len(tasks) > 1:
        odd = next(it for it in items if it.trial.meta.task != meta0.task)
        raise CalibrationError(
            f"{person}: trial {odd.id} is of task {odd.trial.meta.task!r}, trial {first.id} of {meta0.task!r} "
            f"(tasks {', '.join(tasks)} mixed in); calibrate one task per person (--task)"
        )
    for it in items[1:]:
        if abs(float(it.trial.meta.dt) - float(meta0.dt)) > RATE_TOLERANCE * float(meta0.dt):
            raise CalibrationError(
                f"{person}: trial {it.id} was recorded at {1 / it.trial.meta.dt:.0f} Hz, trial {first.id} at "
                f"{1 / meta0.dt:.0f} Hz; calibrate trials of one control rate"
            )
    if len(items) < min_trials:
        raise CalibrationError(
            f"{person}: {len(items)} trial(s) of task {meta0.task!r} ({', '.join(it.id for it in items)}); "
            f"a person model needs at least {min_trials}"
        )
    for it in items:
        _check_trial(person, it.id, it.trial)
    nominal = _nominal(first.trial)
    frame = PathFrame(nominal)
    for it in items[1:]:
        other = _nominal(it.trial)
        # the offsets from the path, and its ends (a plan moved along itself has no offset)
        start, end = float(np.linalg.norm(other[0] - nominal[0])), float(np.linalg.norm(other[-1] - nominal[-1]))
        # either way round: a plan that stops short lies on the other (whichever of the two came first), and is named
        # as that below, not as another path (the order of the trials given had decided which was said)
        apart = min(frame.distance_to(other), PathFrame(other).distance_to(nominal))
        if max(apart, start) > SAME_PATH:
            raise CalibrationError(
                f"{person}: trial {it.id} follows another nominal path than trial {first.id} "
                f"({100 * max(apart, start):.1f} cm apart; task {meta0.task!r}): on an arm, start every calibration "
                "trial from the same place"
            )
        if end > SAME_PATH:  # the same start and line: the plan of one of them stops short (a recording cut early)
            shorter = it.id if PathFrame(other).length < frame.length else first.id
            raise CalibrationError(
                f"{person}: the plans of trials {it.id} and {first.id} end {100 * end:.1f} cm apart (task "
                f"{meta0.task!r}): trial {shorter}'s stops short; was its recording stopped before the end of the task?"
            )
    _check_copies(person, items)
    return meta0.task


def _check_copies(person: str, items: list[NamedTrial]) -> None:
    """Refuse one recording given twice under two names (its arrays equal): it would count its way round twice."""
    seen: dict[bytes, str] = {}
    for it in items:
        t = it.trial
        digest = hashlib.sha256()
        for column in (t.time, t.pose, t.velocity, t.wrench):
            digest.update(np.ascontiguousarray(column, dtype=np.float64).data)
        key = digest.digest()
        if key in seen:
            raise CalibrationError(
                f"{person}: trials {seen[key]} and {it.id} hold the same recording (their time, pose, velocity and "
                "wrench are equal): give each trial once"
            )
        seen[key] = it.id


def calibrate_people(
    trials: Sequence[NamedTrial], *, task: str | None = None, min_trials: int = MIN_TRIALS
) -> list[PersonCalibration]:
    """Each person's :class:`PersonCalibration` from ``trials`` (module docstring), in the order people first
    appear. ``task``: fit only the trials of this task (``TrialMeta.task``); None: every person's trials must
    be of one task. Raises :class:`CalibrationError` (one line, naming the person and the trial)."""
    if isinstance(min_trials, bool) or not isinstance(min_trials, int) or min_trials < 1:
        raise ValueError(f"min_trials must be an int >= 1, got {min_trials!r}")
    if not trials:
        raise CalibrationError("no trials given")
    groups = _group(trials, task)
    if not groups:
        have = sorted({it.trial.meta.task for it in trials})
        raise CalibrationError(f"no trial of task {task!r} (the trials are of {', '.join(have)})")
    out = []
    for person, items in groups.items():
        kind = _check_person(person, items, min_trials)
        probed = [it.trial for it in items if it.trial.meta.controller == PROBE_CONTROLLER]
        rigid, left_out = probes_for_arm(probed)
        wall, cpu = time.perf_counter(), time.process_time()
        estimate = identify_arm(rigid)
        arm, note = measured_arm(estimate)
        if estimate.method == "assumed":  # nothing measured: summary_line says why from the trials
            note = ""
        if left_out:
            note = left_out if not rigid else f"{note}; {left_out}" if note else left_out
        try:
            fit = fit_person([it.trial for it in items], arm=arm)
        except ValueError as exc:
            raise CalibrationError(f"{person}: {exc}") from None
        # whether to lead this person along their paths: their calibration replayed against their twin
        origin = str(items[0].trial.meta.origin)
        fit = replace(fit, lead=lead_check([it.trial for it in items], fit, person_filter_for(origin)))
        out.append(
            PersonCalibration(
                person=person,
                task=kind,
                fit=fit,
                trials=tuple(it.id for it in items),
                probe_trials=len(probed),
                seconds=time.perf_counter() - wall,
                cpu_seconds=time.process_time() - cpu,
                asked_other_way=_asked_other_way(items, np.asarray(fit.paths.asked, dtype=bool)),
                arm_note=note,
                unrecorded=sum(it.trial.meta.controller == UNRECORDED_CONTROLLER for it in items),
            )
        )
    return out


def mount_twists(trial: Trial) -> bool:
    """Whether ``trial``'s object was held through a mount that twists in series with the arm (a yaw mode: the
    board), so that its probe measures the arm and the twist together (the same K = 700 N/m arm measured 449 ± 27 N/m
    on the board, 735 ± 56 on the handle). Not in a world that holds every object rigidly
    (:data:`~coassist.scenario.person_model.RIGID_HOLD_ORIGINS`: the MuJoCo UR5); an object the project does not know
    (a lab's own) is taken to be rigid."""
    if str(trial.meta.origin) in RIGID_HOLD_ORIGINS:
        return False
    try:
        return get_object(trial.meta.object).has_yaw
    except ValueError:
        return False


def probes_for_arm(trials: Sequence[Trial]) -> tuple[list[Trial], str]:
    """The probe trials among ``trials`` the person's arm is measured from (those whose mount does not twist:
    :func:`mount_twists`), and a note naming those left out ("": none), as ``coassist calibrate`` and a study's
    calibration block both decide it."""
    probed = [t for t in trials if t.meta.controller == PROBE_CONTROLLER]
    twisting = [t for t in probed if mount_twists(t)]
    rigid = [t for t in trials if not mount_twists(t)]
    if not twisting:
        return rigid, ""
    objects = ", ".join(sorted({t.meta.object for t in twisting}))
    return rigid, (
        f"{len(twisting)} probe trial(s) on the {objects} left out of the arm's fit (its mount twists in series with "
        "the arm: record the probe trials with the handle)"
    )


def _asked_other_way(items: Sequence[NamedTrial], asked: np.ndarray) -> int:
    """How many of ``items`` asked for a way round whose path the fit does not count as asked (it went the other
    way, or round neither)."""
    return int(sum(bool(it.trial.meta.extra.get(ASKED_WAY, 0)) and not a for it, a in zip(items, asked.tolist())))


def _ways(paths: PathModel, other_way: int = 0) -> str:
    sides = paths.sides
    counts = {s: int(np.sum(sides == s)) for s in (1, -1, 0)}
    parts = [f"{counts[1]} left", f"{counts[-1]} right"]
    if counts[0]:
        parts.append(f"{counts[0]} with no detour")
    asked = int(np.sum(np.asarray(paths.asked, dtype=bool)))
    notes = [f"{asked} asked for, not in the prior"] if asked else []
    if other_way:
        notes.append(f"{other_way} asked for a way but went the other: counted as chosen")
    return ", ".join(parts) + (f" ({'; '.join(notes)})" if notes else "")


def ways_to_ask(sides: np.ndarray, room: int) -> list[tuple[int, int]]:
    """The trials a calibration asks for next (:func:`thin_ways`' advice): for each way round shown in fewer than
    :data:`~coassist.scenario.path_model.FEW_PATHS` of the paths ``sides`` but at least once, (way, trials) to
    show it that often, left first, at most ``room`` trials in all (the lab's budget of trials left). A way never
    shown is not asked for: the person did not choose it, and the model mirrors the other way there."""
    room = check_int(room, "room", 0)
    out = []
    for name, n in few_paths(sides).items():
        ask = min(FEW_PATHS - n, room)
        if ask > 0:
            out.append((WAY_SIGNS[name], ask))
            room -= ask
    return out


def thin_ways(sides: np.ndarray, led: bool = True) -> str:
    """What to record more of: each way round shown in fewer than
    :data:`~coassist.scenario.path_model.FEW_PATHS` of the person's trials but at least once
    (:func:`~coassist.scenario.path_model.few_paths`), e.g. "the right way shown in 1 trial only: the model follows
    that path alone there; record more going right"; "" where every way shown was shown often enough. ``led``: False
    where the model does not lead the person along their paths (the twin check): it follows none, and says only what
    to record."""
    notes = []
    for name, n in few_paths(sides).items():
        paths = "that path" if n == 1 else f"those {n} paths"
        follows = f": the model follows {paths} alone there" if led else ""
        notes.append(
            f"the {name} way shown in {n} trial{'s' if n > 1 else ''} only{follows}; "
            f"record more going {name} (asked: --ask-way {name})"
        )
    return "; ".join(notes)


def summary_line(c: PersonCalibration) -> str:
    """One line of what was learnt of a person: the arm (measured by the probe, or assumed and why), the
    demonstrations per way round, the fit's time, a way shown too few times to follow (:func:`thin_ways`), and whether
    the model leads them along their paths (:class:`~coassist.scenario.person_model.LeadCheck`)."""
    arm = c.fit.arm
    if arm.method == "probe-iv":
        measured = (
            f"arm K̂ {arm.stiffness:.0f} ± {arm.stiffness_se:.0f} N/m, Ĉ {arm.damping:.1f} ± {arm.damping_se:.1f} "
            f"N·s/m, measured by the probe in {arm.trials} trial(s){' (' + c.arm_note + ')' if c.arm_note else ''}"
        )
    else:
        if c.arm_note:  # measured but not usable, or every probe trial left out of the fit
            why = c.arm_note
        elif c.probe_trials:
            why = (
                f"the probe was not measurable in its {c.probe_trials} manual-probe trial(s) (shorter than 3 s, or "
                "no push in the robot's effort)"
            )
        elif c.unrecorded:
            # drive's MCAP bags and ROS recordings keep no trial record: nothing says the probe ran (issue 40's review)
            why = (
                f"{'the trials do' if c.unrecorded == len(c.trials) else f'{c.unrecorded} of the trials do'} not "
                "record which controller ran (a bag or a ROS recording): calibrate the trial files coassist wrote "
                "beside the bags (drive's .parquet), or record with --controller manual-probe"
            )
        else:
            why = "the trials carry no probe (record them with --controller manual-probe)"
        unused = c.arm_note.startswith("measured")  # measured_arm's words for a measurement it does not use
        measured = (
            f"arm ASSUMED{'' if unused else ', not measured'} (K̂ {arm.stiffness:.0f} N/m, Ĉ {arm.damping:.1f} N·s/m): "
            f"{'the probe ' + why if unused else why}"
        )
    # a person not led along their paths is followed along none: their thin way is only what to record more of
    thin = thin_ways(c.fit.paths.sides, led=c.fit.lead is None or c.fit.lead.follow)
    lead = "" if c.fit.lead is None else f"; {c.fit.lead.line}"
    return (
        f"{c.person} ({c.task}, {len(c.trials)} trials): {measured}; demonstrations: {_ways(c.fit.paths, c.asked_other_way)}; "
        f"fit {c.seconds:.1f} s ({c.cpu_seconds:.1f} CPU-s){lead}{'; ' + thin if thin else ''}"
    )
