"""A person's twin: their calibration replayed in closed loop, to check that leading along their paths helps them.

The person model (:mod:`coassist.scenario.person_intent`) leads the tool along the paths a person showed in
their calibration trials. Where a person's path this time is not one they showed (their detours vary from trial to
trial more than the calibration's few trials tell), the lead carries the tool past the person's turn, and they
overshoot more than with no help (MG): docs/person-model.md, *A twin of the person*. Before a person model assists
a person, :func:`lead_check` replays each of their calibration trials, leave-one-out, against a twin of that
person, and says whether the lead pays:

- the twin's arm is the one measured (:class:`~coassist.scenario.arm_identification.ArmEstimate`), a spring and
  damper pulling toward the trial's own intent path as the fit reconstructs it::

      u_h(k) = K̂ (q(k) − p(k)) − Ĉ ṗ(k),   q = p + (w + Ĉ v)/K̂, low-passed (zero phase) as the fit does

  (:func:`~coassist.scenario.person_model.intent_paths`; q is the recorded trial's, on its own time course);
- the robot is the point-mass world's (the plant of the trial's control preset, its plan; the object
  :data:`TWIN_OBJECT`) with the arbitrated controller, run twice per trial: under MG, and with the person model of the person's *other* trials
  (:func:`~coassist.scenario.person_model.without_trial`: the fit less that trial's path, the measured arm);
- the twin's overshoot past q (:func:`coassist.metrics.overshoot`) is compared, trial by trial.

The person is followed (:attr:`~coassist.scenario.person_model.LeadCheck.follow`) unless the person model overshoots
more than MG beyond the trials' spread (the paired difference's 95 % Student-t interval above zero) or in more of the
trials than chance would give (the one-sided sign test at :data:`SIGN_LEVEL`: :func:`lead_verdict`); then the person
model gives that person what every world gives without a calibration (``present-held``: the present estimate held,
with the typical arm), and says so. Told: nothing but the calibration: the trials' poses,
velocities, wrenches, plan and preset, and the arm measured from them. The world's operator profile is a
placeholder whose intent and arm are replaced; nothing of the simulated operator's paths or arm reaches the twin.
A trial whose plan cannot be rebuilt from its task and seed (a plan of a lab's own) leaves the person followed, and
the check says why.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy.stats import binomtest

from coassist.analysis.paired import paired_difference
from coassist.control.presets import CONTROL_PRESETS, get_preset, make_controller
from coassist.metrics import overshoot
from coassist.runtime.episode import Episode
from coassist.scenario.objects import get_object
from coassist.scenario.operator import AUTHOR
from coassist.scenario.person_intent import PersonFilterSettings, PersonPathsIntent
from coassist.scenario.person_model import LeadCheck, PersonFit, asked_way, fit_person, intent_estimate, without_trial
from coassist.scenario.tasks import TASKS, task_for_seed
from coassist.sim.point_mass import PointMassWorld
from coassist.sim.trial_runner import build_trial, run_episodes_lockstep

__all__ = [
    "SIGN_LEVEL",
    "TWIN_CONTROLLER",
    "TWIN_HORIZON",
    "TWIN_OBJECT",
    "TwinArm",
    "TwinArmBatch",
    "checked_people",
    "lead_check",
    "lead_verdict",
    "on_ticks",
    "twin_overshoot",
    "why_no_twin",
]

#: The controller the twin is assisted with: the application's (the arbitrated cooperative game).
TWIN_CONTROLLER = "cooperative-arbitrated"
#: The horizon of the person model's rows in the twin's loop [ticks] (the controller's, 0.4 s at 125 Hz).
TWIN_HORIZON = 50
#: The object the twin carries: a rigid one of the application's mass (the heavy load). Chosen on seed 0's
#: calibrations of the thesis and the held-out populations (docs/person-model.md, *A twin of the person*: the
#: held-out ones were seen while choosing; their report cells now meet trials of their own): with the handle (no
#: mass) MG barely overshoots and the check turned away from the lead a thesis operator whom it helps in the report's
#: trials; with the board the twin's arm (no delay, an effective damping that may be negative) swings the board on
#: its twisting mount, and the check turned every thesis operator away.
TWIN_OBJECT = "heavy"
#: How far the twin's rebuilt plan may lie from the trial's recorded one [m] (in the task's frame) before the check
#: is left out: rounding room for a plan moved back from where an arm laid it out (a 500 Hz plan resampled onto the
#: 125 Hz ticks equals the 125 Hz plan exactly: the curved, Z and linear tasks, three seeds each, measured).
PLAN_TOLERANCE = 1e-6
#: The sign test's level: a person is turned away where the twin overshot more with the lead in so many of their
#: trials that a fair coin gives as many that seldom (one-sided; 7 or more of 8 trials, 5 of 5).
SIGN_LEVEL = 0.05


class TwinArm:
    """The twin's arm (module docstring): u_h = K̂ (q(k) − p) − Ĉ ṗ, per axis, no delay, no noise.

    Parameters
    ----------
    intent : (n, 2) the intent q on the tick grid [m]; ticks past its end hold its last row.
    stiffness : K̂ [N/m].
    damping : Ĉ [N·s/m] (may be negative: the effective damping of an arm with a delay).
    """

    def __init__(self, intent: np.ndarray, stiffness: float, damping: float) -> None:
        self._x, self._y = intent[:, 0].tolist(), intent[:, 1].tolist()
        self._n = len(self._x)
        self.K, self.C = float(stiffness), float(damping)

    def force(self, k: int, px: float, py: float, vx: float, vy: float) -> tuple[float, float]:
        """u_h(k) [N] for hand position (px, py) [m] and velocity (vx, vy) [m/s] at tick k."""
        i = k if k < self._n else self._n - 1
        return self.K * (self._x[i] - px) - self.C * vx, self.K * (self._y[i] - py) - self.C * vy

    @staticmethod
    def batch(arms: Sequence[TwinArm]) -> TwinArmBatch:
        """The array twin of ``arms`` for the point-mass array path (:class:`TwinArmBatch`)."""
        return TwinArmBatch(arms)


class TwinArmBatch:
    """:meth:`TwinArm.force` for B twins at once, row for row the same floats (the same operations in the same order,
    elementwise): what lets a person's twin trials run together on the point-mass array path
    (:mod:`coassist.sim.array_runner`).

    Parameters
    ----------
    arms : the B twins' arms (:class:`TwinArm`).
    """

    def __init__(self, arms: Sequence[TwinArm]) -> None:
        if not arms or not all(type(a) is TwinArm for a in arms):
            raise ValueError("TwinArmBatch takes one or more TwinArm objects")
        self.last = np.array([a._n - 1 for a in arms], dtype=np.intp)
        n = int(self.last.max()) + 1
        self.intent = np.zeros((len(arms), n, 2))
        for b, a in enumerate(arms):
            self.intent[b, : a._n] = np.column_stack([a._x, a._y])
        self.K = np.array([a.K for a in arms])[:, None]
        self.C = np.array([a.C for a in arms])[:, None]

    def force(self, k: int, rows: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        """u_h(k) [N], (len(rows), 2), of the twins ``rows`` (indices) for their hand points p and velocities v,
        (len(rows), 2) [m, m/s]: each row what its arm's :meth:`TwinArm.force` gives."""
        q = self.intent[rows, np.minimum(k, self.last[rows])]
        return self.K[rows] * (q - p) - self.C[rows] * v


