"""The control loop: a world, an operator inside it, and the tick, for one run.

Per period k (dm_control's Environment.step, with the tick in the middle)::

    state = world.read()                      sense (the world owns time and physics)
    out   = tick.step(k, state, upstream)     decide (pure orchestration of the stages)
    world.apply(out.command)                  act, and advance one period
    log row k, then ask the termination rule whether the run is over

``upstream`` carries what the loop itself measured: DEADLINE_MISS when the previous
tick's own work (read → command, not the world's physics or its wait) took longer than ``deadline`` seconds, or when a
real-time world reports that its period overran (``world.last_overrun > 0``). The flag
lands on the next tick because the late command has already been sent; the safety
layer then decelerates (and stops after too many in a row).

A glitch of the robot state (a NaN, ±inf or ``None`` pose, twist or joint vector) is
flagged NONFINITE_STATE by the tick, which holds the last good value (the safety layer
decelerates); the log holds the last good row too, so the run's file stays finite and its
fault column says which ticks were bad.

The run ends when the termination rule says so (e.g. the tool has dwelt at the
target), at ``n_max`` ticks, or when the safety layer has stopped the robot (the loop
then lets the world brake, logs ``ended = "safety_stop"`` and returns; a robot
protective or emergency stop ends it the same way, with ``ended = "robot_stop"``; a
lost link to the robot (a ``ConnectionError`` from the world) with ``"link_lost"``).
Any other exception from the world's ``read`` or ``apply`` (a sensor driver's read
timeout, an ``OSError`` of its socket) ends the run the same controlled way, with
``"world_error"``; one from the tick or the ``on_tick`` monitor with ``"internal_error"``:
the loop calls ``world.stop()``, keeps every row logged so far and says in ``message``
what raised where, so the run's record is written and no traceback reaches the user.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from coassist._rows import RowConstants
from coassist.errors import CoassistError
from coassist.interfaces import Fault
from coassist.runtime.tick import ControlTick
from coassist.runtime.world import RobotState, World, finite_vector, optional_member

__all__ = [
    "LINK_LOST",
    "InterruptsHeld",
    "LoopLog",
    "LoopRun",
    "RunInterrupted",
    "TargetDwell",
    "TargetDwellBatch",
    "alpha_reader",
    "run_loop",
]

Termination = Callable[[int, np.ndarray], bool]


class TargetDwell:
    """Ends a run once the motion is over and the tool has stayed near the target.

    target : (2,) [m]; radius : [m]; dwell_ticks : ticks inside the ball in a row;
    after_tick : the first tick at which the rule may end the run (the planner's and
    the operator's motion are over).
    """

    def __init__(self, target: np.ndarray, radius: float, dwell_ticks: int, after_tick: int) -> None:
        self.tx, self.ty = float(target[0]), float(target[1])
        self.r2 = float(radius) ** 2
        self.dwell_ticks = int(dwell_ticks)
        self.after_tick = int(after_tick)
        self.inside = 0

    def __call__(self, k: int, pose: np.ndarray) -> bool:
        if k < self.after_tick:
            return False
        dx, dy = float(pose[0]) - self.tx, float(pose[1]) - self.ty
        if dx * dx + dy * dy < self.r2:
            self.inside += 1
            return self.inside >= self.dwell_ticks
        self.inside = 0
        return False


class TargetDwellBatch:
    """:class:`TargetDwell` for B runs at once, row for row the same decisions: its array twin.

    Parameters
    ----------
    rules : per run a :class:`TargetDwell` that has not counted a tick inside yet, or None
        (no rule: the run goes on to its time limit). :meth:`accepts` says which can join.
    """

    @staticmethod
    def accepts(rule: object) -> bool:
        """Whether ``rule`` can join a batch: None, or a :class:`TargetDwell` with no tick inside counted."""
        return rule is None or (type(rule) is TargetDwell and rule.inside == 0)

    def __init__(self, rules: Sequence[TargetDwell | None]) -> None:
        for i, rule in enumerate(rules):
            if not self.accepts(rule):
                raise ValueError(f"rules[{i}] cannot join a TargetDwellBatch (TargetDwellBatch.accepts is False)")
        self._has_rule = np.array([r is not None for r in rules], dtype=bool)
        self._target = np.array([(r.tx, r.ty) if r is not None else (0.0, 0.0) for r in rules], dtype=float).reshape(
            -1, 2
        )
        self._r2 = np.array([r.r2 if r is not None else 0.0 for r in rules], dtype=float)
        self._dwell_ticks = np.array([r.dwell_ticks if r is not None else 0 for r in rules], dtype=np.intp)
        self._after_tick = np.array([r.after_tick if r is not None else 0 for r in rules], dtype=np.intp)
        #: (B,) ticks inside the ball in a row so far, as each rule's ``inside``.
        self.inside = np.zeros(len(rules), dtype=np.intp)
        # the rules' constants, gathered once per set of rows
        self._constants = RowConstants((self._has_rule, self._after_tick, self._target, self._r2, self._dwell_ticks))

    def __call__(self, k: int, rows: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """Tick k of the runs ``rows`` (indices) at their poses (len(rows), ≥ 2) [m]: (len(rows),) bool,
        each what its rule's ``rule(k, pose)`` says (False without a rule)."""
        has_rule, after_tick, target, r2, dwell_ticks = self._constants.take(rows)
        counted = has_rule & (k >= after_tick)
        d = pose[:, :2] - target
        inside = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) < r2
        before = self.inside[rows]
        count = np.where(counted, np.where(inside, before + 1, 0), before)
        self.inside[rows] = count
        return counted & inside & (count >= dwell_ticks)


