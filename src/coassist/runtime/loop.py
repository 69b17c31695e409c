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
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from coassist.interfaces import Fault
from coassist.runtime.tick import ControlTick
from coassist.runtime.world import RobotState, World, finite_vector

__all__ = ["LoopLog", "TargetDwell", "run_loop"]

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


@dataclass
class LoopLog:
    """The run's rows (n ticks, d DOFs, H horizon, J joints); see :class:`~coassist.runtime.tick.TickOutput`.

    pose, velocity, wrench, reference, effort_h, effort_r : (n, d). prediction : (n, H, 2)
    or None (nominal source). fault : (n,) int64. joints, joint_velocity : (n, J) measured
    q [rad] and the commanded q̇ [rad/s], or None for worlds without joints.
    compute : (n,) seconds of the tick's own work. ended : why the run ended.
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
    d, Hs = tick.d, tick.Hs
    nj = int(world.n_joints)
    pose = np.empty((n_max, d))
    vel = np.empty((n_max, d))
    wrench = np.empty((n_max, d))
    ref = np.empty((n_max, d))
    pred = None if tick.intent.nominal else np.full((n_max, Hs, 2), np.nan)
    eff_h = np.empty((n_max, d))
    eff_r = np.empty((n_max, d))
    fault = np.zeros(n_max, dtype=np.int64)
    joints = np.empty((n_max, nj)) if nj else None
    jvel = np.empty((n_max, nj)) if nj else None
    compute = np.empty(n_max)
    hand_of = _hand_reader(world)
    overrun_of = getattr(world, "last_overrun", None) is not None
    upstream = Fault.NONE
    ended, message, n = "time_limit", "", n_max
    held_q = np.zeros(nj)  # the joints logged for a glitch at tick 0 (nothing good seen yet)
    for k in range(n_max):
        try:
            t0 = clock()
            state = world.read()
            out = tick.step(k, state, upstream)
            spent = clock() - t0  # sense + decide; apply() simulates or waits for the period
            world.apply(out.command)
        except ConnectionError as exc:  # the robot link dropped: nothing more can be sent
            n, ended, message = k, "link_lost", f"the link to the robot was lost ({exc}); check the cable and the robot, then rerun"
            try:
                world.stop()
            except Exception:
                pass
            break
        compute[k] = spent
        upstream = Fault.NONE
        if deadline is not None and spent > deadline:
            upstream |= Fault.DEADLINE_MISS
        if overrun_of and float(getattr(world, "last_overrun", 0.0) or 0.0) > 0.0:
            upstream |= Fault.DEADLINE_MISS
        pose[k] = out.pose
        vel[k] = out.velocity
        wrench[k] = out.wrench
        ref[k] = out.reference
        if pred is not None and out.prediction is not None:
            pred[k, : out.prediction.shape[0]] = out.prediction
        eff_r[k] = out.u_r if out.command.effort is None else out.command.effort
        eff_h[k] = hand_of()[:d] if hand_of is not None else out.wrench
        fault[k] = int(out.fault)
        if nj:
            jvel[k] = out.command.qd if out.command.qd is not None else 0.0
            q = finite_vector(state.q, nj)
            if q is not None:
                joints[k] = q
            else:  # a glitch: the tick flagged it (NONFINITE_STATE); the log holds the last good row
                joints[k] = joints[k - 1] if k else held_q
        if on_tick is not None:
            on_tick(k, state, out)
        if out.command.stop:
            n = k + 1
            robot = out.fault & (Fault.ROBOT_PROTECTIVE_STOP | Fault.ROBOT_EMERGENCY_STOP)
            ended = "robot_stop" if robot else "safety_stop"
            message = _stop_message(Fault(out.fault))
            world.stop()
            break
        if termination is not None and termination(k, pose[k]):
            n = k + 1
            ended = "target"
            break
    return LoopLog(
        pose=pose[:n], velocity=vel[:n], wrench=wrench[:n], reference=ref[:n],
        prediction=None if pred is None else pred[:n], effort_h=eff_h[:n], effort_r=eff_r[:n],
        fault=fault[:n], joints=None if joints is None else joints[:n],
        joint_velocity=None if jvel is None else jvel[:n], compute=compute[:n], ended=ended, message=message,
    )


def _hand_reader(world: World) -> Callable[[], object] | None:
    """What the hand applied in the last period, where the world knows it (simulation).

    A real robot does not: there the log's effort_h is the measured hand wrench."""
    fn = getattr(world, "hand_force", None)
    if callable(fn):
        return fn
    if hasattr(type(world), "hand_wrench"):
        return lambda: world.hand_wrench
    return None


def _stop_message(f: Fault) -> str:
    if f & Fault.ROBOT_EMERGENCY_STOP:
        return "the robot reports an emergency stop: release the e-stop, check the cell, power the arm on, then rerun"
    if f & Fault.ROBOT_PROTECTIVE_STOP:
        return ("the robot reports a protective stop (its force limit or a collision): clear it on the teach pendant, "
                "check the workspace, then rerun")  # fmt: skip
    if f & Fault.CONTACT_FORCE_LIMIT:
        return "the hand force exceeded the contact threshold: protective stop by coassist's safety layer"
    reasons = [flag.name for flag in Fault if flag and flag & f and flag.name]
    return "the safety layer stopped the robot after repeated bad ticks (" + ", ".join(reasons) + ")"
