"""One logged trial of physical human-robot interaction.

A :class:`Trial` is the unit everything else exchanges: the simulator logs one per run,
the real-recording loader builds one per rosbag export, the intent model trains on
windows cut from a set of them (a dataset D_k, thesis Algorithm 4.1), and the metrics of
thesis §5.2.4 are computed on them.

Conventions (docs/architecture.md, *Conventions for the math*):

- SI units: s, m, m/s, N.
- ``d`` is the number of controlled Cartesian DOFs (1 to 6). Axis ``j`` of every
  ``(T, d)`` array is the same DOF; a trial file (:mod:`coassist.data.trial_file`) names them x, y, z, rx, ry, rz in order.
- ``prediction[k, i - 1]`` is the position predicted at tick ``k`` for tick ``k + i``,
  ``i = 1 … H``; a row of NaN means "no prediction in use at that tick".

Both classes are frozen and validated on construction, so a Trial that exists is
consistent: every array has the right shape, is float64 (``fault`` int64), is a
read-only copy of what was passed in, and time is strictly increasing.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_optional_int

__all__ = ["FORMER_KEYS", "GAP_FACTOR", "MAX_DOF", "ORIGINS", "Trial", "TrialMeta", "time_gaps"]

#: Most Cartesian DOFs a trial may carry (3 linear + 3 angular).
MAX_DOF = 6
#: A time step longer than this many nominal periods is a gap in the recording, not a
#: late tick: the UR5 recordings' late ticks reach 2.3 periods (18.6 ms at 8 ms).
GAP_FACTOR = 5.0
#: Where a trial comes from (:attr:`TrialMeta.origin`): the point-mass simulator, a recording
#: (rosbag export), MuJoCo, a UR5 (real or coassist ur-sim), a Franka arm.
ORIGINS = ("sim", "real", "mujoco", "ur5", "franka")
#: A key of files written before its field was renamed -> the field (issue 43: "source" also
#: named the intent sources). Trial files and manifests holding it still read, to the same
#: TrialMeta; one holding both the former key and the field with different values is refused.
FORMER_KEYS = {"source": "origin"}


def _require_str(value: Any, name: str, *, allow_empty: bool = False) -> str:
    if not isinstance(value, str):
        raise ValueError(f"TrialMeta.{name} must be a string, got {type(value).__name__} {value!r}")
    if not allow_empty and not value.strip():
        raise ValueError(f"TrialMeta.{name} must be a non-empty string")
    return value


def _freeze_json(value: Any) -> Any:
    """Deep read-only view of a JSON value (dicts become mapping proxies, lists tuples)."""
    if isinstance(value, dict):
        return MappingProxyType({k: _freeze_json(v) for k, v in value.items()})
    if isinstance(value, list):
        return tuple(_freeze_json(v) for v in value)
    return value


def _thaw_json(value: Any) -> Any:
    """Inverse of :func:`_freeze_json`: plain dicts and lists for ``json.dumps``."""
    if isinstance(value, Mapping):
        return {k: _thaw_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_thaw_json(v) for v in value]
    return value


@dataclass(frozen=True)
class TrialMeta:
    """What a trial is: who, which task, which object and controller, which model.

    Attributes
    ----------
    user : str
        Operator id, e.g. ``"user-0"`` (simulated) or ``"user-a"`` (recorded).
    task : str
        Nominal path: ``"linear"``, ``"curved"``, ``"sinusoidal"``, ``"z"``, ``"real"``, …
    object : str
        Co-manipulated object: ``"handle"``, ``"board"``, ``"heavy"``, ``"unknown"``.
    controller : str
        ``"cooperative"``, ``"impedance"``, ``"manual"``, ``"unknown"``.
    model_id : str or None
        Intent model in the loop; ``None`` means the nominal reference was used as the
        predicted intent (dataset D0 of Algorithm 4.1).
    seed : int or None
        Seed of the simulated trial; ``None`` for recordings.
    origin : str
        Where the trial comes from, one of :data:`ORIGINS`: ``"sim"`` (the point mass),
        ``"real"`` (a recording), ``"mujoco"``, ``"ur5"``, ``"franka"``. Files written before
        issue 43 store it under the key ``"source"`` (:data:`FORMER_KEYS`); they read the same.
    dt : float
        Nominal control period in s (> 0). For recordings, the median period.
    extra : Mapping
        JSON-serialisable task details (obstacle box, target point, start/end, loader
        diagnostics, …). Stored normalised through JSON (tuples become lists on the
        way in, so a written and re-read meta compares equal) and exposed read-only.
    """

    user: str
    task: str
    object: str
    controller: str
    model_id: str | None
    seed: int | None
    origin: str
    dt: float
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _require_str(self.user, "user")
        _require_str(self.task, "task")
        _require_str(self.object, "object")
        _require_str(self.controller, "controller")
        if self.model_id is not None:
            _require_str(self.model_id, "model_id")
        object.__setattr__(self, "seed", check_optional_int(self.seed, "TrialMeta.seed"))
        if self.origin not in ORIGINS:
            raise ValueError(f"TrialMeta.origin must be one of {ORIGINS}, got {self.origin!r}")
        if isinstance(self.dt, bool):
            raise ValueError(f"TrialMeta.dt must be a number, got {self.dt!r}")
        try:
            dt = float(self.dt)
        except (TypeError, ValueError):
            raise ValueError(f"TrialMeta.dt must be a number, got {self.dt!r}") from None
        if not math.isfinite(dt) or dt <= 0.0:
            raise ValueError(f"TrialMeta.dt must be a finite number > 0 (s), got {self.dt!r}")
        object.__setattr__(self, "dt", dt)
        if not isinstance(self.extra, Mapping):
            raise ValueError(f"TrialMeta.extra must be a mapping, got {type(self.extra).__name__}")
        # Normalise through strict JSON now, so that a meta that exists can always be
        # written, and reads back equal (tuples -> lists, numpy scalars rejected early).
        try:
            text = json.dumps(_thaw_json(self.extra), allow_nan=False, sort_keys=True)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"TrialMeta.extra must be JSON-serialisable (no NaN/inf, str keys): {exc}") from None
        object.__setattr__(self, "extra", _freeze_json(json.loads(text)))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (the form stored in files and manifests)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["extra"] = _thaw_json(self.extra)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrialMeta:
        """Inverse of :meth:`to_dict`; unknown or missing keys raise ``ValueError``.

        A former key (:data:`FORMER_KEYS`: ``"source"``, written before issue 43) reads as its
        field (``origin``); both present with different values raise ``ValueError`` naming both.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"TrialMeta must be read from a mapping, got {type(data).__name__}")
        data, former = _renamed(data)
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(data) - set(names))
        if unknown:
            raise ValueError(f"TrialMeta has no field(s) {unknown}")
        missing = [n for n in names if n not in data and n != "extra"]
        if missing:
            raise ValueError(f"TrialMeta is missing field(s) {missing}")
        try:
            return cls(**{n: data[n] for n in names if n in data})
        except ValueError as exc:
            if not former:
                raise
            # the file holds the former key: say so, or the field named would not be found in it
            was = ", ".join(f"{FORMER_KEYS[k]} under its former key {k!r}" for k in former)
            raise ValueError(f"{exc} (read {was})") from None

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), allow_nan=False, sort_keys=True)

    @classmethod
    def from_json(cls, text: str | bytes) -> TrialMeta:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"TrialMeta JSON is malformed: {exc}") from None
        return cls.from_dict(data)