@dataclass
class LoopLog:
    """The run's rows (n ticks, d DOFs, H horizon, J joints); see :class:`~coassist.runtime.tick.TickOutput`.

    pose, velocity, wrench, reference, effort_h, effort_r : (n, d). prediction : (n, H, 2)
    or None (nominal source). fault : (n,) int64. joints, joint_velocity : (n, J) measured
    q [rad] and the commanded q̇ [rad/s], or None for worlds without joints.
    compute : (n,) seconds of the tick's own work. ended : why the run ended.
    alpha : (n,) the game's α each tick's command was computed with (the arbitration's online
    one; :func:`alpha_reader`), or None (a controller without one: IMP, MG).
    """

    pose: np.ndarray
    velocity: np.ndarray
    wrench: np.ndarray
    reference: np.ndarray
    prediction: np.ndarray | None
    effort_h: np.ndarray
    effort_r: np.ndarray
    fault: np.ndarray
    joints: np.ndarray | None
    joint_velocity: np.ndarray | None
    compute: np.ndarray
    ended: str
    message: str = ""
    alpha: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.fault.shape[0])

    def prediction_or_plan(self, plan_xy: np.ndarray, horizon: int) -> np.ndarray:
        """(n, H, 2): the logged prediction, or where the source was the nominal plan (eq. 4.7)
        the plan's next H rows at every tick, ``plan_xy[k+1 … k+H]`` (plan_xy (≥ n+H, 2) [m])."""
        if self.prediction is not None:
            return self.prediction
        n, H = self.n, int(horizon)
        windows = np.lib.stride_tricks.sliding_window_view(np.asarray(plan_xy)[1 : n + H, :2], H, axis=0)  # (n, 2, H)
        return np.ascontiguousarray(windows.transpose(0, 2, 1))