def why_no_twin(trial) -> str:
    """Why ``trial`` cannot be replayed against a twin ("" where it can): the twin rebuilds the trial's plan from
    its task and seed and its robot from its control preset, as the trial recorded them."""
    meta = trial.meta
    if meta.task not in TASKS or meta.seed is None or int(meta.seed) < 0:
        return f"its task {meta.task!r} (seed {meta.seed}) is not one coassist rebuilds"
    if meta.extra.get("preset") not in CONTROL_PRESETS:
        return "it does not name a control preset coassist knows"
    return ""


def on_ticks(values: np.ndarray, dt: float, step: float) -> np.ndarray:
    """(T, 2) samples ``dt`` apart resampled ``step`` apart over the same span (linear; the same rows where equal)."""
    if dt == step:
        return values
    t = dt * np.arange(len(values))
    k = step * np.arange(int(t[-1] / step) + 1)
    return np.stack([np.interp(k, t, values[:, j]) for j in (0, 1)], axis=1)


def twin_overshoot(
    trial, intent: np.ndarray, arm, source: PersonPathsIntent | None, obj: str = TWIN_OBJECT
) -> float | None:
    """The twin's overshoot past ``intent`` [m] (module docstring) in ``trial``'s task and preset, assisted by the
    arbitrated controller with ``source`` (None: MG), carrying ``obj``; None where the trial cannot be replayed
    (:func:`why_no_twin`) or its plan is not its task's within :data:`PLAN_TOLERANCE` (nothing is run then). The
    trial and ``intent`` are in the task's frame (:func:`lead_check` moves a real arm's there); a trial recorded at
    another rate than its preset's (a 500 Hz arm) is resampled onto the preset's ticks."""
    built = _twin_run(trial, intent, arm, source, obj, {})
    return None if built is None else _overshoots([built])[0]