def _renamed(data: Mapping[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """``data`` with each former key (:data:`FORMER_KEYS`) under its field's name, and the former
    keys it held."""
    out = dict(data)
    former = [k for k in FORMER_KEYS if k in out]
    for key in former:
        name = FORMER_KEYS[key]
        value = out.pop(key)
        if name in out and out[name] != value:
            raise ValueError(
                f"TrialMeta.{name} is stored twice, as {name!r} ({out[name]!r}) and under its former key {key!r} "
                f"({value!r}), with different values"
            )
        out[name] = value
    return out, former


#: How far a trial's median time step may lie from ``meta.dt`` (a factor either way): a recording's steps jitter and
#: it has gaps (the lab's UR5 CSVs: the median step is 8 ms in all 18 trials), another rate is a factor of 2 or more.
CLOCK_TOLERANCE = 1.25


def time_gaps(time: ArrayLike, dt: float, factor: float = GAP_FACTOR) -> np.ndarray:
    """Indices k where ``time[k+1] − time[k] > factor · dt``: the samples after which data is missing.

    Parameters
    ----------
    time : array, shape (T,), s
    dt : nominal period in s
    factor : how many periods make a gap (default :data:`GAP_FACTOR`)

    Returns
    -------
    ndarray of int64, shape (G,)
    """
    steps = np.diff(np.asarray(time, dtype=np.float64))
    return np.flatnonzero(steps > factor * float(dt)).astype(np.int64)


def _float_array(value: ArrayLike, name: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"Trial.{name} must be numeric: {exc}") from None
    arr.setflags(write=False)
    return arr


def _check_shape(arr: np.ndarray, name: str, expected: tuple[int | str, ...]) -> None:
    ok = arr.ndim == len(expected) and all(isinstance(e, str) or a == e for a, e in zip(arr.shape, expected))
    if not ok:
        shown = "(" + ", ".join(str(e) for e in expected) + ("," if len(expected) == 1 else "") + ")"
        raise ValueError(f"Trial.{name} has shape {arr.shape}, expected {shown}")


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        bad = int(np.argwhere(~np.isfinite(arr))[0][0])
        raise ValueError(f"Trial.{name} has non-finite values (first at tick {bad})")


# Fields shaped like the pose, in the order a trial file (data.trial_file) writes them.
_TD_REQUIRED = ("velocity", "wrench", "reference")
_TD_OPTIONAL = ("intent", "effort_h", "effort_r")


@dataclass(frozen=True, eq=False)
class Trial:
    """A logged trial: T ticks of the d controlled DOFs.

    Attributes
    ----------
    meta : TrialMeta
    time : ndarray, shape (T,)
        Time stamps in s, strictly increasing; 0 at the first tick for logged and
        loaded trials.
    pose : ndarray, shape (T, d)
        Measured end-effector position in m.
    velocity : ndarray, shape (T, d)
        Measured end-effector velocity in m/s.
    wrench : ndarray, shape (T, d)
        Interaction force measured at the sensor in N.
    reference : ndarray, shape (T, d)
        Nominal reference y_ref,r from the motion planner in m.
    prediction : ndarray, shape (T, H, d), optional
        Predicted human intent in use at tick k for ticks k+1 … k+H, in m. NaN rows
        mark ticks without a prediction (e.g. before the history window is full).
    intent : ndarray, shape (T, d), optional
        The operator's true desired position in m (simulation only).
    effort_h, effort_r : ndarray, shape (T, d), optional
        Human and robot efforts applied, in N.
    fault : ndarray of int64, shape (T,), optional
        Fault flags per tick (0 = none; :class:`coassist.interfaces.Fault`).
    joints : ndarray, shape (T, J), optional
        Measured joint positions q in rad (arm worlds: MuJoCo UR5, the real UR5).
    joint_velocity : ndarray, shape (T, J), optional
        Joint velocity command q̇ sent at each tick in rad/s (after the safety layer).
    alpha : ndarray, shape (T,), optional
        The cooperative game's α each tick's command was computed with, in [0, 1] (the
        arbitration's online one; constant for the plain game). Recorded by every loop
        (simulated and on an arm) since 2026-12-06; IMP and MG have none.

    Notes
    -----
    Equality is identity (``eq=False``): numpy arrays have no single truth value. Use
    :meth:`equals` for an exact, bit-for-bit comparison.
    """

    meta: TrialMeta
    time: np.ndarray
    pose: np.ndarray
    velocity: np.ndarray
    wrench: np.ndarray
    reference: np.ndarray
    prediction: np.ndarray | None = None
    intent: np.ndarray | None = None
    effort_h: np.ndarray | None = None
    effort_r: np.ndarray | None = None
    fault: np.ndarray | None = None
    joints: np.ndarray | None = None
    joint_velocity: np.ndarray | None = None
    alpha: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.meta, TrialMeta):
            raise ValueError(f"Trial.meta must be a TrialMeta, got {type(self.meta).__name__}")
        set_ = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)

        time = _float_array(self.time, "time")
        if time.ndim != 1 or time.shape[0] < 1:
            raise ValueError(f"Trial.time has shape {time.shape}, expected (T,) with T >= 1")
        _check_finite(time, "time")
        steps = np.diff(time)
        if np.any(steps <= 0.0):
            k = int(np.argmax(steps <= 0.0))
            raise ValueError(
                f"Trial.time must be strictly increasing; time[{k + 1}] = {time[k + 1]!r} <= time[{k}] = {time[k]!r}"
            )
        if steps.size >= 2:
            # the clock and the period must agree: windows, the plant and every rate are built on meta.dt (the median
            # step: a recording's jitter and gaps move it little)
            median = float(np.median(steps))
            if not 1.0 / CLOCK_TOLERANCE <= median / self.meta.dt <= CLOCK_TOLERANCE:
                raise ValueError(
                    f"Trial.time steps by {median:.6g} s (the median of its steps) but meta.dt is {self.meta.dt:g} s: "
                    f"a trial of {1.0 / median:.4g} Hz named {1.0 / self.meta.dt:.4g} Hz (its clock in other units, or "
                    "another rate's meta?)"
                )
        set_("time", time)
        n = time.shape[0]

        pose = _float_array(self.pose, "pose")
        if pose.ndim != 2 or pose.shape[0] != n or not 1 <= pose.shape[1] <= MAX_DOF:
            raise ValueError(f"Trial.pose has shape {pose.shape}, expected ({n}, d) with 1 <= d <= {MAX_DOF}")
        _check_finite(pose, "pose")
        set_("pose", pose)
        d = pose.shape[1]

        for name in _TD_REQUIRED + _TD_OPTIONAL:
            value = getattr(self, name)
            if value is None:
                if name in _TD_REQUIRED:
                    raise ValueError(f"Trial.{name} is required")
                continue
            arr = _float_array(value, name)
            _check_shape(arr, name, (n, d))
            _check_finite(arr, name)
            set_(name, arr)

        if self.prediction is not None:
            pred = _float_array(self.prediction, "prediction")
            _check_shape(pred, "prediction", (n, "H", d))
            if pred.shape[1] < 1:
                raise ValueError(f"Trial.prediction has shape {pred.shape}, expected ({n}, H, {d}) with H >= 1")
            # NaN marks "no prediction at this tick"; infinities are always a bug.
            if np.any(np.isinf(pred)):
                raise ValueError("Trial.prediction has infinite values")
            set_("prediction", pred)

        if self.fault is not None:
            raw = np.array(self.fault, copy=True)
            if raw.dtype.kind == "f":
                if not np.all(np.isfinite(raw)) or np.any(raw != np.round(raw)):
                    raise ValueError("Trial.fault must hold integer flags")
            elif raw.dtype.kind not in "biu":
                raise ValueError(f"Trial.fault must hold integer flags, got dtype {raw.dtype}")
            fault = raw.astype(np.int64)
            _check_shape(fault, "fault", (n,))
            fault.setflags(write=False)
            set_("fault", fault)

        n_joints = None
        for name in ("joints", "joint_velocity"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = _float_array(value, name)
            if arr.ndim != 2 or arr.shape[0] != n or not 1 <= arr.shape[1] <= 12:
                raise ValueError(f"Trial.{name} has shape {arr.shape}, expected ({n}, J) with 1 <= J <= 12")
            if n_joints is not None and arr.shape[1] != n_joints:
                raise ValueError(
                    f"Trial.joints and Trial.joint_velocity have different joint counts ({n_joints}, {arr.shape[1]})"
                )
            n_joints = arr.shape[1]
            _check_finite(arr, name)
            set_(name, arr)

        if self.alpha is not None:
            alpha = _float_array(self.alpha, "alpha")
            _check_shape(alpha, "alpha", (n,))
            _check_finite(alpha, "alpha")
            if np.any((alpha < 0.0) | (alpha > 1.0)):
                k = int(np.argmax((alpha < 0.0) | (alpha > 1.0)))
                raise ValueError(f"Trial.alpha must lie in [0, 1]; alpha[{k}] = {float(alpha[k])!r}")
            set_("alpha", alpha)

    @property
    def n_samples(self) -> int:
        """Number of ticks T."""
        return int(self.time.shape[0])

    @property
    def n_dof(self) -> int:
        """Number of controlled DOFs d."""
        return int(self.pose.shape[1])

    @property
    def horizon(self) -> int | None:
        """Prediction horizon H in samples, or None without predictions."""
        return None if self.prediction is None else int(self.prediction.shape[1])

    @property
    def duration(self) -> float:
        """time[-1] − time[0], in s."""
        return float(self.time[-1] - self.time[0])

    def equals(self, other: object) -> bool:
        """Exact comparison: equal meta and bit-identical arrays (NaN payloads included)."""
        if not isinstance(other, Trial) or self.meta != other.meta:
            return False
        for f in fields(self):
            if f.name == "meta":
                continue
            a, b = getattr(self, f.name), getattr(other, f.name)
            if (a is None) != (b is None):
                return False
            if a is not None and (a.dtype != b.dtype or a.shape != b.shape or a.tobytes() != b.tobytes()):
                return False
        return True
