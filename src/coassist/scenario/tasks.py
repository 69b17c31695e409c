"""Tasks of the simulated experiments: nominal paths, the motion planner, obstacle and target.

A task (thesis §5.2.2) is a nominal path in the x-y plane from a start point to an
end point (the target), timed by the motion planner, plus a box obstacle placed at
random along the path that only the operator knows about.

Paths (sizes follow the real user-a recordings: x from −0.10 to 0.40 m at
y ≈ −0.615 m, in the UR5 base frame):

- ``linear``: a straight segment, 0.50 m (real: 0.50 m over 10 s);
- ``curved``: a half-sine arc bulging 0.15 m in +y, ≈0.61 m (real: 0.60 m over 10 s);
- ``sinusoidal``: one full sine period of amplitude 0.15 m, ≈0.80 m (real S path:
  0.87 m over 14 s);
- ``z``: a Z with rounded corners (0.40 m wide, 0.30 m tall, ≈1.2 m), the new
  trajectory of the transfer experiment (thesis Fig. 5.9).

Motion planner: minimum-jerk (quintic) time scaling along the arc length s::

    τ = (t − t₀)/T ∈ [0, 1],   s(t) = L (10τ³ − 15τ⁴ + 6τ⁵)
    ṡ(t) = (L/T)(30τ² − 60τ³ + 30τ⁴),   peak ṡ = 1.875 L/T at τ = ½

so speed and acceleration are zero at both ends. Before t₀ the reference holds the
start, after t₀ + T it holds the end point. The reference output is
y_ref,r = [x, y, ẋ, ẏ] with velocity = ṡ · unit tangent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from coassist._checks import check_positive_scalar
from coassist.registry import Registry
from coassist.scenario.seeds import task_rng

#: Start and end of the real recordings (user-a), m, UR5 base frame.
START = (-0.10, -0.615)
END = (0.40, -0.615)

#: The real references start moving about 0.9 s after the recording starts.
START_DELAY = 0.9

_N_POINTS = 2001  # dense polyline samples: < 1 mm between points on every path


def quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk profile σ(τ), σ'(τ), σ''(τ) on τ clipped to [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    t2 = tau * tau
    t3 = t2 * tau
    sigma = t3 * (10.0 - 15.0 * tau + 6.0 * t2)
    dsigma = 30.0 * t2 * (1.0 - 2.0 * tau + t2)
    ddsigma = 60.0 * tau * (1.0 - 3.0 * tau + 2.0 * t2)
    return sigma, dsigma, ddsigma


@dataclass(frozen=True, eq=False)
class NominalPath:
    """A planar path as a dense polyline, parametrised by arc length.

    Parameters
    ----------
    name : the path kind.
    points : (P, 2) positions [m], P ≥ 2, first = start, last = end; consecutive
        points must differ (the arc length must increase).

    Attributes
    ----------
    arc : (P,) cumulative arc length [m], arc[0] = 0.
    length : total length L [m].
    tangents : (P, 2) unit tangents (central differences).
    """

    name: str
    points: np.ndarray
    arc: np.ndarray = field(init=False, repr=False)
    length: float = field(init=False)
    tangents: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        pts = np.array(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
            raise ValueError(f"NominalPath.points must have shape (P >= 2, 2), got {pts.shape}")
        if not np.isfinite(pts).all():
            raise ValueError("NominalPath.points must be finite")
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        if np.any(seg <= 0.0):
            raise ValueError("NominalPath.points has repeated consecutive points (arc length must increase)")
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        tan = np.gradient(pts, arc, axis=0)
        norm = np.linalg.norm(tan, axis=1, keepdims=True)
        turn = norm[:, 0] == 0.0  # a plan that turns straight back: no central direction there
        if turn.any():  # the incoming segment's (nothing changes where the gradient is not zero)
            k = np.flatnonzero(turn)
            tan[k] = (pts[k] - pts[k - 1]) / seg[k - 1, None]
            norm[k] = 1.0
        tan /= norm
        for name, value in (("points", pts), ("arc", arc), ("tangents", tan)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "length", float(arc[-1]))

    @property
    def start(self) -> np.ndarray:
        return self.points[0]

    @property
    def end(self) -> np.ndarray:
        return self.points[-1]

    def position(self, s: np.ndarray | float) -> np.ndarray:
        """Position(s) at arc length s [m] (clipped to [0, L]); shape s.shape + (2,)."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        return np.stack([np.interp(s, self.arc, self.points[:, 0]), np.interp(s, self.arc, self.points[:, 1])], axis=-1)

    def tangent(self, s: np.ndarray | float) -> np.ndarray:
        """Unit tangent(s) at arc length s; shape s.shape + (2,)."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        t = np.stack(
            [np.interp(s, self.arc, self.tangents[:, 0]), np.interp(s, self.arc, self.tangents[:, 1])], axis=-1
        )
        return t / np.linalg.norm(t, axis=-1, keepdims=True)

    def normal(self, s: np.ndarray | float) -> np.ndarray:
        """Unit left normal (tangent turned +90°) at arc length s."""
        t = self.tangent(s)
        return np.stack([-t[..., 1], t[..., 0]], axis=-1)


def _smooth_corners(corners: np.ndarray, radius: float, n: int) -> np.ndarray:
    """Polyline through ``corners`` resampled to n points, corners rounded by a moving average.

    The average over a window of arc length 2·radius (ends padded with the end
    points, so start and end stay put) turns each corner into a smooth curve.
    """
    seg = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.linspace(0.0, arc[-1], n)
    pts = np.stack([np.interp(s, arc, corners[:, 0]), np.interp(s, arc, corners[:, 1])], axis=1)
    half = max(1, int(round(radius / (arc[-1] / (n - 1)))))
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    out = np.empty_like(pts)
    for j in range(2):
        padded = np.concatenate([np.full(half, pts[0, j]), pts[:, j], np.full(half, pts[-1, j])])
        # Two passes of a box filter: a triangular window, whose result has a continuous tangent.
        once = np.convolve(padded, kernel, mode="same")
        padded2 = np.concatenate([np.full(half, pts[0, j]), once[half:-half], np.full(half, pts[-1, j])])
        out[:, j] = np.convolve(padded2, kernel, mode="same")[half:-half]
    out[0], out[-1] = corners[0], corners[-1]
    return out


def _sideways(offset: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """A path that runs along the chord start → end, ``offset(u)`` [m] to its left at the chord's
    fraction u ∈ [0, 1]: p(u) = p0 + u (p1 − p0) + offset(u) n, n the chord's left normal."""

    def points(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        u = np.linspace(0.0, 1.0, _N_POINTS)
        chord = p1 - p0
        along = chord / float(np.linalg.norm(chord))
        left = np.array([-along[1], along[0]])
        return p0 + u[:, None] * chord + offset(u)[:, None] * left

    return points


def _z_points(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """The Z: top stroke left→right, diagonal back, bottom stroke left→right, corners rounded (4 cm)."""
    chord = p1 - p0
    along = chord / float(np.linalg.norm(chord))
    left = np.array([-along[1], along[0]])
    a = p0 + 0.05 * along
    b = p1 - 0.05 * along
    corners = np.array([a + 0.15 * left, b + 0.15 * left, a - 0.15 * left, b - 0.15 * left])
    return _smooth_corners(corners, 0.04, _N_POINTS)


@dataclass(frozen=True)
class TaskEntry:
    """One path kind of :data:`TASKS`.

    points : ``points(start, end)`` → (P, 2) polyline [m] from ``start`` to ``end`` (each (2,) [m],
        distinct), consecutive points distinct: the :class:`NominalPath`'s points.
    motion_time : planned motion time T [s] of the minimum-jerk timing (:class:`MotionPlanner`), > 0.
    summary : what the path is, a phrase.
    """

    points: Callable[[np.ndarray, np.ndarray], np.ndarray]
    motion_time: float
    summary: str

    def __post_init__(self) -> None:
        if not callable(self.points):
            raise ValueError(f"TaskEntry.points must be callable (start, end) -> (P, 2) points, got {self.points!r}")
        object.__setattr__(self, "motion_time", check_positive_scalar(self.motion_time, "TaskEntry.motion_time"))
        if not isinstance(self.summary, str) or not self.summary:
            raise ValueError(f"TaskEntry.summary must be a non-empty string, got {self.summary!r}")


#: Path kinds (module docstring): the three of the iterative experiments and the transfer one.
#: Motion times from the real references (linear and curved 10 s, the S path 14 s); the Z keeps
#: the same mean speed (≈0.06 m/s).
TASKS: Registry[TaskEntry] = Registry(
    "task",
    {
        "linear": TaskEntry(_sideways(np.zeros_like), 10.0, "a straight segment, 0.50 m"),
        "curved": TaskEntry(
            _sideways(lambda u: 0.15 * np.sin(np.pi * u)), 10.0, "a half-sine arc bulging 0.15 m to the left"
        ),
        "sinusoidal": TaskEntry(
            _sideways(lambda u: -0.15 * np.sin(2.0 * np.pi * u)), 14.0, "one sine period of amplitude 0.15 m"
        ),
        "z": TaskEntry(_z_points, 20.0, "a Z with rounded corners, 0.40 m wide and 0.30 m tall"),
    },
    entry_type=TaskEntry,
)
#: The built-in kinds' names (a kind registered later is in :data:`TASKS`, not here).
TASK_KINDS: tuple[str, ...] = tuple(TASKS)


def nominal_path(kind: str, start: tuple[float, float] = START, end: tuple[float, float] = END) -> NominalPath:
    """The nominal path of ``kind`` (one of :data:`TASKS`) from ``start`` to ``end`` [m].

    linear, curved and sinusoidal run from start to end; the Z spans the same x range
    (shrunk by 0.05 m each side), its top stroke at y_start + 0.15 m and its bottom
    stroke at y_start − 0.15 m.
    """
    if kind not in TASKS:
        raise ValueError(f"task kind must be one of {tuple(TASKS)}, got {kind!r}")
    p0, p1 = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    if float(np.linalg.norm(p1 - p0)) <= 0.0:
        raise ValueError("start and end must differ")
    return NominalPath(kind, TASKS[kind].points(p0, p1))


@dataclass(frozen=True, eq=False)
class MotionPlanner:
    """Minimum-jerk timing of a path: the nominal reference y_ref,r(t) (module docstring).

    Parameters
    ----------
    path : the nominal path.
    duration : motion time T [s], > 0.
    start_delay : t₀ [s], ≥ 0: the reference holds the start until then.
    """

    path: NominalPath
    duration: float
    start_delay: float = START_DELAY

    def __post_init__(self) -> None:
        if not isinstance(self.path, NominalPath):
            raise ValueError(f"MotionPlanner.path must be a NominalPath, got {type(self.path).__name__}")
        object.__setattr__(self, "duration", check_positive_scalar(self.duration, "MotionPlanner.duration"))
        d = float(self.start_delay)
        if not (np.isfinite(d) and d >= 0.0):
            raise ValueError(f"MotionPlanner.start_delay must be a finite number >= 0 [s], got {self.start_delay!r}")
        object.__setattr__(self, "start_delay", d)

    @property
    def end_time(self) -> float:
        """t₀ + T [s]: the reference holds the end point from then on."""
        return self.start_delay + self.duration

    @property
    def peak_speed(self) -> float:
        """1.875 L / T [m/s], the closed-form peak of the quintic profile."""
        return 1.875 * self.path.length / self.duration

    def arc_length(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """s(t) [m] and ṡ(t) [m/s]."""
        tau = (np.asarray(t, dtype=float) - self.start_delay) / self.duration
        sigma, dsigma, _ = quintic(tau)
        inside = (tau > 0.0) & (tau < 1.0)
        return self.path.length * sigma, np.where(inside, dsigma * (self.path.length / self.duration), 0.0)

    def reference(self, t: np.ndarray | float) -> np.ndarray:
        """y_ref,r(t) = [x, y, ẋ, ẏ] [m, m/s]; shape t.shape + (4,)."""
        s, sdot = self.arc_length(t)
        pos = self.path.position(s)
        vel = self.path.tangent(s) * sdot[..., None]
        return np.concatenate([pos, vel], axis=-1)

    def grid(self, n: int, dt: float) -> np.ndarray:
        """The reference at t = k·dt for k = 0…n−1, shape (n, 4); holds the end point after the end."""
        return self.reference(np.arange(int(n)) * float(dt))

    def horizon_rows(self, k: int, horizon: int, dt: float) -> np.ndarray:
        """Rows k+1 … k+horizon of :meth:`grid`, shape (horizon, 4): what the controller reads at tick k."""
        return self.reference((k + 1 + np.arange(int(horizon))) * float(dt))


@dataclass(frozen=True)
class Box:
    """Axis-aligned box obstacle in the x-y plane: centre (2,) and size (2,) [m]."""

    center: tuple[float, float]
    size: tuple[float, float]

    def __post_init__(self) -> None:
        for name in ("center", "size"):
            value = np.asarray(getattr(self, name), dtype=float)
            if value.shape != (2,) or not np.isfinite(value).all():
                raise ValueError(f"Box.{name} must be 2 finite numbers [m], got {getattr(self, name)!r}")
            object.__setattr__(self, name, (float(value[0]), float(value[1])))
        if min(self.size) <= 0.0:
            raise ValueError(f"Box.size must be > 0 [m], got {self.size!r}")

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance [m] from points (..., 2) to the box surface (negative inside)."""
        q = np.abs(np.asarray(points, dtype=float) - np.asarray(self.center)) - 0.5 * np.asarray(self.size)
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        inside = np.minimum(np.max(q, axis=-1), 0.0)
        return outside + inside

    def to_dict(self) -> dict[str, list[float]]:
        return {"center": list(self.center), "size": list(self.size)}


@dataclass(frozen=True, eq=False)
class Task:
    """One task: the timed nominal path, the obstacle (operator-only) and the target (the end point).

    ``obstacle_arc`` is the arc length [m] of the path point the obstacle was placed at.
    """

    kind: str
    planner: MotionPlanner
    obstacle: Box
    obstacle_arc: float

    @property
    def path(self) -> NominalPath:
        return self.planner.path

    @property
    def start(self) -> np.ndarray:
        return self.planner.path.start

    @property
    def target(self) -> np.ndarray:
        return self.planner.path.end

    def to_extra(self) -> dict[str, Any]:
        """JSON-able description for TrialMeta.extra."""
        return {
            "task_kind": self.kind,
            "start": [float(v) for v in self.start],
            "target": [float(v) for v in self.target],
            "obstacle": self.obstacle.to_dict(),
            "obstacle_arc": self.obstacle_arc,
            "path_length": self.path.length,
            "motion_start": self.planner.start_delay,
            "motion_time": self.planner.duration,
        }


#: Obstacle size [m]: the same in every trial (thesis §5.2.2).
OBSTACLE_SIZE = (0.06, 0.06)
#: Range of the obstacle's position along the path, as a fraction of its length.
OBSTACLE_RANGE = (0.3, 0.7)
#: Obstacles by name: (size [m], range of its position along the path as fractions of its
#: length). "small" is the evaluation's box beside the shown path (§5.2.2). "large" is the
#: application's (§5.2.3): a real object midway between start and target with no path
#: shown, around which the person detours widely (8–12 cm from the nominal path against
#: 4–7 cm; user-a's recordings deviate up to 0.1 m, user-b's up to 0.5 m). It stays near
#: the middle so the detour has returned to the path before the target.
OBSTACLES = {"small": (OBSTACLE_SIZE, OBSTACLE_RANGE), "large": ((0.12, 0.12), (0.45, 0.55))}


def make_task(
    kind: str,
    rng: np.random.Generator,
    *,
    obstacle_size: tuple[float, float] = OBSTACLE_SIZE,
    obstacle_range: tuple[float, float] = OBSTACLE_RANGE,
    motion_time: float | None = None,
) -> Task:
    """A task of ``kind`` with the obstacle centred on the path at a uniformly random arc length.

    Positions where the path turns by more than 60° within ±6 cm are redrawn.

    Parameters
    ----------
    kind : one of :data:`TASK_KINDS`.
    rng : the generator that places the obstacle (pass one derived from the trial seed).
    obstacle_size : box size [m].
    obstacle_range : (lo, hi) fractions of the path length, 0 ≤ lo ≤ hi ≤ 1.
    motion_time : T [s]; default the kind's :attr:`TaskEntry.motion_time`.
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy Generator, got {type(rng).__name__}")
    lo, hi = (float(v) for v in obstacle_range)
    if not 0.0 <= lo <= hi <= 1.0:
        raise ValueError(f"obstacle_range must satisfy 0 <= lo <= hi <= 1, got {obstacle_range!r}")
    path = nominal_path(kind)
    planner = MotionPlanner(path, TASKS[kind].motion_time if motion_time is None else motion_time)
    # Redraw (up to 100 times, from the same generator) where the path turns by more
    # than 60° within ±6 cm: an operator cannot dodge a box sitting on a sharp corner
    # (the Z's) with a smooth sideways detour.
    for _ in range(100):
        s_obs = float(rng.uniform(lo, hi) * path.length)
        t_before, t_after = path.tangent(s_obs - 0.06), path.tangent(s_obs + 0.06)
        if float(np.dot(t_before, t_after)) >= 0.5:
            break
    center = path.position(s_obs)
    box = Box((float(center[0]), float(center[1])), tuple(obstacle_size))
    return Task(kind=kind, planner=planner, obstacle=box, obstacle_arc=s_obs)


#: [s] the planned motion times a person can follow (a reach of the thesis takes 10-20 s): a study plan's and the
#: browser page's bounds.
MOTION_TIME_RANGE = (0.5, 120.0)


def task_for_seed(kind: str, seed: int, *, obstacle: str = "small", motion_time: float | None = None) -> Task:
    """The task ``kind`` of trial seed ``seed`` in every world: the obstacle ``obstacle`` (a name of
    :data:`OBSTACLES`) placed from :func:`coassist.scenario.seeds.task_rng`."""
    if obstacle not in OBSTACLES:
        raise ValueError(f"obstacle must be one of {tuple(OBSTACLES)}, got {obstacle!r}")
    size, placement = OBSTACLES[obstacle]
    return make_task(kind, task_rng(seed), obstacle_size=size, obstacle_range=placement, motion_time=motion_time)