def _twin_run(trial, intent: np.ndarray, arm, source: PersonPathsIntent | None, obj: str, mg: dict):
    """:func:`twin_overshoot`'s closed loop built, not run: (how to build it again, its episode, the intent on its
    ticks), or None where it is not run. ``mg``: MG's controllers by preset name, filled here, shared by the runs under
    MG (it keeps no state: runs in lockstep sharing one step it once a tick for all, row for row its step)."""
    if why_no_twin(trial):
        return None
    meta = trial.meta
    motion = meta.extra.get("motion_time")
    task = task_for_seed(meta.task, int(meta.seed), motion_time=None if motion is None else float(motion))
    preset = get_preset(str(meta.extra["preset"]))
    step = float(preset.impedance.dt)  # the twin runs at the preset's own period (its controllers' dt)
    recorded = on_ticks(np.asarray(trial.reference[:, :2], dtype=float), float(meta.dt), step)
    intent = on_ticks(np.asarray(intent, dtype=float), float(meta.dt), step)

    def build() -> tuple[Episode, np.ndarray]:
        if source is not None:
            controller = make_controller(TWIN_CONTROLLER, preset)
        else:
            if preset.name not in mg:
                mg[preset.name] = make_controller("manual", preset)
            controller = mg[preset.name]
        episode = build_trial(
            task,
            replace(AUTHOR, name=str(meta.user)),  # a placeholder: its intent and arm are replaced below
            get_object(obj),
            controller,
            source,
            int(meta.seed),
            preset_name=preset.name,
        )
        world = episode.world
        if not isinstance(world, PointMassWorld):  # build_trial's world; a check that it is the one replaced here
            raise TypeError(f"the twin's world must be a PointMassWorld, got {type(world).__name__}")
        grid_n = max(len(world.intent.positions), len(intent))
        grid = np.vstack([intent, np.repeat(intent[-1:], grid_n - len(intent), axis=0)])
        # the world calls its arm's force() once a tick (its array twin, TwinArmBatch, on the array path)
        world.arm = TwinArm(grid, arm.stiffness, arm.damping)  # type: ignore[assignment]
        return episode, grid

    episode, grid = build()
    n = min(len(recorded), len(episode.plan))
    if n == 0 or float(np.max(np.abs(episode.plan[:n, :2] - recorded[:n]))) > PLAN_TOLERANCE:
        return None
    return build, episode, grid


def _overshoots(runs: Sequence) -> list[float]:
    """The overshoots of the built twin runs ``runs`` (:func:`_twin_run`'s), run together
    (:func:`~coassist.sim.trial_runner.run_episodes_lockstep`: the point-mass array path, a run that leaves it
    built again and run on the reference path; the same trials either way)."""
    poses: list = [None] * len(runs)

    def keep(i: int, trial) -> None:
        poses[i] = trial.pose

    run_episodes_lockstep([episode for _, episode, _ in runs], lambda i: runs[i][0]()[0], keep)
    return [overshoot(pose[:, :2], grid[: len(pose)]) for pose, (_, _, grid) in zip(poses, runs)]


def lead_check(trials: Sequence, fit: PersonFit, settings: PersonFilterSettings, obj: str = TWIN_OBJECT) -> LeadCheck:
    """Whether the person model should lead this person (module docstring): each of their chosen-way calibration
    trials (``trials``, one person's, those :func:`~coassist.scenario.person_model.fit_person` gave ``fit``) replayed
    against their twin, under MG and with the model of their other trials (``settings``: the filter it will run
    with). Trials the lab asked a way of stay in every fold's fit and are not replayed (the person did not choose
    them). Deterministic: the same trials give the same check."""
    trials = list(trials)
    chosen = [i for i, t in enumerate(trials) if asked_way(t) == 0]
    if len(chosen) < 2:
        return LeadCheck(follow=True, folds=0, note="not checked: fewer than two chosen-way trials")
    for i, trial in enumerate(trials):
        why = why_no_twin(trial)
        if why:
            return LeadCheck(follow=True, folds=0, note=f"not checked: trial {i + 1} cannot be replayed ({why})")
    # a real arm lays each trial's plan out from where its tool stood (drive): each trial moved back into its task's
    # frame, where the twin runs, and the paths fitted there (the arm, measured from motion and force, is the same)
    offsets = [_plan_offset(t) for t in trials]
    if any(np.any(o != 0.0) for o in offsets):
        trials = [_moved(t, -o) for t, o in zip(trials, offsets)]
        try:
            fit = replace(fit, paths=fit_person(trials, arm=fit.arm).paths)
        except ValueError as exc:
            return LeadCheck(follow=True, folds=0, note=f"not checked: the trials moved to their task's frame ({exc})")
    # each trial's reconstructed intent on its whole clock (before leaving the start and after the end as well)
    full = [intent_estimate(t, fit.arm)[1] for t in trials]
    user = str(trials[0].meta.user)
    runs = []  # each chosen trial's twin under MG, then with the model of the other trials
    shared_mg: dict = {}  # MG's controller per preset, one for every run under MG
    for i in chosen:
        fold = without_trial(fit, trials, i)  # the model of the other trials
        source = PersonPathsIntent(
            TWIN_HORIZON, paths={user: fold.paths}, arms={user: fit.arm}, settings=settings, model_id="twin"
        )
        try:
            pair = [_twin_run(trials[i], full[i], fit.arm, way, obj, shared_mg) for way in (None, source)]
        except ValueError as exc:  # a recording the twin cannot take: the calibration goes on, the person led
            return LeadCheck(follow=True, folds=0, note=f"not checked: trial {i + 1} could not be replayed ({exc})")
        if pair[0] is None or pair[1] is None:  # the same plan and its check, with the lead or without
            return LeadCheck(follow=True, folds=0, note=f"not checked: trial {i + 1}'s plan is not its task's")
        runs += pair
    # every twin trial of the check in one lockstep batch on the point-mass array path: what each gives alone
    try:
        over = _overshoots(runs)
    except ValueError as exc:  # a recording the twin cannot take: the calibration goes on, the person led
        return LeadCheck(follow=True, folds=0, note=f"not checked: its twin trials could not be run ({exc})")
    led, unled = [], []
    for mg, person in zip(over[0::2], over[1::2]):
        if not (math.isfinite(person) and math.isfinite(mg)):
            continue
        led.append(person)
        unled.append(mg)
    if len(led) < 2:
        return LeadCheck(follow=True, folds=len(led), note="not checked: fewer than two trials could be replayed")
    return lead_verdict(1000.0 * np.asarray(led), 1000.0 * np.asarray(unled))