def run_loop(
    world: World,
    tick: ControlTick,
    n_max: int,
    termination: Termination | None = None,
    *,
    deadline: float | None = None,
    on_tick: Callable[[int, RobotState, object], None] | None = None,
    clock: Callable[[], float] = time.perf_counter,
) -> LoopLog:
    """Run ``tick`` against ``world`` for at most ``n_max`` periods (module docstring).

    The tick must have been :meth:`~ControlTick.reset` for this run. ``deadline`` [s]:
    the budget of one tick's work (None: not checked; simulated worlds have no wall
    clock). ``on_tick(k, state, out)`` is called after each command (a monitor; it must
    not block). Returns the :class:`LoopLog`; the world is left at rest but not closed.
    """
    run = LoopRun(world, tick, n_max, termination, deadline=deadline, on_tick=on_tick, clock=clock)
    k = 0
    try:
        for k in range(n_max):
            row = run.sense(k)
            if row is LINK_LOST:
                break
            if run.act(k, None if row is None else run.predict(k, row)):
                break
    except KeyboardInterrupt:
        # Ctrl-C: the world stopped as on any failure, the ticks finished before it kept (tick k was cut off
        # wherever it was), and the interrupt goes on to the caller with them
        run.interrupt(k)
        raise RunInterrupted(run.log()) from None
    return run.log()


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run (:func:`run_loop`): the world was stopped; ``log`` holds the ticks finished before it
    (``ended = "interrupted"``) and ``trial``, where the caller made one of them (``coassist drive`` writes it), that
    trial. A KeyboardInterrupt still: whoever does not look for it stops as before."""

    def __init__(self, log: LoopLog, *, after_end: bool = False) -> None:
        super().__init__(f"interrupted after {log.n} ticks" + (", the run over" if after_end else ""))
        self.log = log
        self.trial: Any = None
        #: Ctrl-C came once the run was over (its arm stopped, the trial being made): the trial is whole
        self.after_end = after_end


class InterruptsHeld:
    """Ctrl-C held, not raised, while a run that is over is stopped, made a trial and written (``with
    InterruptsHeld() as held: …``; ``held.pending`` then says whether one came): a KeyboardInterrupt there lost the
    whole trial, the loop's own catch being behind it. In the main thread only (where Python delivers signals);
    elsewhere it holds nothing and ``pending`` stays False."""

    def __init__(self) -> None:
        self.pending = False
        self._old: Any = None

    def _note(self, signum: int, frame: Any) -> None:
        self.pending = True

    def __enter__(self) -> InterruptsHeld:
        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._note)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
            self._old = None


#: The intent stage's answer where the stage itself raised: no prediction (the plan's rows), flagged as a failing
#: predictor's is (:class:`~coassist.runtime.intent.WindowIntent`), and the loop goes on.
INTENT_FAILED = (None, Fault.PREDICTION_FALLBACK)


#: What :meth:`LoopRun.sense` returns when the link to the robot dropped (the run is over).
LINK_LOST = object()


class LoopRun:
    """One run of the loop, a tick at a time: :func:`run_loop`'s state and body.

    ``split``: the runner does other runs' work between :meth:`sense` and :meth:`act`, so
    each part is timed alone (two more clock reads a tick) and :meth:`charge` adds the
    rest; otherwise a tick costs two clock reads, before the read and after the decision.

    Tick k is ``row = sense(k)`` (read the world, the tick's first stage; the intent's
    feature row, None for the nominal intent, or :data:`LINK_LOST`), then
    ``over = act(k, intent)`` with ``intent = tick.predict(k, row)`` (or an answer
    computed elsewhere for that row, e.g. in one network call for many runs:
    :mod:`coassist.runtime.batched_loops`), which commands the world, logs row k and says
    whether the run has ended. :meth:`log` gives the :class:`LoopLog`.
    """

    def __init__(
        self,
        world: World,
        tick: ControlTick,
        n_max: int,
        termination: Termination | None = None,
        *,
        deadline: float | None = None,
        on_tick: Callable[[int, RobotState, object], None] | None = None,
        clock: Callable[[], float] = time.perf_counter,
        split: bool = False,
    ) -> None:
        self.split = bool(split)
        self.world, self.tick, self.n_max, self.termination = world, tick, int(n_max), termination
        self.deadline, self.on_tick, self.clock = deadline, on_tick, clock
        d, Hs, n_max = tick.d, tick.Hs, self.n_max
        self.nj = nj = int(world.n_joints)
        self.pose = np.empty((n_max, d))
        self.vel = np.empty((n_max, d))
        self.wrench = np.empty((n_max, d))
        self.ref = np.empty((n_max, d))
        self.pred = None if tick.intent.nominal else np.full((n_max, Hs, 2), np.nan)
        self.eff_h = np.empty((n_max, d))
        self.eff_r = np.empty((n_max, d))
        self.fault = np.zeros(n_max, dtype=np.int64)
        self.joints = np.empty((n_max, nj)) if nj else None
        self.jvel = np.empty((n_max, nj)) if nj else None
        self.compute = np.zeros(n_max)
        self.hand_of = _hand_reader(world)
        self.alpha_of = alpha_reader(tick.controller)
        self.alpha = None if self.alpha_of is None else np.zeros(n_max)
        self.overrun_of = optional_member(world, "last_overrun") is not None
        self.upstream = Fault.NONE
        self.ended, self.message, self.n = "time_limit", "", n_max
        self.held_q = np.zeros(nj)  # the joints logged for a glitch at tick 0 (nothing good seen yet)
        self._state: RobotState | None = None
        self._t0 = self._spent = 0.0

    def _overran(self) -> bool:
        """Whether the world reports its period overran (``last_overrun`` > 0). A value that is not a number, or NaN,
        counts as late (it raised out of the loop, with the arm moving, or was taken as on time: a review,
        2026-12-07)."""
        value = optional_member(self.world, "last_overrun")
        try:
            late = float(value or 0.0)
        except (TypeError, ValueError):
            return True
        return not late <= 0.0

    def sense(self, k: int) -> Any:  # the feature row, None, or LINK_LOST
        """Read the world and begin tick k (class docstring)."""
        try:
            self._t0 = self.clock()
            self._state = self.world.read()
        except Exception as exc:  # noqa: BLE001 - a lost link, a driver's error: a controlled stop
            self._world_failed(k, exc, "read")
            return LINK_LOST
        upstream = self.upstream
        if self.overrun_of and self._overran():
            # a world that measures the gap at read (the robot's own clock): this tick is late too
            upstream |= Fault.DEADLINE_MISS
        try:
            row = self.tick.sense(k, self._state, upstream)
        except Exception as exc:  # noqa: BLE001 - a bug of a stage: stop, keep what was logged
            self._failed(
                k, "internal_error", f"the control tick failed at tick {k} ({_what(exc)}); the arm was stopped"
            )
            return LINK_LOST
        if self.split:  # other runs' work follows: time this part alone
            self._spent = self.clock() - self._t0
        return row

    def predict(self, k: int, row: Any) -> tuple[np.ndarray | None, Fault]:
        """The intent stage's answer for tick k's feature ``row`` (``tick.predict``); a stage that raises (a
        predictor's answer of the wrong type, a bug) gives :data:`INTENT_FAILED`: the plan's rows, flagged, and the
        tick goes on to the controller and the safety layer as with any failing predictor."""
        try:
            return self.tick.predict(k, row)
        except Exception:  # noqa: BLE001 - a failing intent stage must not stop the loop
            return INTENT_FAILED

    def accept(self, prediction: Any) -> tuple[np.ndarray | None, Fault]:
        """The intent stage's answer for a ``prediction`` made elsewhere (one batched call for many runs:
        ``tick.intent.accept``); a stage that raises gives :data:`INTENT_FAILED`, as :meth:`predict`."""
        try:
            return self.tick.intent.accept(prediction)
        except Exception:  # noqa: BLE001 - as predict
            return INTENT_FAILED

    def act(self, k: int, intent: Any, control: Any = None) -> bool:
        """Finish tick k with the intent's answer, command the world, log; True when the run is over.

        ``control``: the controller's step for this tick computed elsewhere (``split`` runs:
        :meth:`ControlTick.control_inputs <coassist.runtime.tick.ControlTick.control_inputs>`
        was called with ``intent`` and the runner stepped the controller, e.g. in one call for
        many runs); None: the tick steps it itself.
        """
        world, state = self.world, self._state
        if state is None:
            raise RuntimeError(f"LoopRun.act({k}) before sense({k})")
        try:
            t1 = self.clock() if self.split else self._t0
            out = self.tick.decide(intent) if control is None else self.tick.finish(control)
        except Exception as exc:  # noqa: BLE001 - a bug of a stage: stop, keep what was logged
            self._failed(
                k, "internal_error", f"the control tick failed at tick {k} ({_what(exc)}); the arm was stopped"
            )
            return True
        # read → command (the intent included); apply() simulates or waits for the period
        spent = self.clock() - t1 + (self._spent if self.split else 0.0)
        try:
            world.apply(out.command)
        except Exception as exc:  # noqa: BLE001 - the link dropped, or the driver failed: nothing more is sent
            self._world_failed(k, exc, "apply")
            return True
        self.compute[k] = spent
        upstream = Fault.NONE
        if self.deadline is not None and spent > self.deadline:
            upstream |= Fault.DEADLINE_MISS
        if self.overrun_of and self._overran():
            upstream |= Fault.DEADLINE_MISS
        self.upstream = upstream
        d = self.tick.d
        self.pose[k] = out.pose
        self.vel[k] = out.velocity
        self.wrench[k] = out.wrench
        self.ref[k] = out.reference
        if self.pred is not None and out.prediction is not None:
            self.pred[k, : out.prediction.shape[0]] = out.prediction
        self.eff_r[k] = out.u_r if out.command.effort is None else out.command.effort
        try:
            self.eff_h[k] = self.hand_of()[:d] if self.hand_of is not None else out.wrench
        except Exception as exc:  # noqa: BLE001 - a simulated world's hand that fails: stop, keep what was logged
            self._failed(
                k, "internal_error", f"the world's hand_force failed at tick {k} ({_what(exc)}); the arm was stopped"
            )
            return True
        self.fault[k] = int(out.fault)
        if self.alpha is not None and self.alpha_of is not None:
            alpha = self.alpha_of()
            if isinstance(alpha, (int, float)) and 0.0 <= alpha <= 1.0:  # a game's α is; no row is lost over one not
                self.alpha[k] = alpha
            else:
                self.alpha[k] = self.alpha[k - 1] if k else 0.0
        nj = self.nj
        if nj:
            self.jvel[k] = out.command.qd if out.command.qd is not None else 0.0
            q = finite_vector(state.q, nj)
            if q is not None:
                self.joints[k] = q
            else:  # a glitch: the tick flagged it (NONFINITE_STATE); the log holds the last good row
                self.joints[k] = self.joints[k - 1] if k else self.held_q
        if self.on_tick is not None:
            try:
                self.on_tick(k, state, out)
            except Exception as exc:  # noqa: BLE001 - a monitor's failure stops the run, not the process
                self._failed(
                    k + 1,
                    "internal_error",
                    f"the monitor (on_tick) failed at tick {k} ({_what(exc)}); the arm was stopped",
                )
                return True
        if out.command.stop:
            self.n = k + 1
            robot = out.fault & (Fault.ROBOT_PROTECTIVE_STOP | Fault.ROBOT_EMERGENCY_STOP)
            self.ended = "robot_stop" if robot else "safety_stop"
            self.message = _stop_message(Fault(out.fault))
            world.stop()
            return True
        if self.termination is not None and self.termination(k, self.pose[k]):
            self.n = k + 1
            self.ended = "target"
            return True
        return False

    def charge(self, seconds: float) -> None:
        """Charge the current tick with work done for it elsewhere (a share of a batched network
        call); ``split`` runs only, between :meth:`sense` and :meth:`act`."""
        self._spent += seconds

    def interrupt(self, k: int) -> None:
        """Ctrl-C during tick k: end the run with rows 0 … k−1 and stop the world."""
        self._failed(min(k, self.n), "interrupted", f"stopped by Ctrl-C at tick {k}; the arm was stopped")

    def _world_failed(self, k: int, exc: Exception, where: str) -> None:
        """The world's ``read`` or ``apply`` of tick k raised: end the run with rows 0 … k−1."""
        if isinstance(exc, ConnectionError):  # the robot link dropped
            self._failed(
                k, "link_lost", f"the link to the robot was lost ({exc}); check the cable and the robot, then rerun"
            )
        elif isinstance(exc, CoassistError):  # coassist's own words (a refused input): they say what to do
            self._failed(k, "world_error", f"{exc} (at tick {k}; the arm was stopped)")
        else:
            self._failed(
                k,
                "world_error",
                f"the robot's {where}() failed at tick {k} ({_what(exc)}); the arm was "
                "stopped: check the robot, its sensor and their drivers, then rerun",
            )

    def _failed(self, n: int, ended: str, message: str) -> None:
        """End the run after ``n`` logged rows: stop the world (whatever it says), keep the rows."""
        self.n, self.ended, self.message = n, ended, message
        try:
            self.world.stop()
        except Exception:  # noqa: BLE001 - a dead link: the robot's own watchdog brakes it
            pass

    def log(self) -> LoopLog:
        """The rows logged so far (all of them once the run is over)."""
        n, pred, joints, jvel = self.n, self.pred, self.joints, self.jvel
        return LoopLog(
            pose=self.pose[:n],
            velocity=self.vel[:n],
            wrench=self.wrench[:n],
            reference=self.ref[:n],
            prediction=None if pred is None else pred[:n],
            effort_h=self.eff_h[:n],
            effort_r=self.eff_r[:n],
            fault=self.fault[:n],
            joints=None if joints is None else joints[:n],
            joint_velocity=None if jvel is None else jvel[:n],
            compute=self.compute[:n],
            ended=self.ended,
            message=self.message,
            alpha=None if self.alpha is None else self.alpha[:n],
        )


