"""The safety layer: the last stage of every control tick, in every world, always on.

Whatever reaches it — NaN, ±inf, 1e300, arrays of the wrong shape, ``None``, strings —
the layer returns a finite joint velocity command inside the limits of
:class:`~coassist.runtime.safety_limits.SafetyLimits`, never raises, and reports every intervention as a
:class:`~coassist.interfaces.Fault` flag for the tick's log row. The same code runs in
simulation and on the UR5, so what the tests prove here holds on the robot.

Notation: n joints, period dt [s], the previous command q̇⁻ (what the robot was told
last tick), the Jacobian J = [J_v; J_ω] (6×n, base frame, twist = [v; ω]), the TCP
position p (the first three entries of the pose), the workspace box [lo, hi] and the
margin m (the layer aims at m · each speed limit, so a command stays inside the true
limit even as J changes between ticks).

**Cartesian stage** — :meth:`SafetyLayer.limit_twist`, before the joint mapping::

    v ← v · min(1, m v̄ / ‖v‖)            ω ← ω · min(1, m ω̄ / ‖ω‖)       (direction kept)
    v_i ← clip(v_i, min(lo_i − p_i, 0)/dt, max(hi_i − p_i, 0)/dt)     (each axis; the
                                                               motion along a face is kept)

**Joint stage** — :meth:`SafetyLayer.limit_joint_velocity`, in this order:

1. *Stop.* A robot stop (protective or emergency) or a hand wrench ‖f‖ > f̄ or ‖τ‖ > τ̄
   (a protective stop, CONTACT_FORCE_LIMIT) latches STOPPED: from then on the command
   is zero and ``stop`` is True (the world brakes with its own stop), until ``reset()``.
   SENSOR_SATURATED upstream counts as such a wrench (CONTACT_FORCE_LIMIT): the wrench pipeline
   holds its last good reading, but a channel at the sensor's range (an FT300's 300 N, 30 N·m)
   says the hand pushes at least that hard, past f̄ and τ̄.
2. *Bad tick.* An upstream fault of :data:`BAD_TICK_FAULTS`, or q̇, J, the pose or the
   hand wrench non-finite or of the wrong shape: the target becomes 0 (DECELERATING),
   reached along the acceleration ramp of step 5. ``max_bad_ticks`` bad ticks in a row
   latch STOPPED; a good tick resets the count.
   *After a stall* (DEADLINE_MISS upstream, with the measured joint velocity q̇ₘ given),
   with the tracking lag ℓ = 2 m a dt (the MuJoCo UR5 lags its command by at most
   0.095 rad/s on the fault table's deadline ticks, against ℓ = 0.125 rad/s at 125 Hz):

   - q̇ₘ within ℓ of the span of the commands of the last :data:`RESUME_LATENCY` (on every
     joint, between the smallest and the largest of them ± ℓ): the robot kept its commands,
     seen with the state's latency; q̇⁻ is kept;
   - else, q̇ₘ between rest and q̇⁻ on every joint (± ℓ): the robot braked while the loop was
     away (a Franka brakes to rest when its 50 ms hold runs out; a watchdog sends zeros):
     q̇⁻ becomes q̇ₘ, each joint clipped to between 0 and its q̇⁻ (so no joint speeds up or
     reverses), and every step from here on is an acceleration step from what the arm
     really does (``resumed_from_measured``);
   - else q̇ₘ is no velocity a stall leaves an arm at (faster than its last command, or
     reversed: a joint state later than the latency allows, another publisher's, a
     glitch): it is not used and q̇⁻ is kept (``refused_measured``; the tick is bad
     already). So no measured value makes a joint speed up or reverse by more than one
     acceleration step.
3. *Manipulability* (Yoshikawa) w = ∏ σ_i(J) (= |det J| for n = 6, √det(J Jᵀ) for n > 6,
   √det(Jᵀ J) for n < 6). Below w_min the target is scaled by
   clip((w − w_min/2)/(w_min/2), 0, 1): zero at half the guard (SINGULARITY).
4. *Velocity sets.* The target t is scaled uniformly toward 0 by the largest s ≤ 1 that
   puts s·t into every set (each set contains 0 and is star-shaped from it, so the
   smallest of the per-set scales satisfies all; each set that acted is flagged)::

       |q̇_i| ≤ m q̄̇_i                                        JOINT_VELOCITY_LIMIT
       ‖J_v q̇‖ ≤ m v̄,   ‖J_ω q̇‖ ≤ m ω̄                        TOOL_SPEED_LIMIT
       u_i · dt · (1 + κ/2) ≤ d_i,  κ = ‖q̇‖∞ / (m a dt)        WORKSPACE_LIMIT

   with u_i the tool speed toward face i and d_i = max(distance to it, 0). The last is
   the one-step condition p + J_v q̇ dt ∈ box tightened by the braking distance: κ is
   the number of ticks the ramp of step 5 needs to bring q̇ to rest, and the tool
   covers at most u_i dt (1 + κ/2) on the way. Approaching a face along a direction
   therefore slows down within the acceleration limit and never needs a jump (the
   condition is invariant under one ramp step, so it holds at the next tick too).
5. *Acceleration.* Δ = t − q̇⁻, s = min(1, m a dt / ‖Δ‖∞), q̇ = q̇⁻ + s Δ
   (JOINT_ACCELERATION_LIMIT when s < 1). q̇ lies between two points of the sets, and
   the sets are convex (except the braking one, which only tightens the true limit),
   so it stays inside them whenever q̇⁻ was inside for the current J and pose.
6. *Verification* against the TRUE limits (no margin; :func:`~coassist.runtime.safety_limits.within_limits`): joint
   speed, acceleration against q̇⁻, tool speeds with the current J, the one-step
   workspace condition p + J_v q̇ dt ∈ box (or, outside it, no outward motion). This can
   fail only when q̇⁻ itself is outside the sets for the *new* J or pose (J or p jumped,
   or the direction of motion changed while braking toward a face). Then:

   a. The common case is a command sliding along a workspace face while J turns
      under it: the outward tool velocity it gains is tiny. It is removed with the
      least joint change, Δq̇ = Rᵀ (R Rᵀ)⁻¹ e (R: the rows of J_v of the crossed
      faces, e: the excess over the one-step bound), and the result is kept if it
      passes every check, acceleration included.
   b. Else q̇_b = q̇⁻ ramped toward 0 by one acceleration step. If q̇_b is inside, the
      command is the point of the segment [q̇_b, q̇] closest to q̇ that is inside —
      both ends respect the acceleration limit, so the command does too.
   c. Else (only if q̇⁻ is outside the sets, since q̇_b is a contraction of it toward
      0), after trying (a) on q̇_b, no command respects both the state-dependent sets
      (tool speed with the new J, workspace with the new pose) and the acceleration
      limit. This is the documented *residual case*: the command is q̇_b, braking at
      the acceleration limit, inside the joint speed limits, and it is counted in
      ``limit_conflicts``. The joint speed and acceleration limits hold whatever the
      state says: a reported pose or J that jumps (a glitch, or a real jump) could
      otherwise make the layer send a joint step of any size (a 1 m jump of the
      reported pose once asked for 0.24 rad/s in one tick against 0.064).
      :func:`~coassist.runtime.safety_limits.within_limits` accepts a tool-speed or workspace excess only here: q̇⁻
      itself outside that set for the current J and pose, q̇ one step toward rest.

   The flags of the violated sets are reported; the command is always finite.
7. q̇ becomes q̇⁻. Any exception inside the method gives the ramp of q̇⁻ toward 0
   (INTERNAL_ERROR | DECELERATING, a bad tick), never a raise.

The layer limits commands, not the robot: the robot's own tracking lag, the
nonlinearity of the kinematics within one period and a human who drags the arm are
outside it. The workspace and tool limits use the first-order prediction
p(k+1) = p(k) + J_v q̇ dt.

The limits and their check against the true limits are :mod:`coassist.runtime.safety_limits`.
:class:`SafetyLayerBatch`, the effort stage's array twin, sits beside the layer (as every
batched stage sits beside its per-trial original, docs/architecture.md).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

import numpy as np

from coassist._checks import check_int_at_least, check_positive_scalar, is_integer
from coassist._rows import RowConstants
from coassist.interfaces import Fault
from coassist.runtime.safety_limits import (
    LIMIT_TOLERANCE,
    SafetyLimits,
    TrueLimits,
    as_jacobian,
    as_vector,
    violations,
)

try:  # numpy's determinant kernel without np.linalg.det's Python checks (≈ 2 µs less per tick)
    from numpy.linalg import _umath_linalg as _ula

    _det = _ula.det
    _det(np.eye(2))
except Exception:  # pragma: no cover - another numpy
    _det = np.linalg.det

__all__ = ["BAD_TICK_FAULTS", "RESUME_LATENCY", "SafetyLayer", "SafetyLayerBatch"]

#: [s] How late a measured joint velocity may show the commands the robot kept (step 2): the
#: commands of this long before a stall still count as kept. A loaded machine's ROS 2 executor
#: delivers joint states a few ticks late; 40 ms is 5 ticks at 125 Hz.
RESUME_LATENCY = 0.04

#: Upstream faults that make a tick "bad": the layer decelerates, and stops after
#: ``SafetyLimits.max_bad_ticks`` of them in a row.
BAD_TICK_FAULTS = (
    Fault.DEADLINE_MISS
    | Fault.PREDICTOR_STALLED
    | Fault.NONFINITE_STATE
    | Fault.NONFINITE_WRENCH
    | Fault.NONFINITE_EFFORT
    | Fault.SENSOR_STALE
    | Fault.WRENCH_SPIKE
    | Fault.INTERNAL_ERROR
    | Fault.INVALID_INPUT
    | Fault.STATE_MISMATCH
)  # SENSOR_SATURATED is not here: it stops the robot (step 1), it does not merely decelerate it

#: The sideways part of an effort above ``tool_speed``, relative to |u| |v|, that the effort stage removes: more than
#: the rounding of an effort straight against v.
_ACROSS = 1e-9
#: [m/s] A tool velocity at or above this is no measurement (no tool moves so fast): INVALID_INPUT, zero effort. Its
#: square overflowed above ~1e154, the speed read inf, and a sideways effort passed the tool-speed check unflagged
#: (a review, 2026-12-07).
_V_MAX = 1e3

_ROBOT_STOPS = int(Fault.ROBOT_PROTECTIVE_STOP | Fault.ROBOT_EMERGENCY_STOP)
_SAT = int(Fault.SENSOR_SATURATED)
_BAD = int(BAD_TICK_FAULTS)
_JV = int(Fault.JOINT_VELOCITY_LIMIT)
_JA = int(Fault.JOINT_ACCELERATION_LIMIT)
_TS = int(Fault.TOOL_SPEED_LIMIT)
_WS = int(Fault.WORKSPACE_LIMIT)
_CF = int(Fault.CONTACT_FORCE_LIMIT)
_SG = int(Fault.SINGULARITY)
_DC = int(Fault.DECELERATING)
_ST = int(Fault.STOPPED)
_IE = int(Fault.INTERNAL_ERROR)
_II = int(Fault.INVALID_INPUT)
_NE = int(Fault.NONFINITE_EFFORT)
_DM = int(Fault.DEADLINE_MISS)

#: The flags the layer raises, counted in ``SafetyLayer.interventions``.
_COUNTED = (
    Fault.JOINT_VELOCITY_LIMIT,
    Fault.JOINT_ACCELERATION_LIMIT,
    Fault.TOOL_SPEED_LIMIT,
    Fault.WORKSPACE_LIMIT,
    Fault.CONTACT_FORCE_LIMIT,
    Fault.SINGULARITY,
    Fault.DECELERATING,
    Fault.STOPPED,
    Fault.ROBOT_PROTECTIVE_STOP,
    Fault.ROBOT_EMERGENCY_STOP,
    Fault.INTERNAL_ERROR,
    Fault.INVALID_INPUT,
)
_COUNTED_BITS = tuple((int(f), f.name) for f in _COUNTED)

#: A tool speed toward a face below this [m/s] is rounding (the pseudo-inverse of a twist
#: along the face), not motion: it moves the tool 1e-11 m per tick at 125 Hz.
_VN_EPS = 1e-9

_FAULTS: dict[int, Fault] = {0: Fault.NONE}


def _fault(bits: int) -> Fault:
    """Fault(bits), cached: building an IntFlag costs microseconds, a dict lookup does not."""
    f = _FAULTS.get(bits)
    if f is None:
        f = _FAULTS[bits] = Fault(bits)
    return f


# ---------------------------------------------------------------------- input parsing
def _finite_vector(x, at_least: int) -> np.ndarray | None:
    """x as a finite float64 1-D array of at least ``at_least`` entries, or None."""
    if type(x) is np.ndarray and x.dtype.char == "d" and x.ndim == 1 and x.shape[0] >= at_least:
        s = sum(x.tolist())  # the per-tick case: a plain sum is cheaper than isfinite().all()
        if s - s == 0.0:  # NaN and ±inf survive the sum (inf − inf = NaN); overflow is re-checked below
            return x
    try:
        a = np.asarray(x)
        if a.dtype.kind not in "fiu" or a.ndim != 1 or a.shape[0] < at_least:
            return None
        a = a.astype(np.float64, copy=False)
    except Exception:
        return None
    return a if np.isfinite(a).all() else None


def _fault_word(x) -> int | None:
    """A fault word as a non-negative int, or None when it is not one."""
    if is_integer(x) and x >= 0:
        return int(x)
    return None


# ---------------------------------------------------------------------- the layer
class SafetyLayer:
    """The safety layer of one robot (module docstring).

    Parameters
    ----------
    limits : the limits to enforce.
    dt : the control period [s].
    n_joints : joints of the robot (6 for the UR5).

    Attributes
    ----------
    interventions : dict flag name → calls (of either stage) that raised it since ``reset``.
    bad_ticks : consecutive bad ticks so far.
    limit_conflicts : ticks of the residual case (step 6c): J or the pose jumped so that
        no command within the acceleration limit kept the tool speed or workspace set;
        the layer braked at the acceleration limit.
    resumed_from_measured : ticks after a stall on which q̇⁻ became the measured joint
        velocity (step 2).
    refused_measured : ticks after a stall whose measured joint velocity no stall explains
        (step 2: not used).
    """

    def __init__(self, limits: SafetyLimits, dt: float, n_joints: int) -> None:
        if not isinstance(limits, SafetyLimits):
            raise TypeError(f"SafetyLayer.limits must be a SafetyLimits, got {type(limits).__name__}")
        self.limits = limits
        self.dt = check_positive_scalar(dt, "SafetyLayer.dt")
        self.n_joints = check_int_at_least(n_joints, "SafetyLayer.n_joints", 1)
        n, m = self.n_joints, limits.margin
        self._b = TrueLimits(limits, self.dt, n)
        self._n = n
        self._inv_vmax_m = (1.0 / (m * limits.joint_velocity_array(n))).tolist()
        self._inv_vuniform = 0.0 if self._b.vuniform is None else 1.0 / (m * self._b.vuniform)
        self._acc_m = m * limits.joint_acceleration * self.dt
        self._tool_m = m * limits.tool_speed
        self._ang_m = m * limits.tool_angular_speed
        self._f2 = limits.contact_force * limits.contact_force
        self._t2 = limits.contact_torque * limits.contact_torque
        self._wmin = limits.min_manipulability
        self._box = limits.workspace_lower is not None
        self._zeros = [0.0] * n
        self._effort_d = 2  # limit_effort's output length until it has seen a good u_r
        # the commands of the last RESUME_LATENCY (step 2), newest last
        self._recent: deque[list[float]] = deque(maxlen=max(1, math.ceil(RESUME_LATENCY / self.dt - 1e-9)))
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, qd=None) -> None:
        """Start a run: not stopped, no bad ticks, counters cleared, previous command = qd or zeros.

        qd : (n,) the robot's current joint velocity [rad/s] (so the first command ramps
        from it), scaled into the joint speed limits. Raises ValueError when it is not
        a finite (n,) vector.
        """
        prev = self._zeros
        if qd is not None:
            x = as_vector(qd, self._n)
            if x is None:
                raise ValueError(f"SafetyLayer.reset: qd must be a finite ({self._n},) vector, got {qd!r}")
            xl = x.tolist()
            r = max(abs(v) * iv for v, iv in zip(xl, self._inv_vmax_m))
            prev = [v / r for v in xl] if r > 1.0 else xl
        self._prev = list(prev)
        self._recent.clear()
        self._recent.append(self._prev)
        self._stopped = False
        self._decelerating = False
        self.bad_ticks = 0
        self.limit_conflicts = 0
        self.resumed_from_measured = 0
        self.refused_measured = 0
        self.interventions = {name: 0 for _, name in _COUNTED_BITS}

    @property
    def stopped(self) -> bool:
        """STOPPED is latched: every command is zero with ``stop`` True until :meth:`reset`."""
        return self._stopped

    @property
    def decelerating(self) -> bool:
        """The last command was the ramp toward rest of a bad tick (the tick may reset its admittance to it)."""
        return self._decelerating

    @property
    def previous(self) -> np.ndarray:
        """The last command [rad/s] (a copy)."""
        return np.array(self._prev)

    def latch_stop(self) -> None:
        """Latch STOPPED from outside (an effort world's stop): zero command from now on."""
        self._stopped = True
        self._prev = list(self._zeros)

    def _count(self, bits: int) -> None:
        d = self.interventions
        for bit, name in _COUNTED_BITS:
            if bits & bit:
                d[name] += 1

    # ------------------------------------------------------------------ effort worlds
    def limit_effort(
        self, u_r: np.ndarray, v: np.ndarray, hand: np.ndarray, upstream: Fault, robot_stop: Fault = Fault.NONE
    ) -> tuple[np.ndarray, Fault, bool]:
        """The stage for ``effort`` worlds (the point-mass world renders the admittance itself).

        u_r : (d,) the robot's effort [N]; v : (≥ 2,) the tool's velocity [m/s] (x-y first);
        hand : the hand wrench [N, N·m], (6,) or its first (≥ 2,) force entries. Returns
        (effort, flags, stop), effort a new finite (d,) array:

        - a robot stop, a hand force over ``contact_force``, or SENSOR_SATURATED upstream (a channel at
          the sensor's range: the force is at least that, above ``contact_force``) latches STOPPED
          (CONTACT_FORCE_LIMIT for the last two): zero effort and ``stop`` from now on (the world brakes);
        - u_r not a finite vector: zero effort, NONFINITE_EFFORT (INVALID_INPUT when it
          is not a vector at all); v or hand missing, short or non-finite, or v at or above 1000 m/s (no
          measurement): zero effort, INVALID_INPUT (the contact and speed checks cannot be made);
        - above ``tool_speed``, with or without an upstream fault (a wrench fault zeroes the hand's
          force, not the controller's effort), the effort may only brake: of its x-y force only the
          component against v is kept, the rest (forward, and sideways: a sideways push turns and,
          stepped over a period, speeds the tool) removed (TOOL_SPEED_LIMIT).

        Never raises (as the joint stage); d is u_r's length, or the last good call's.
        """
        try:
            with np.errstate(all="ignore"):
                return self._limit_effort(u_r, v, hand, upstream, robot_stop)
        except Exception:  # pragma: no cover - defensive: nothing above is expected to raise
            self._count(_IE)
            return np.zeros(self._effort_d), _fault(_IE), False

    def _limit_effort(self, u_r, v, hand, upstream, robot_stop) -> tuple[np.ndarray, Fault, bool]:
        lim = self.limits
        up, rs = _fault_word(upstream), _fault_word(robot_stop)
        u = _finite_vector(u_r, 1)
        if u is not None:
            self._effort_d = u.shape[0]
        f = (rs or 0) & _ROBOT_STOPS
        w = _finite_vector(hand, 2)
        if (w is not None and float(np.dot(w[:3], w[:3])) > self._f2) or (up or 0) & _SAT:
            f |= _CF
        if f or self._stopped:
            self.latch_stop()
            self._count(f | _ST)
            return np.zeros(self._effort_d), _fault(f | _ST), True
        vel = _finite_vector(v, 2)
        bad = 0
        if u is None:
            bad |= _NE if np.ndim(u_r) == 1 and np.size(u_r) else _II
        if vel is None or w is None or up is None or rs is None or not abs(vel[:2]).max() < _V_MAX:
            bad |= _II
        if bad or u is None or vel is None or w is None or up is None or rs is None:  # (the Nones set bad)
            self._count(bad & _II)
            return np.zeros(self._effort_d), _fault(bad), False
        u = u.copy()
        # The tool-speed check runs after an upstream fault too: a wrench fault zeroes the hand's force, not the
        # controller's effort (a zero effort passes it unchanged: nothing along v).
        speed = math.sqrt(float(vel[0] * vel[0] + vel[1] * vel[1]))
        flags = 0
        if speed > lim.tool_speed and u.shape[0] >= 2:
            along = float(u[0] * vel[0] + u[1] * vel[1])
            across = float(u[0] * vel[1] - u[1] * vel[0])
            # (an effort straight against v is kept as it is: its sideways part is then rounding, ≤ 1e-9 of it)
            if along > 0.0 or abs(across) > _ACROSS * math.hypot(float(u[0]), float(u[1])) * speed:
                u[:2] = min(along, 0.0) / (speed * speed) * vel[:2]
                flags |= _TS
                self._count(flags)
        return u, _fault(flags), False

    # ------------------------------------------------------------------ Cartesian stage
    def limit_twist(self, twist, pose) -> tuple[np.ndarray, Fault]:
        """The tool twist (6,) [m/s, rad/s] inside the tool speeds and the workspace (module docstring).

        A twist that is not a finite (6,) vector, or a pose that is not one while a
        workspace box is set, gives zeros and INVALID_INPUT. Never raises.
        """
        try:
            with np.errstate(all="ignore"):
                return self._limit_twist(twist, pose)
        except Exception:  # pragma: no cover - defensive: nothing above is expected to raise
            self._count(_II | _IE)
            return np.zeros(6), _fault(_II | _IE)

    def _limit_twist(self, twist, pose) -> tuple[np.ndarray, Fault]:
        t = as_vector(twist, 6)
        p = as_vector(pose, 6) if self._box else None
        if t is None or (self._box and p is None):
            self._count(_II)
            return np.zeros(6), _fault(_II)
        tl = t.tolist()
        flags = 0
        lin2 = tl[0] * tl[0] + tl[1] * tl[1] + tl[2] * tl[2]
        if lin2 > self._tool_m * self._tool_m:
            k = self._tool_m / math.sqrt(lin2)
            tl[0] *= k
            tl[1] *= k
            tl[2] *= k
            flags |= _TS
        ang2 = tl[3] * tl[3] + tl[4] * tl[4] + tl[5] * tl[5]
        if ang2 > self._ang_m * self._ang_m:
            k = self._ang_m / math.sqrt(ang2)
            tl[3] *= k
            tl[4] *= k
            tl[5] *= k
            flags |= _TS
        if p is not None:
            b, dt = self._b, self.dt
            pl = p.tolist()
            for i in range(3):
                # per axis, so the motion along a face is kept; outside the box the
                # outward bound is 0: the tool may come back but is never pushed back
                up = max(b.hi[i] - pl[i], 0.0) / dt
                down = min(b.lo[i] - pl[i], 0.0) / dt
                if tl[i] > up:
                    tl[i] = up
                    flags |= _WS
                elif tl[i] < down:
                    tl[i] = down
                    flags |= _WS
        if flags:
            self._count(flags)
        return np.array(tl), _fault(flags)

    # ------------------------------------------------------------------ joint stage
    def limit_joint_velocity(
        self, qd, J, pose, hand_wrench, upstream: Fault = Fault.NONE, robot_stop: Fault = Fault.NONE, measured=None
    ) -> tuple[np.ndarray, Fault, bool]:
        """The joint velocity command to send: (command (n,) [rad/s], flags, stop).

        qd : (n,) the requested joint velocity; J : (6, n) the Jacobian at the measured
        q; pose : (6,) the measured TCP pose; hand_wrench : (6,) the hand wrench [N, N·m]
        (any frame: only its norms are used); upstream : the tick's faults so far;
        robot_stop : the robot's own stop flags; measured : (n,) the measured joint
        velocity [rad/s] on a tick after a stall (DEADLINE_MISS; step 2), else None.
        Stages in the module docstring. Never raises; the command is always a new finite array.
        """
        try:
            # garbage in (1e300 · 1e300) is handled, not warned about on every tick
            with np.errstate(all="ignore"):
                if measured is not None:
                    self._resume_from(measured, upstream)
                out = self._limit_joint_velocity(qd, J, pose, hand_wrench, upstream, robot_stop)
                self._recent.append(self._prev)
                return out
        except Exception:
            # Something unforeseen: treat it as a bad tick and ramp toward rest from the
            # last command (always finite: the layer only ever stores finite commands).
            try:
                flags, stop = _IE | _DC, False
                self.bad_ticks += 1
                if self._stopped or self.bad_ticks >= self.limits.max_bad_ticks:
                    self._stopped = True
                    out, flags, stop = list(self._zeros), _IE | _ST, True
                else:
                    out = self._ramp_to_rest(self._prev)
                    if not all(math.isfinite(v) for v in out):
                        out = list(self._zeros)
                self._prev = out
                self._recent.append(out)
                self._decelerating = not stop
                self._count(flags)
                return np.array(out, dtype=float), _fault(flags), stop
            except Exception:  # pragma: no cover - last resort
                return np.zeros(self._n), Fault.INTERNAL_ERROR | Fault.STOPPED, True

    def _resume_from(self, measured, upstream) -> None:
        """After a stall, q̇⁻ := the measured q̇ when the robot braked instead of keeping its commands (step 2)."""
        up = _fault_word(upstream)
        if up is None or not up & _DM or self._stopped:
            return
        m = as_vector(measured, self._n)
        if m is None:
            return
        ml = m.tolist()
        lag = 2.0 * self._acc_m
        recent = self._recent
        if all(
            min(c[i] for c in recent) - lag <= v <= max(c[i] for c in recent) + lag for i, v in enumerate(ml)
        ):  # kept its commands (seen with the state's latency)
            return
        prev = self._prev
        if not all(min(c, 0.0) - lag <= v <= max(c, 0.0) + lag for v, c in zip(ml, prev)):
            self.refused_measured += 1  # faster than the last command, or reversed: no brake
            return
        # between rest and the last command, joint by joint (inside the joint speed limits as q̇⁻ is)
        self._prev = [min(max(v, min(c, 0.0)), max(c, 0.0)) for v, c in zip(ml, prev)]
        self.resumed_from_measured += 1

    def _ramp_to_rest(self, prev: list) -> list:
        """prev moved one (margin) acceleration step toward 0, along its own direction."""
        top = max(abs(v) for v in prev)
        if top <= self._acc_m:
            return list(self._zeros)
        k = 1.0 - self._acc_m / top
        return [v * k for v in prev]

    def _stop(self, flags: int) -> tuple[np.ndarray, Fault, bool]:
        self._stopped = True
        self._decelerating = False
        self._prev = list(self._zeros)
        flags |= _ST
        self._count(flags)
        return np.zeros(self._n), _fault(flags), True

    def _limit_joint_velocity(self, qd, J, pose, hand_wrench, upstream, robot_stop):
        n = self._n
        prev = self._prev
        # -------- 1. stops: the robot's own, or the hand pushing too hard
        up = _fault_word(upstream)
        rs = _fault_word(robot_stop)
        w = as_vector(hand_wrench, 6)
        flags = ((up or 0) | (rs or 0)) & _ROBOT_STOPS
        if (up or 0) & _SAT:  # a channel at the sensor's range: the hand wrench is at least that, over f̄ or τ̄
            flags |= _CF
        if w is not None:
            wl = w.tolist()
            if (
                wl[0] * wl[0] + wl[1] * wl[1] + wl[2] * wl[2] > self._f2
                or wl[3] * wl[3] + wl[4] * wl[4] + wl[5] * wl[5] > self._t2
            ):
                flags |= _CF
        if flags or self._stopped:
            return self._stop(flags)

        # -------- 2. bad tick: decelerate, stop when it persists
        q = as_vector(qd, n)
        p = as_vector(pose, 6)
        v0 = None  # J q at the requested q, as a list
        if q is not None and type(J) is np.ndarray and J.dtype.char == "d" and J.shape == (6, n):
            # a non-finite entry of J reaches J q (0·inf = NaN): one product checks both
            v = J.dot(q).tolist()
            s = sum(v)
            if s - s == 0.0:
                Jm, v0 = J, v
            else:
                Jm = as_jacobian(J, n)
        else:
            Jm = as_jacobian(J, n)
        if v0 is None and q is not None and Jm is not None:
            v = Jm.dot(q).tolist()
            if all(math.isfinite(x) for x in v):  # else J q overflowed: meaningless, a bad tick
                v0 = v
        bad = up is None or rs is None or w is None or q is None or v0 is None or p is None or (up & _BAD) != 0
        pl = None if p is None else p.tolist()
        if bad:
            self.bad_ticks += 1
            if self.bad_ticks >= self.limits.max_bad_ticks:
                return self._stop(0)
            flags = _DC
            cl = self._ramp_to_rest(prev)
        else:
            self.bad_ticks = 0
            ql = q.tolist()
            scale = 1.0
            # -------- 3. manipulability guard
            if self._wmin > 0.0:
                wm = self._manipulability(Jm)
                if not wm < self._wmin and wm != wm:  # NaN (J Jᵀ overflowed): assume the worst
                    wm = 0.0
                if wm < self._wmin:
                    half = 0.5 * self._wmin
                    scale = min(max((wm - half) / half, 0.0), 1.0)
                    flags |= _SG
            # -------- 4. velocity sets: the largest uniform scale into all of them
            if scale > 0.0:
                if self._inv_vuniform:
                    r = max(max(ql), -min(ql)) * self._inv_vuniform
                else:
                    r = max(abs(v) * iv for v, iv in zip(ql, self._inv_vmax_m))
                if r * scale > 1.0:
                    scale = 1.0 / r
                    flags |= _JV
                lin2 = v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2]
                ang2 = v0[3] * v0[3] + v0[4] * v0[4] + v0[5] * v0[5]
                k_lin = self._tool_m / math.sqrt(lin2) if lin2 > 0.0 else math.inf
                k_ang = self._ang_m / math.sqrt(ang2) if ang2 > 0.0 else math.inf
                k = min(k_lin, k_ang)
                if k < scale:
                    scale = k
                    flags |= _TS
                if self._box:
                    k = self._workspace_scale(ql, v0, pl)
                    if k < scale:
                        scale = k
                        flags |= _WS
            if scale < 1.0:
                tl = [v * scale for v in ql]
            else:
                tl = ql
            # -------- 5. acceleration: a step of at most m a dt toward the target
            dl = [t - c for t, c in zip(tl, prev)]
            dmax = max(max(dl), -min(dl))
            if dmax > self._acc_m:
                k = self._acc_m / dmax
                cl = [c + k * d for c, d in zip(prev, dl)]
                flags |= _JA
                dmax = max(abs(a - c) for a, c in zip(cl, prev))
            else:
                cl = tl  # dmax is the step already
        # -------- 6. verification against the true limits, with the current J and pose
        if bad:
            dmax = max(abs(a - c) for a, c in zip(cl, prev))
        cmd = np.array(cl, dtype=float)
        viol = violations(self._b, cmd, Jm, pl, LIMIT_TOLERANCE)
        if viol or not dmax <= self._b.acc + LIMIT_TOLERANCE:
            flags |= viol
            cmd = self._repair(cmd, Jm, pl)
        # -------- 7. remember
        self._prev = cmd.tolist()
        self._decelerating = bad
        if flags:
            self._count(flags)
        return cmd, _fault(flags), False

    def _manipulability(self, J: np.ndarray) -> float:
        """Yoshikawa's w = ∏ σ_i(J) over the min(6, n) singular values."""
        n = self._n
        if n == 6:
            return abs(float(_det(J)))
        JJ = J.T @ J if n < 6 else J @ J.T
        return math.sqrt(max(float(_det(JJ)), 0.0))

    def _workspace_scale(self, ql: list, v0: list, pl: list) -> float:
        """Largest σ ≤ 1 with σ q inside the braking bound of every face it approaches (step 4)."""
        b, dt = self._b, self.dt
        top = max(max(ql), -min(ql))
        K = top / self._acc_m  # ticks the ramp needs to bring q to rest
        best = 1.0
        for i in range(3):
            u = v0[i]
            if u > _VN_EPS:
                d = b.hi[i] - pl[i]
            elif u < -_VN_EPS:
                u = -u
                d = pl[i] - b.lo[i]
            else:
                continue
            if d < 0.0:
                d = 0.0  # outside: no motion further out
            if u * dt * (1.0 + 0.5 * K) <= d:
                continue
            # σ u dt (1 + σ K / 2) ≤ d  ⇔  σ ≤ 2 r / (1 + √(1 + 2 K r)),  r = d / (u dt)
            r = d / (u * dt)
            sigma = 2.0 * r / (1.0 + math.sqrt(1.0 + 2.0 * K * r))
            if sigma < best:
                best = sigma
        return best

    def _repair(self, cmd: np.ndarray, J: np.ndarray | None, pl: list | None) -> np.ndarray:
        """Step 6: a command inside the true sets, within the acceleration limit when possible."""
        b = self._b
        prev = np.array(self._prev)

        def feasible(x: np.ndarray | None) -> bool:
            return (
                x is not None
                and not violations(b, x, J, pl, LIMIT_TOLERANCE)
                and float(np.max(np.abs(x - prev))) <= b.acc + LIMIT_TOLERANCE
            )

        # A command sliding along a face whose J moved under it: remove the (tiny)
        # outward tool velocity with the least joint change, keep the rest.
        out = self._face_correction(cmd, J, pl)
        if feasible(out):
            return out
        brake = np.array(self._ramp_to_rest(self._prev), dtype=float)
        if not violations(b, brake, J, pl, LIMIT_TOLERANCE):
            # 6b: both ends of [brake, cmd] are one acceleration step from prev
            lam = self._segment(brake, cmd - brake, J, pl)
            out = brake + lam * (cmd - brake)
            return out if feasible(out) else brake
        out = self._face_correction(brake, J, pl)
        if feasible(out):
            return out
        # 6c: the residual case (module docstring): brake at the acceleration limit
        self.limit_conflicts += 1
        return brake

    def _face_correction(self, x: np.ndarray, J: np.ndarray | None, pl: list | None) -> np.ndarray | None:
        """x minus the least-norm joint change that brings the tool velocity toward every face it
        would cross back to the one-step bound: Δq = Rᵀ (R Rᵀ)⁻¹ e, R the rows of J_v, e the excess."""
        b = self._b
        if J is None or pl is None or b.lo is None:
            return None
        dt = self.dt
        v = J[:3].dot(x).tolist()
        rows, excess = [], []
        for i in range(3):
            p = pl[i]
            up = (max(b.hi[i], p) - p) / dt
            down = (min(b.lo[i], p) - p) / dt
            if v[i] > up:
                rows.append(i)
                excess.append(v[i] - up)
            elif v[i] < down:
                rows.append(i)
                excess.append(v[i] - down)
        if not rows:
            return None
        R = J[rows]
        try:
            out = x - R.T @ np.linalg.solve(R @ R.T, np.array(excess))
        except np.linalg.LinAlgError:
            return None
        return out if np.isfinite(out).all() else None

    def _segment(self, base: np.ndarray, w: np.ndarray, J: np.ndarray | None, pl: list | None) -> float:
        """Largest λ ∈ [0, 1] with base + λ w inside the true sets (base is inside)."""
        b = self._b
        lam = 1.0
        for c, wi, lim in zip(base.tolist(), w.tolist(), b.vmax):
            if wi > 0.0:
                lam = min(lam, (lim - c) / wi)
            elif wi < 0.0:
                lam = min(lam, (-lim - c) / wi)
        if J is not None:
            u = J.dot(base)
            z = J.dot(w)
            for sl, rad in ((slice(0, 3), b.tool), (slice(3, 6), b.ang)):
                uu, zz = u[sl], z[sl]
                a2 = float(zz @ zz)
                if a2 > 0.0:
                    uz = float(uu @ zz)
                    slack = max(rad * rad - float(uu @ uu), 0.0)
                    lam = min(lam, (-uz + math.sqrt(uz * uz + a2 * slack)) / a2)
            if pl is not None and b.lo is not None:
                dt = self.dt
                ul, zl = u.tolist(), z.tolist()
                for i in range(3):
                    p = pl[i]
                    hi = max(b.hi[i], p)
                    lo = min(b.lo[i], p)
                    zi = zl[i] * dt
                    if zi > 0.0:
                        lam = min(lam, (hi - p - ul[i] * dt) / zi)
                    elif zi < 0.0:
                        lam = min(lam, (lo - p - ul[i] * dt) / zi)
        # a hair inside, so the boundary point survives rounding
        return min(max(lam * (1.0 - 1e-12), 0.0), 1.0)


