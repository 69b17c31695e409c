"""The safety layer's limits and their check: :class:`SafetyLimits` and :func:`within_limits`.

:class:`SafetyLimits` holds, validated, what :class:`~coassist.runtime.safety.SafetyLayer`
enforces on every command; :func:`within_limits` says which of them a joint velocity
command violates, against the TRUE limits (no margin), as the layer's own verification
(step 6 of :mod:`coassist.runtime.safety`) does. With n joints, period dt [s], the command
q̇, the previous command q̇⁻, the Jacobian J = [J_v; J_ω] (6×n) and the TCP position p, the
velocity sets are::

    |q̇_i| ≤ q̄̇_i                                    JOINT_VELOCITY_LIMIT
    ‖J_v q̇‖ ≤ v̄,   ‖J_ω q̇‖ ≤ ω̄                      TOOL_SPEED_LIMIT
    min(lo_i, p_i) ≤ p_i + (J_v q̇)_i dt ≤ max(hi_i, p_i)   WORKSPACE_LIMIT

and the acceleration limit ‖q̇ − q̇⁻‖∞ ≤ a dt, each to :data:`LIMIT_TOLERANCE`. The layer
shares :class:`TrueLimits`, :func:`violations` and the input parsers :func:`as_vector` and
:func:`as_jacobian` with :func:`within_limits`, so both check the same sets the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from coassist._checks import check_int_at_least, check_positive_scalar
from coassist.interfaces import Fault

__all__ = [
    "LIMIT_TOLERANCE",
    "SafetyLimits",
    "TrueLimits",
    "as_jacobian",
    "as_vector",
    "violations",
    "within_limits",
]

_JV = int(Fault.JOINT_VELOCITY_LIMIT)
_TS = int(Fault.TOOL_SPEED_LIMIT)
_WS = int(Fault.WORKSPACE_LIMIT)

#: Tolerance of the layer's verification (step 6 of :mod:`coassist.runtime.safety`) and of
#: :func:`within_limits`: rounding of a
#: command computed to sit exactly on a limit is not a violation.
LIMIT_TOLERANCE = 1e-9


def _positive(value, name: str) -> float:
    return check_positive_scalar(value, f"SafetyLimits.{name}")


@dataclass(frozen=True)
class SafetyLimits:
    """The limits the safety layer enforces on every command (validated; errors name the field).

    Attributes
    ----------
    joint_velocity : float or (n,) [rad/s], default π/2 (90 °/s)
        Largest joint speed, one value for all joints or one per joint. The layer aims
        at ``margin`` times it.
    joint_acceleration : float [rad/s²], default 8.0
        Largest change of any joint's velocity command per second: the command moves
        by at most ``joint_acceleration · dt`` per tick (also how fast a bad tick
        decelerates).
    tool_speed : float [m/s], default 0.25
        Largest linear speed of the tool centre point (ISO/TS 15066 collaborative
        speeds are of this order).
    tool_angular_speed : float [rad/s], default 1.0 (57 °/s)
        Largest rotation speed of the tool.
    workspace_lower, workspace_upper : (3,) [m] or None, default None
        Corners of the box, in the base frame, that the tool centre point may not
        leave; None for no box (both or neither). Motion toward a face slows down so
        that it stops at the face; outside the box, motion further out is removed
        (the layer never pushes back on its own).
    contact_force : float [N], default 120.0
        Hand force (norm of the measured hand wrench's force) above which the robot
        makes a protective stop. The hand wrench is the wrench pipeline's: filtered, and its
        deadband (``WrenchConfig.deadband_force``, 0.2 N by default) taken off, so the sensor's force
        must pass contact_force plus the deadband.
    contact_torque : float [N·m], default 15.0
        The same for the hand torque.
    min_manipulability : float [-], default 0.01; 0 disables
        Yoshikawa manipulability √det(J Jᵀ) under which motion is scaled down, linearly
        to zero at half this value (near a singularity small tool motions need large
        joint motions).
    max_bad_ticks : int, default 25 (0.2 s at 125 Hz)
        Consecutive bad ticks (upstream faults, invalid inputs) after which the layer
        stops the robot; the last of them is the stop. Until then it decelerates.
    margin : float in (0, 1], default 0.98
        Fraction of each velocity and acceleration limit the layer aims for, so that a
        command stays inside the true limit as J changes between ticks.
    """

    joint_velocity: float | tuple[float, ...] = math.pi / 2
    joint_acceleration: float = 8.0
    tool_speed: float = 0.25
    tool_angular_speed: float = 1.0
    workspace_lower: tuple[float, float, float] | None = None
    workspace_upper: tuple[float, float, float] | None = None
    contact_force: float = 120.0
    contact_torque: float = 15.0
    min_manipulability: float = 0.01
    max_bad_ticks: int = 25
    margin: float = 0.98

    def __post_init__(self) -> None:
        jv = self.joint_velocity
        if isinstance(jv, (str, bytes)):
            raise ValueError(f"SafetyLimits.joint_velocity must be a number or a list of numbers, got {jv!r}")
        try:
            arr = np.asarray(jv, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"SafetyLimits.joint_velocity must be a number or a list of numbers, got {jv!r}") from None
        if arr.ndim > 1 or arr.size == 0:
            raise ValueError(f"SafetyLimits.joint_velocity must be a number or a list of numbers, got {jv!r}")
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            raise ValueError(f"SafetyLimits.joint_velocity must be finite and > 0, got {jv!r}")
        object.__setattr__(self, "joint_velocity", float(arr) if arr.ndim == 0 else tuple(float(v) for v in arr))
        for name in ("joint_acceleration", "tool_speed", "tool_angular_speed", "contact_force", "contact_torque"):
            object.__setattr__(self, name, _positive(getattr(self, name), name))
        lo, hi = self.workspace_lower, self.workspace_upper
        if (lo is None) != (hi is None):
            missing = "workspace_upper" if hi is None else "workspace_lower"
            raise ValueError(f"SafetyLimits.{missing} must be given with the other corner of the workspace box")
        if lo is not None:
            box = []
            for name, val in (("workspace_lower", lo), ("workspace_upper", hi)):
                try:
                    a = np.asarray(val, dtype=float)
                except (TypeError, ValueError):
                    raise ValueError(f"SafetyLimits.{name} must be 3 numbers [m], got {val!r}") from None
                if a.shape != (3,) or not np.all(np.isfinite(a)):
                    raise ValueError(f"SafetyLimits.{name} must be 3 finite numbers [m], got {val!r}")
                box.append(tuple(float(v) for v in a))
            if not all(lo < hi for lo, hi in zip(*box)):
                raise ValueError(
                    f"SafetyLimits.workspace_upper must exceed workspace_lower on every axis, got {box[0]} and {box[1]}"
                )
            object.__setattr__(self, "workspace_lower", box[0])
            object.__setattr__(self, "workspace_upper", box[1])
        try:
            wmin = float(self.min_manipulability)
        except (TypeError, ValueError):
            raise ValueError(
                f"SafetyLimits.min_manipulability must be a number, got {self.min_manipulability!r}"
            ) from None
        if not math.isfinite(wmin) or wmin < 0:
            raise ValueError(
                f"SafetyLimits.min_manipulability must be finite and >= 0, got {self.min_manipulability!r}"
            )
        object.__setattr__(self, "min_manipulability", wmin)
        check_int_at_least(self.max_bad_ticks, "SafetyLimits.max_bad_ticks", 1)
        object.__setattr__(self, "max_bad_ticks", int(self.max_bad_ticks))
        try:
            margin = float(self.margin)
        except (TypeError, ValueError):
            raise ValueError(f"SafetyLimits.margin must be a number, got {self.margin!r}") from None
        if not 0.0 < margin <= 1.0:
            raise ValueError(f"SafetyLimits.margin must be in (0, 1], got {self.margin!r}")
        object.__setattr__(self, "margin", margin)

    def joint_velocity_array(self, n_joints: int) -> np.ndarray:
        """(n_joints,) joint speed limits [rad/s]; a per-joint tuple must have n_joints entries."""
        jv = self.joint_velocity
        if isinstance(jv, tuple):
            if len(jv) != n_joints:
                raise ValueError(
                    f"SafetyLimits.joint_velocity has {len(jv)} entries but the robot has {n_joints} joints"
                )
            return np.array(jv)
        return np.full(n_joints, jv)

    def describe(self) -> str:
        """The limits in plain words, one per line, for the operator to read before the robot moves."""
        deg = 180.0 / math.pi
        jv = self.joint_velocity
        if isinstance(jv, tuple):
            joint = "joint speed ≤ " + ", ".join(f"{v * deg:.0f}" for v in jv) + " °/s (joints 1…" + f"{len(jv)})"
        else:
            joint = f"joint speed ≤ {jv * deg:.0f} °/s ({jv:.3g} rad/s) on every joint"
        lines = [
            joint,
            f"joint acceleration ≤ {self.joint_acceleration * deg:.0f} °/s² ({self.joint_acceleration:.3g} rad/s²)",
            f"tool speed ≤ {self.tool_speed:.3g} m/s, tool rotation ≤ {self.tool_angular_speed * deg:.0f} °/s "
            f"({self.tool_angular_speed:.3g} rad/s)",
        ]
        if self.workspace_lower is None:
            lines.append("workspace: no box (the tool may go wherever the robot reaches)")
        else:
            axes = ", ".join(
                f"{a} ∈ [{lo:.3f}, {hi:.3f}] m" for a, lo, hi in zip("xyz", self.workspace_lower, self.workspace_upper)
            )
            lines.append(f"workspace: the tool stays in the box {axes} (robot base frame)")
        lines.append(
            f"contact: hand force > {self.contact_force:.3g} N or hand torque > {self.contact_torque:.3g} N·m "
            "→ protective stop"
        )
        if self.min_manipulability > 0:
            lines.append(
                f"singularity: motion slows below manipulability {self.min_manipulability:.3g}, "
                f"stops at {self.min_manipulability / 2:.3g}"
            )
        else:
            lines.append("singularity: no manipulability guard")
        lines.append(
            f"faults: the robot decelerates on a bad tick and stops after {self.max_bad_ticks} bad ticks in a row"
        )
        lines.append(f"margin: commands aim at {self.margin:.0%} of each speed and acceleration limit")
        return "\n".join(lines)


# ---------------------------------------------------------------------- input parsing
def as_vector(x, n: int) -> np.ndarray | None:
    """x as a finite float64 (n,) array, or None (wrong type, shape, or non-finite)."""
    if type(x) is np.ndarray and x.dtype.char == "d" and x.shape == (n,):
        s = sum(x.tolist())
        if s - s == 0.0:  # NaN and ±inf survive the sum (inf − inf = NaN); overflow is re-checked
            return x
        return x if np.isfinite(x).all() else None
    try:
        a = np.asarray(x)
        if a.dtype.kind not in "fiu" or a.shape != (n,):
            return None
        a = a.astype(np.float64)
    except Exception:
        return None
    return a if np.isfinite(a).all() else None


def as_jacobian(x, n: int) -> np.ndarray | None:
    """x as a finite float64 (6, n) array (a Jacobian), or None (wrong type, shape, or non-finite)."""
    try:
        a = x if type(x) is np.ndarray and x.dtype.char == "d" else np.asarray(x)
        if a.dtype.kind not in "fiu" or a.shape != (6, n):
            return None
        a = a.astype(np.float64, copy=False)
    except Exception:
        return None
    return a if np.isfinite(a).all() else None


# ---------------------------------------------------------------------- the true limits
class TrueLimits:
    """The true limits as Python floats, for the layer's verification (step 6) and :func:`within_limits`.

    For n joints and period dt [s]: ``vmax`` the (n,) joint speed limits [rad/s] as a list,
    ``vuniform`` the one joint speed limit [rad/s] when all joints share it (else None),
    ``acc`` = a dt the largest command step per tick [rad/s], ``tool`` [m/s] and ``ang``
    [rad/s] the tool speeds, ``lo`` and ``hi`` the workspace box's corners [m] as lists
    (None without a box). No margin: these are the limits themselves.
    """

    __slots__ = ("n", "dt", "vmax", "vuniform", "acc", "tool", "ang", "lo", "hi")

    def __init__(self, limits: SafetyLimits, dt: float, n: int) -> None:
        self.n = n
        self.dt = dt
        self.vmax = limits.joint_velocity_array(n).tolist()
        self.vuniform = None if isinstance(limits.joint_velocity, tuple) else limits.joint_velocity
        self.acc = limits.joint_acceleration * dt
        self.tool = limits.tool_speed
        self.ang = limits.tool_angular_speed
        self.lo = None if limits.workspace_lower is None else list(limits.workspace_lower)
        self.hi = None if limits.workspace_upper is None else list(limits.workspace_upper)


def violations(
    b: TrueLimits, x: np.ndarray, J: np.ndarray | None, pl: list | None, tol: float, notes: list | None = None
) -> int:
    """Flags of the velocity sets (true limits + tol) that x violates; J, pl: valid or None.

    JOINT_VELOCITY_LIMIT: |x_i| > q̄̇_i; TOOL_SPEED_LIMIT: ‖J_v x‖ > v̄ or ‖J_ω x‖ > ω̄;
    WORKSPACE_LIMIT: p_i + (J_v x)_i dt beyond max(hi_i, p_i) or min(lo_i, p_i).
    x is (n,) [rad/s], J (6, n), pl the TCP pose as a list (its first three entries, [m]);
    ``notes``, when a list, gets one line per violation (:func:`within_limits`' text).
    """
    bad = 0
    xl = x.tolist()
    if b.vuniform is not None and notes is None:
        if not max(max(xl), -min(xl)) <= b.vuniform + tol:
            bad |= _JV
    else:
        for i, (xi, lim) in enumerate(zip(xl, b.vmax)):
            if not abs(xi) <= lim + tol:
                bad |= _JV
                if notes is not None:
                    notes.append(f"joint_velocity: joint {i} at {xi:.6g} rad/s, limit {lim:.6g}")
    if J is None:
        return bad
    vl = J.dot(x).tolist()
    lin = math.sqrt(vl[0] * vl[0] + vl[1] * vl[1] + vl[2] * vl[2])
    ang = math.sqrt(vl[3] * vl[3] + vl[4] * vl[4] + vl[5] * vl[5])
    if not lin <= b.tool + tol:  # `not <=`: NaN is a violation too
        bad |= _TS
        if notes is not None:
            notes.append(f"tool_speed: {lin:.6g} m/s, limit {b.tool:.6g}")
    if not ang <= b.ang + tol:
        bad |= _TS
        if notes is not None:
            notes.append(f"tool_angular_speed: {ang:.6g} rad/s, limit {b.ang:.6g}")
    if pl is not None and b.lo is not None:
        dt = b.dt
        for i in range(3):
            p = pl[i]
            nxt = p + vl[i] * dt
            hi = b.hi[i] if b.hi[i] > p else p
            lo = b.lo[i] if b.lo[i] < p else p
            if not (lo - tol <= nxt <= hi + tol):
                bad |= _WS
                if notes is not None:
                    notes.append(
                        f"workspace: {'xyz'[i]} would go from {p:.6g} to {nxt:.6g} m, box [{b.lo[i]:.6g}, {b.hi[i]:.6g}]"
                    )
    return bad


def _braking(x: list, prev: list, tol: float) -> bool:
    """x = σ prev for some σ ∈ [0, 1) (to tol per joint): prev slowed down along its own direction."""
    pp = sum(p * p for p in prev)
    if pp == 0.0:
        return False
    sigma = sum(a * p for a, p in zip(x, prev)) / pp
    return 0.0 <= sigma < 1.0 and all(abs(a - sigma * p) <= tol for a, p in zip(x, prev))


def within_limits(qd, qd_prev, J, pose, limits: SafetyLimits, dt: float, tol: float = LIMIT_TOLERANCE) -> list[str]:
    """Every limit of ``limits`` that the joint velocity command qd violates (empty: none).

    qd : (n,) the command [rad/s]; it must be finite.
    qd_prev : (n,) the previous command, or None to skip the acceleration check (a
        command sent with ``stop=True`` is not a velocity command: the world brakes
        with its own stop).
    J : (6, n) Jacobian, pose : (6,) TCP pose. When J (or the pose) is not finite or
        of the wrong shape, the tool (or workspace) limits cannot be evaluated and are
        skipped: the layer did not know them either.

    The joint speed and acceleration limits ‖qd − qd_prev‖∞ ≤ a dt always hold. A tool
    speed or workspace excess is accepted only in the residual case of
    :mod:`coassist.runtime.safety`'s docstring (step 6c): qd_prev itself violates that set
    for this J and pose, and qd is a step of at most a dt from qd_prev toward zero.
    The returned strings start with the name of the violated SafetyLimits field.
    """
    with np.errstate(all="ignore"):
        return _within_limits(qd, qd_prev, J, pose, limits, dt, tol)


def _within_limits(qd, qd_prev, J, pose, limits, dt, tol):
    try:
        shape = np.shape(qd)
    except Exception:
        shape = ()
    x = as_vector(qd, shape[0] if len(shape) == 1 else -1)
    if x is None:
        return [f"qd: not a finite vector: {qd!r}"]
    n = x.shape[0]
    b = TrueLimits(limits, float(dt), n)
    Jm = as_jacobian(J, n)
    p = as_vector(pose, 6)
    pl = None if p is None else p.tolist()
    notes: list[str] = []
    violations(b, x, Jm, pl, tol, notes)
    if qd_prev is not None:
        prev = as_vector(qd_prev, n)
        if prev is None:
            notes.append(f"joint_acceleration: the previous command is not a finite ({n},) vector")
            return notes
        xl, pv = x.tolist(), prev.tolist()
        step = max(abs(a - c) for a, c in zip(xl, pv))
        if step > b.acc + tol:
            notes.append(
                f"joint_acceleration: a step of {step:.6g} rad/s in one tick, limit {b.acc:.6g} "
                f"({limits.joint_acceleration:.6g} rad/s² × {dt:.6g} s)"
            )
        elif _braking(xl, pv, tol):  # step 6c: braking from a command the new state put outside
            inherited = violations(b, prev, Jm, pl, tol)
            for flag, field in ((_TS, "tool_"), (_WS, "workspace")):
                if inherited & flag:
                    notes = [note for note in notes if not note.startswith(field)]
    return notes