def alpha_reader(controller: Any) -> Callable[[], float | None] | None:
    """A reader of the controller's α now (the cooperative game's, an arbitration's online one),
    or None for a controller without one (IMP, MG): what the log's ``alpha`` column, a live view and
    the ROS 2 monitor show."""
    if getattr(controller, "alpha", None) is None:
        return None
    return lambda: getattr(controller, "alpha", None)


def _hand_reader(world: World) -> Callable[[], object] | None:
    """What the hand applied in the last period, where the world knows it (simulation).

    A real robot does not: there the log's effort_h is the measured hand wrench."""
    fn = optional_member(world, "hand_force")
    if callable(fn):
        return fn
    if optional_member(type(world), "hand_wrench") is not None:
        return lambda: world.hand_wrench
    return None


def _what(exc: BaseException) -> str:
    """``Type: text`` of an exception, on one line."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _stop_message(f: Fault) -> str:
    if f & Fault.ROBOT_EMERGENCY_STOP:
        return "the robot reports an emergency stop: release the e-stop, check the cell, power the arm on, then rerun"
    if f & Fault.ROBOT_PROTECTIVE_STOP:
        return (
            "the robot reports a protective stop (its force limit or a collision): clear it on the teach pendant, "
            "check the workspace, then rerun"
        )
    if f & Fault.CONTACT_FORCE_LIMIT:
        return "the hand force exceeded the contact threshold: protective stop by coassist's safety layer"
    reasons = [flag.name for flag in Fault if flag and flag & f and flag.name]
    return "the safety layer stopped the robot after repeated bad ticks (" + ", ".join(reasons) + ")"