class SafetyLayerBatch:
    """:meth:`SafetyLayer.limit_effort` for B layers at once on the fault-free tick: its array twin.

    On a tick without an upstream fault or a robot stop, a layer's effort stage passes u_r
    as it is, with no flag, unless the hand force is over ``contact_force`` (STOPPED), u_r,
    v or the hand is not finite, or the tool is over ``tool_speed`` with u_r pushing it on
    (TOOL_SPEED_LIMIT). :meth:`limit_effort` says for each row whether it is such a clean
    tick, on which the layer gives u_r back unchanged; a row that is not clean the caller
    runs on the layer itself. At the contact limit itself the layer's ``np.dot`` may round
    either way: rows within a relative 1e-12 of it are not clean either.

    Parameters
    ----------
    layers : the B layers (:meth:`accepts`).
    """

    @staticmethod
    def accepts(layer: object) -> bool:
        """Whether ``layer`` can join a batch: a :class:`SafetyLayer` that has not stopped."""
        return type(layer) is SafetyLayer and not layer.stopped

    def __init__(self, layers: Sequence[SafetyLayer]) -> None:
        for i, layer in enumerate(layers):
            if not self.accepts(layer):
                raise ValueError(f"layers[{i}] cannot join a SafetyLayerBatch (SafetyLayerBatch.accepts is False)")
        self._contact2 = np.array([layer._f2 for layer in layers], dtype=float)  # contact_force², as the layer's
        self._tool_speed = np.array([layer.limits.tool_speed for layer in layers], dtype=float)
        self._constants = RowConstants((self._contact2, self._tool_speed))  # gathered once per set of rows

    def limit_effort(self, rows: np.ndarray, u_r: np.ndarray, v: np.ndarray, hand: np.ndarray) -> np.ndarray:
        """clean (len(rows),) bool for the layers ``rows`` (indices), their efforts u_r (len(rows), 2)
        [N], tool velocities v (len(rows), 2) [m/s] and hand forces (len(rows), 3) [N] (class docstring)."""
        contact2, tool_speed = self._constants.take(rows)
        f2 = hand[:, 0] * hand[:, 0] + hand[:, 1] * hand[:, 1] + hand[:, 2] * hand[:, 2]
        clean = ~(f2 > contact2 * (1.0 - 1e-12))
        speed = np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])
        along = u_r[:, 0] * v[:, 0] + u_r[:, 1] * v[:, 1]
        across = u_r[:, 0] * v[:, 1] - u_r[:, 1] * v[:, 0]  # the sideways part, which the layer removes there too
        sideways = np.abs(across) > _ACROSS * np.sqrt(u_r[:, 0] * u_r[:, 0] + u_r[:, 1] * u_r[:, 1]) * speed
        clean &= ~((speed > tool_speed) & ((along > 0.0) | sideways))
        # as the docstring says: a non-finite effort, velocity or hand force is the layer's to flag, and so is an
        # implausible velocity (_V_MAX: its square overflows)
        clean &= np.isfinite(u_r).all(axis=1) & (np.abs(v[:, :2]) < _V_MAX).all(axis=1) & np.isfinite(hand).all(axis=1)
        return clean