def lead_verdict(led_mm: np.ndarray, mg_mm: np.ndarray) -> LeadCheck:
    """The check's verdict from the twin's overshoots [mm], (n,) each, paired trial by trial: with the lead
    (``led_mm``) and under MG (``mg_mm``). The person is turned away only where the lead costs overshoot beyond chance
    (a person whose lead is about as good as MG is led: it saves them force): the paired difference's 95 % Student-t
    interval above zero, or the lead worse in so many trials that a fair coin gives as many less often than
    :data:`SIGN_LEVEL` (the one-sided sign test, ties left out: a trial the person went their rare way round, where
    MG overshoots several times as much, widens the interval of anyone)."""
    led_mm, mg_mm = np.asarray(led_mm, dtype=float), np.asarray(mg_mm, dtype=float)
    if led_mm.shape != mg_mm.shape or led_mm.ndim != 1 or len(led_mm) < 2:
        raise ValueError(f"lead_verdict needs two paired (n,) arrays, n >= 2; got {led_mm.shape} and {mg_mm.shape}")
    _, low, _, _ = paired_difference(led_mm, mg_mm)
    worse, better = int(np.sum(led_mm > mg_mm)), int(np.sum(led_mm < mg_mm))
    by_chance = binomtest(worse, worse + better, 0.5, alternative="greater").pvalue if worse else 1.0
    return LeadCheck(
        follow=not (low > 0.0 or by_chance < SIGN_LEVEL),
        folds=len(led_mm),
        person_mm=float(np.mean(led_mm)),
        mg_mm=float(np.mean(mg_mm)),
        low_mm=float(low),
        note="checked",
        worse=worse,
    )


def _plan_offset(trial) -> np.ndarray:
    """(2,) how far ``trial``'s recorded plan starts from its task's start [m] (zero in a simulated world)."""
    meta = trial.meta
    motion = meta.extra.get("motion_time")
    task = task_for_seed(meta.task, int(meta.seed), motion_time=None if motion is None else float(motion))
    return np.asarray(trial.reference[0, :2], dtype=float) - np.asarray(task.start, dtype=float)[:2]


def _moved(trial, by: np.ndarray):
    """``trial`` with its positions (tool pose and plan) moved by ``by`` (2,) [m]."""
    pose, reference = np.array(trial.pose, dtype=float), np.array(trial.reference, dtype=float)
    pose[:, :2] += by
    reference[:, :2] += by
    return replace(trial, pose=pose, reference=reference)


def checked_people(
    trials: Sequence, fits: Mapping[str, PersonFit], settings: PersonFilterSettings, obj: str = TWIN_OBJECT
) -> dict[str, PersonFit]:
    """``fits`` (by person, as :func:`~coassist.scenario.person_model.fit_people` gives them) each with its
    :func:`lead_check` from that person's trials among ``trials`` (grouped by ``meta.user``)."""
    by_user: dict[str, list] = {}
    for trial in trials:
        by_user.setdefault(str(trial.meta.user), []).append(trial)
    return {
        name: replace(fit, lead=lead_check(by_user.get(name, []), fit, settings, obj)) for name, fit in fits.items()
    }
