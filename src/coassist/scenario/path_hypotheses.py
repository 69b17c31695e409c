"""Where the person wants the tool *now*, and the paths people take round the obstacles the robot is told of.

Two intent sources that read only what the robot measures (the last feature row: tool
position p, velocity v, wrench w) and what it is told (the nominal path, the obstacles,
the object's mass), with no trained network:

``present`` — the present estimate, extrapolated at constant velocity::

    p̂(k) = p + (w + m a + Ĉ v) / K̂          (the arm of eq. 4.1 solved for the intent)
    ŷ(k+i) = p̂(k) + i·dt·v                  i = 1 … H

``a`` is the tool's acceleration (dv/dt, low-pass filtered over ``accel_time``) and m the
carried object's mass: the sensor measures the hand force less m·a (coassist.scenario.objects),
so m·a puts back what accelerating the object took. K̂ and Ĉ are a typical arm's stiffness
and damping (:class:`ArmGuess`); an arm that is stiffer or delayed makes p̂ lag and shrink.

``paths`` — path hypotheses and a filter over them (issue 34): the person goes round each
known obstacle on one side, along the nominal path deformed by the detour model of
:func:`coassist.scenario.operator.deformed_path` (a shift of A·b(s) along the path's normal
at the obstacle; A = half the box plus the clearance c, b rising over the anticipation
distance a). One hypothesis per side and per shape (c, a) of a small grid around the
person's own shape (:class:`PersonShape`, fitted to a few calibration trials by
:func:`calibrate`). Every tick:

1. each hypothesis n gives the tool's phase on it, sₙ (the nearest point of the curve), and
   its present estimate of the intent, qₙ = curveₙ(sₙ + ℓₙ) with the lead
   ℓₙ = tₙ·(w + m a + Ĉ v)/K̂ along the curve's tangent tₙ;
2. **side.** Before the detour both sides' curves are the nominal path; the lateral offset of
   p̂ from it then is a bias b (the tool riding beside the path) and is learnt, with an
   exponential average over ``bias_time``, while the rows follow that shared path, and
   clipped to ±``bias_limit`` (a larger offset is a detour that starts early, not a bias).
   Once the mean-shape curves of the two sides are D ≥ ``divergence`` apart, the log-odds
   of the left side grow by
   κ·(z − b)·D/σ² per tick (z: p̂'s offset from their midpoint towards the left curve; the
   Gaussian log-likelihood ratio of the two curves, discounted by κ for the correlation of
   successive ticks); they start at the person's side preference;
3. **shape.** Each hypothesis accumulates κ·(rₙ − min r)/(2σ²), rₙ = ‖p̂ − b·n_o − qₙ‖², as its
   negative log-likelihood relative to its side's best, while its side's curves are apart;
4. **rows.** Once |log-odds| > ``decide``, the rows run along the likely shapes of the more
   likely side from their present estimates at the tool's speed along the curve,
   ŷ(k+i) = Σₙ wₙ curveₙ(sₙ + ℓₙ + i·dt·max(tₙ·v, 0)), wₙ ∝ the likelihoods of the
   :data:`MIXTURE` most likely shapes (those within a factor 100 of the best). While the two
   sides' rows over the horizon are more than ``divergence`` apart and the side is not
   decided, the rows are the present estimate's, p̂ + ``hedge_velocity``·i·dt·v (neither side,
   and never the nominal plan through the obstacle); before the detour, the (shared) nominal
   curve's. The rows cross-fade between the two over ``blend_time``, so the robot's effort
   never steps.

Without an obstacle in the way (none told, none the plan passes within half the person's largest
clearance of, or ``use_obstacles=False``) ``paths`` is ``present``. What the
robot is told comes from :class:`~coassist.interfaces.TrialContext` (``path``, ``obstacles``,
``object``); a person's shape from a calibration file (:func:`write_calibration`), whose
folder is given as the intent (``intent="<folder>"``: ``path-hypotheses.json``).

Ranges. Every field of :class:`PersonShape`, :class:`ArmGuess` and :class:`FilterSettings` lies
in the range a person (and a filter for people) can have, :data:`CALIBRATION_RANGES`, checked
when one is built, so a calibration file is checked where it is read: numbers only (the string
``"0.03"`` and ``true`` are refused), each field's error naming it. Within them no calibration made
the robot push more than 30 N harder than the worse of the robot with no prediction at all (the
nominal plan, the fallback of every unusable row) and with the default calibration
(tests/scenario/test_calibration_ranges.py fuzzes them; docs/precision.md, *A calibration is
bounded like a limit*, gives each bound's reason). The file carries the SHA-256 of its content
(:func:`coassist._io.write_hashed_json`): a hand edit is refused in one line.

The detour model is the simulated operator's own (the hypotheses are its family of paths):
in simulation the filter knows the form of every path an operator can take, not its shape
in a trial (each trial draws its clearance and anticipation, ``OperatorProfile.shape_jitter``).
How far real detours follow that family is unknown (docs/realism.md).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from coassist._checks import check_int, check_real, is_real_number
from coassist._io import read_hashed_json, write_hashed_json
from coassist.interfaces import TrialContext
from coassist.scenario.curve_search import CurveSearch, window_distances
from coassist.scenario.hand_force import HandForce
from coassist.scenario.operator import deformed_path
from coassist.scenario.tasks import Box, MotionPlanner, NominalPath, Task

__all__ = [
    "CALIBRATION_FILE",
    "CALIBRATION_RANGES",
    "ArmGuess",
    "FilterSettings",
    "PathHypothesesIntent",
    "PersonShape",
    "calibrate",
    "fit_detour",
    "read_calibration",
    "write_calibration",
]

#: The most shapes whose rows a decided side mixes (module docstring, step 4).
MIXTURE = 4
#: The control period [s] the filter's per-tick constants (κ) were chosen at: at another rate κ is
#: scaled by dt / REFERENCE_DT, so the evidence gathered per second is the same.
REFERENCE_DT = 0.008
#: The share of ``decide`` the person's side preference may give the log-odds before any evidence: a
#: preference alone never decides the side (a person may not detour at all).
PRIOR_SHARE = 0.9
#: The calibration file of a ``paths`` source folder.
CALIBRATION_FILE = "path-hypotheses.json"
_FORMAT = "coassist-path-hypotheses-1"

#: The closed range [lo, hi] of every calibration field (module docstring, *Ranges*; the reasons in
#: docs/precision.md, section 5): ``"<Class>.<field>"`` → (lo, hi). ``PersonShape.left_preference`` is the open
#: (0, 1); ``FilterSettings.shape_grid`` holds 1 … :data:`MAX_SHAPE_GRID` factors, each in its range,
#: with 1 between the smallest and the largest.
CALIBRATION_RANGES: dict[str, tuple[float, float]] = {
    # --- the person (what people have)
    # people keep 1–5 cm from a box (the simulated population), the fit's grid spans 5 mm–8 cm; closer
    # than 2 mm is touching it, farther than 8 cm is another path, which the filter would push toward
    "PersonShape.clearance": (0.002, 0.08),
    # the path over which a person moves aside: 5–20 cm simulated, the fit's grid 3–30 cm
    "PersonShape.anticipation": (0.02, 0.3),
    "PersonShape.left_preference": (0.0, 1.0),
    "PersonShape.trials": (0, 10_000),
    # arm stiffness: the simulated users span 460–1300 N/m, the browser's hand is 400 N/m (the most
    # compliant arm coassist models); a guess below it inflates the present estimate's lead
    # (w + m a + Ĉ v)/K̂ (at 150 N/m the robot pushed 38 N more than with no prediction at all on the
    # fuzz's Z); 2000 N/m is 1.5× the stiffest simulated arm
    "ArmGuess.stiffness": (400.0, 2000.0),
    # damping: simulated 5.9–10 N·s/m, the browser's hand 40 N·s/m; 0 leaves the velocity term out
    "ArmGuess.damping": (0.0, 40.0),
    # --- the filter's constants, chosen on validation seeds (docs/precision.md): a calibration may move
    # each within about ¼× … 5× of its validated value (or its natural limits), not by orders of magnitude
    "FilterSettings.sigma": (0.0005, 0.01),
    "FilterSettings.kappa": (0.05, 1.0),
    "FilterSettings.decide": (0.25, 5.0),
    # "apart" must stay well under the smallest detour (half the 6 cm box plus a clearance)
    "FilterSettings.divergence": (1e-4, 0.005),
    "FilterSettings.bias_time": (0.1, 2.0),
    # a larger offset beside the path is a detour starting early, not a bias
    "FilterSettings.bias_limit": (0.0, 0.01),
    # the acceleration estimate's lag: the carried object's m·a a tenth of a second late is a wrong force
    "FilterSettings.accel_time": (0.0, 0.1),
    # above 0: the cross-fade is what keeps the robot's effort from stepping when the rows change
    "FilterSettings.blend_time": (0.02, 0.5),
    "FilterSettings.hedge_velocity": (0.0, 1.0),
    # at least what a tool at the point-mass world's 1 m/s limit moves in a 125 Hz tick (8 mm); at most
    # 2.5× the default, so a tick's search stays within 2.5× its compute (a 1e300 window searched every
    # whole curve every tick: 7× the compute per trial)
    "FilterSettings.search_window": (0.01, 0.05),
    "FilterSettings.evidence_rate": (5.0, 150.0),
    # factors on the person's clearance and anticipation: half to twice their own
    "FilterSettings.shape_grid": (0.5, 2.0),
}
#: The most factors in ``FilterSettings.shape_grid``: 9 × 9 shapes per side, 162 curves (3.2× the default's
#: 50; 10 000 factors asked for 2·10⁸ curves and crashed).
MAX_SHAPE_GRID = 9


def _ranged(value: object, name: str) -> float:
    """``value`` as a float if it is a number (not a string or a bool) in ``CALIBRATION_RANGES[name]``."""
    if not is_real_number(value):
        raise ValueError(f"{name} must be a number, got {value!r}")
    lo, hi = CALIBRATION_RANGES[name]
    return check_real(value, name, lo, hi)


@dataclass(frozen=True)
class PersonShape:
    """How one person goes round an obstacle: clearance c [m] kept from it, anticipation a [m] of
    path over which they move aside, and the probability they pass on the left of the path
    (``left_preference`` ∈ (0, 1)); ``trials``: how many calibration trials it was fitted to (0: a
    guess)."""

    clearance: float = 0.025
    anticipation: float = 0.06
    left_preference: float = 0.5
    trials: int = 0

    def __post_init__(self) -> None:
        for name in ("clearance", "anticipation"):
            object.__setattr__(self, name, _ranged(getattr(self, name), f"PersonShape.{name}"))
        lp = _ranged(self.left_preference, "PersonShape.left_preference")
        if not 0.0 < lp < 1.0:
            raise ValueError(f"PersonShape.left_preference must be strictly between 0 and 1, got {lp!r}")
        object.__setattr__(self, "left_preference", lp)
        lo, hi = CALIBRATION_RANGES["PersonShape.trials"]
        object.__setattr__(self, "trials", check_int(self.trials, "PersonShape.trials", int(lo), int(hi)))


@dataclass(frozen=True)
class ArmGuess:
    """The arm the present estimate assumes (eq. 4.1): stiffness K̂ [N/m] and damping Ĉ [N·s/m].

    The defaults are the simulated author's relaxed-to-mid stiffness and damping
    (coassist.scenario.operator.AUTHOR: 550–1300 N/m, 10 N·s/m); the ranges a person's arm can
    have are in :data:`CALIBRATION_RANGES`."""

    stiffness: float = 800.0
    damping: float = 10.0

    def __post_init__(self) -> None:
        for name in ("stiffness", "damping"):
            object.__setattr__(self, name, _ranged(getattr(self, name), f"ArmGuess.{name}"))


@dataclass(frozen=True)
class FilterSettings:
    """The filter's constants (module docstring), chosen on validation seeds (docs/precision.md).

    sigma : σ [m], the present estimate's noise in the likelihoods.
    kappa : κ ∈ (0, 1], the discount for the correlation of successive ticks.
    decide : the log-odds of a side at which the rows follow it.
    divergence : [m] the distance at which two curves (or two sides' rows) count as apart.
    bias_time : [s] the averaging time of the lateral bias before the detour.
    bias_limit : [m] the largest lateral bias learnt.
    accel_time : [s] the low-pass time of the acceleration estimate.
    blend_time : [s] the cross-fade between the present estimate's rows and a curve's (0: a switch).
    hedge_velocity : while the sides disagree, the rows are p̂ + hedge_velocity·i·dt·v: 1 extrapolates
        the tool's velocity, 0 holds the present estimate (no push along the old direction).
    search_window : [m] of each curve searched for the tool's nearest point, either side of the last
        one (a tool moves < 1 mm per tick; the whole curve is searched when it is longer than the path).
    evidence_rate : [1/s] the most the side's log-odds may move per second (per tick: evidence_rate·dt),
        so that no tick or two decide the side alone.
    shape_grid : factors on the person's clearance and anticipation, one hypothesis per pair: 1 …
        :data:`MAX_SHAPE_GRID` distinct, increasing factors with 1 between the smallest and the largest
        (the person's own shape among the hypotheses' span).

    Each field lies in its :data:`CALIBRATION_RANGES` range.

    σ, κ, decide and the times were chosen at 125 Hz; κ is scaled by dt / 0.008 s at other rates
    (:data:`REFERENCE_DT`), so the evidence per second is the same.
    """

    sigma: float = 0.002
    kappa: float = 0.2
    decide: float = 1.0
    divergence: float = 0.0005
    bias_time: float = 0.4
    bias_limit: float = 0.005
    accel_time: float = 0.02
    blend_time: float = 0.1
    hedge_velocity: float = 0.5
    search_window: float = 0.02
    evidence_rate: float = 30.0
    shape_grid: tuple[float, ...] = (0.6, 0.8, 1.0, 1.25, 1.6)

    def __post_init__(self) -> None:
        for name in (
            "sigma",
            "kappa",
            "decide",
            "divergence",
            "bias_time",
            "bias_limit",
            "accel_time",
            "blend_time",
            "hedge_velocity",
            "search_window",
            "evidence_rate",
        ):
            object.__setattr__(self, name, _ranged(getattr(self, name), f"FilterSettings.{name}"))
        given = self.shape_grid
        if not isinstance(given, (list, tuple, np.ndarray)) or np.ndim(given) != 1:
            raise ValueError(f"FilterSettings.shape_grid must be a list of factors, got {given!r}")
        if not 1 <= len(given) <= MAX_SHAPE_GRID:
            raise ValueError(f"FilterSettings.shape_grid must hold 1 to {MAX_SHAPE_GRID} factors, got {len(given)}")
        grid = tuple(_ranged(g, "FilterSettings.shape_grid") for g in given)
        if list(grid) != sorted(set(grid)):
            raise ValueError(f"FilterSettings.shape_grid must be distinct factors in increasing order, got {given!r}")
        if not grid[0] <= 1.0 <= grid[-1]:
            raise ValueError(
                f"FilterSettings.shape_grid must span the person's own shape (smallest <= 1 <= largest), got {given!r}"
            )
        object.__setattr__(self, "shape_grid", grid)


def _scene_task(path: np.ndarray, obstacle: tuple[Sequence[float], Sequence[float]]) -> Task:
    """A :class:`Task` for :func:`deformed_path` from what the robot is told: the nominal path's
    polyline and one box (centre, size); the obstacle's arc length is where the path passes
    nearest its centre. The timing is not used."""
    pts = np.asarray(path, dtype=float)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 0.0])
    nominal = NominalPath("told", pts[keep])
    box = Box(tuple(obstacle[0]), tuple(obstacle[1]))  # type: ignore[arg-type]
    arc = float(nominal.arc[int(np.argmin(np.linalg.norm(nominal.points - np.asarray(box.center), axis=1)))])
    return Task(kind="told", planner=MotionPlanner(nominal, 1.0, 0.0), obstacle=box, obstacle_arc=arc)


class _Hypotheses:
    """The curves of one trial: (N, P, 2) points on the nominal path's samples, their arc
    lengths (N, P) and unit tangents (N, P, 2); sides (N,); the mean shape's index per side."""

    def __init__(self, task: Task, shape: PersonShape, grid: tuple[float, ...]) -> None:
        curves, sides, shapes = [], [], []
        for side in (1, -1):
            for gc in grid:
                for ga in grid:
                    pts, _, taken = deformed_path(task, side, shape.clearance * gc, shape.anticipation * ga)
                    curves.append(pts)
                    sides.append(taken)
                    shapes.append((gc, ga))
        self.points = np.stack(curves)
        # the x and y of every point, flat (curve n's point i at n·P + i): the per-tick search gathers
        # with np.take, several times cheaper than fancy-indexing the (N, P, 2) array
        self.flat_x = np.ascontiguousarray(self.points[:, :, 0]).ravel()
        self.flat_y = np.ascontiguousarray(self.points[:, :, 1]).ravel()
        seg = np.linalg.norm(np.diff(self.points, axis=1), axis=2)
        self.arc = np.concatenate([np.zeros((len(curves), 1)), np.cumsum(seg, axis=1)], axis=1)
        tan = np.gradient(self.points, axis=1)
        self.tangents = tan / np.linalg.norm(tan, axis=2, keepdims=True)
        self.sides = np.asarray(sides)
        n, p = self.points.shape[:2]
        self.row_start = np.arange(n) * p
        self.flat_points, self.flat_tangents = self.points.reshape(n * p, 2), self.tangents.reshape(n * p, 2)
        self.flat_arc = self.arc.ravel()
        self.search = CurveSearch(self.flat_x, self.flat_y, n, p)  # the phase search's tables, per window width
        self.on_side = (np.flatnonzero(self.sides == 1), np.flatnonzero(self.sides == -1))  # curves per side
        # each side's curves as a slice where they are one run (always but at a sharp corner): a view, not a copy
        self.side_runs: tuple[slice | np.ndarray, ...] = tuple(
            slice(int(on[0]), int(on[-1]) + 1) if on.size and on[-1] - on[0] + 1 == on.size else on
            for on in self.on_side
        )
        self.n_o = task.path.normal(task.obstacle_arc)
        mid = grid.index(1.0) if 1.0 in grid else len(grid) // 2
        centre = mid * len(grid) + mid
        self.centre = {1: centre, -1: len(grid) ** 2 + centre}
        # at a sharp corner a side may be impossible (deformed_path goes round the other way)
        self.centre = {s: i if self.sides[i] == s else self.centre[-s] for s, i in self.centre.items()}
        self.step = float(task.path.length) / (self.points.shape[1] - 1)
        # where the curves part: outside [first, last] every curve is the nominal path, sample for sample
        apart = np.flatnonzero(np.any(self.points != self.points[:1], axis=(0, 2)))
        self.first_apart: int = int(apart[0]) if apart.size else self.points.shape[1]
        self.last_apart: int = int(apart[-1]) if apart.size else -1

    def at(self, n: int, s: np.ndarray) -> np.ndarray:
        """Points of curve n at its arc lengths s (clipped to the curve)."""
        arc, n0 = self.arc[n], n * self.points.shape[1]
        out = np.empty(np.shape(s) + (2,))
        out[..., 0] = np.interp(s, arc, self.flat_x[n0 : n0 + arc.size])
        out[..., 1] = np.interp(s, arc, self.flat_y[n0 : n0 + arc.size])
        return out


class PathHypothesesIntent:
    """The ``present`` and ``paths`` intent sources (module docstring): an
    :class:`~coassist.interfaces.IntentSource` with state between ticks (one per trial).

    Parameters
    ----------
    horizon : rows predicted.
    shapes : person name (TrialContext.user) → :class:`PersonShape`; a person not in it gets ``default``.
    default : the shape of a person nobody calibrated.
    arm : the arm of the present estimate.
    settings : the filter's constants.
    use_obstacles : False: ``present`` (never reads the obstacles).
    extrapolation : the share e ∈ [0, 1] of the tool's velocity the present estimate's rows carry
        where no obstacle is told: ŷ(k+i) = p̂(k) + e·i·dt·v (1: ``present``; 0: ``present-held``, the
        estimate held over the horizon; 0.5: ``present-half``).
    model_id : what trials record as the source (default ``"paths"`` or ``"present"``).
    """

    history = 1
    #: One curve stands for all where they coincide (:meth:`_shared`); False: the whole filter every tick
    #: (the same rows to rounding: tests/scenario/test_path_hypotheses.py).
    shared_fast_path = True

    def __init__(
        self,
        horizon: int = 50,
        *,
        shapes: Mapping[str, PersonShape] | None = None,
        default: PersonShape | None = None,
        arm: ArmGuess | None = None,
        settings: FilterSettings | None = None,
        use_obstacles: bool = True,
        extrapolation: float = 1.0,
        model_id: str | None = None,
    ) -> None:
        self.horizon = check_int(horizon, "PathHypothesesIntent.horizon", 1)
        self.extrapolation = check_real(extrapolation, "PathHypothesesIntent.extrapolation", 0.0, 1.0)
        self.shapes = dict(shapes or {})
        for name, shape in self.shapes.items():
            if not isinstance(shape, PersonShape):
                raise ValueError(
                    f"PathHypothesesIntent.shapes[{name!r}] must be a PersonShape, got {type(shape).__name__}"
                )
        self.default = PersonShape() if default is None else default
        self.arm = ArmGuess() if arm is None else arm
        self.settings = FilterSettings() if settings is None else settings
        self.use_obstacles = bool(use_obstacles)
        self.model_id = model_id or ("paths" if self.use_obstacles else "present")
        self._hyp: _Hypotheses | None = None
        self._ready = False

    # -- per trial -------------------------------------------------------------------------
    def reset(self, context: TrialContext) -> None:
        st = self.settings
        self.dt = float(context.dt)
        self._steps = self.dt * np.arange(1, self.horizon + 1)
        self._present_steps = (self.extrapolation * self._steps)[:, None]
        self._hand = HandForce(self.dt, st.accel_time, context.object)
        self._b_gain = 1.0 - math.exp(-self.dt / st.bias_time)
        self._hyp = None
        obstacles = tuple(context.obstacles) if self.use_obstacles else ()
        shape = self.shapes.get(context.user, self.default)
        path = None if context.path is None else np.asarray(context.path, dtype=float)
        if obstacles and path is not None:
            obstacles = self.in_the_way(path, obstacles, context.user)
        if obstacles and path is not None:
            # the obstacle the path passes nearest: one detour per trial (the scenarios have one box)
            near = min(obstacles, key=lambda o: float(np.min(np.linalg.norm(path - np.asarray(o[0]), axis=1))))
            task = _scene_task(path, near)
            self._hyp = _Hypotheses(task, shape, st.shape_grid)
            n = len(self._hyp.sides)
            self._idx = np.zeros(n, dtype=int)
            self._loglik = np.zeros(n)
            prior = math.log(shape.left_preference / (1.0 - shape.left_preference))
            bound = PRIOR_SHARE * st.decide
            self._log_odds = min(max(prior, -bound), bound)
            self._kappa = st.kappa * self.dt / REFERENCE_DT
            self._step_cap = st.evidence_rate * self.dt
            # the nominal sample where the obstacle sits: side evidence stops once the tool is past it
            self._obstacle_index = int(np.searchsorted(task.path.arc, task.obstacle_arc))
            self._bias = 0.0
            self._side = 0
            self._mix = 1.0
            self._mix_step = self.dt / st.blend_time if st.blend_time > 0.0 else 1.0
            self._hedge_steps = (st.hedge_velocity * self._steps)[:, None]
            self._search_widest = widest = self._widest(self._hyp)
            self._pad_x, self._pad_y, self._pad_first, self._window, self._pad_local = self._hyp.search.tables(widest)
        self._ready = True

    def in_the_way(
        self, path: np.ndarray, obstacles: tuple[tuple[tuple[float, float], tuple[float, float]], ...], user: str
    ) -> tuple[tuple[tuple[float, float], tuple[float, float]], ...]:
        """The boxes of ``obstacles`` (centre, size) [m] the nominal ``path`` (P, 2) does not clear by half of
        ``user``'s largest clearance (their shape's times the largest factor of ``shape_grid``; :func:`deformed_path`'s
        own test of a cleared box): those a trial's hypotheses go round (:meth:`reset`). A box beside the path, or
        across the room, a scene file may name with every other fixture lies clear of it: a detour round it would
        lead the tool away from a plan that already passes it."""
        clearance = self.shapes.get(user, self.default).clearance * max(self.settings.shape_grid)
        points = np.asarray(path, dtype=float)
        return tuple(o for o in obstacles if float(Box(o[0], o[1]).signed_distance(points).min()) < 0.5 * clearance)

    @property
    def curves(self) -> tuple[np.ndarray, np.ndarray]:
        """This trial's hypotheses: (sides (N,), points (N, P, 2) [m]); empty without an obstacle."""
        if self._hyp is None:
            return np.zeros(0, dtype=int), np.zeros((0, 0, 2))
        return self._hyp.sides.copy(), self._hyp.points.copy()

    @property
    def side(self) -> int:
        """The side the rows follow: +1 left of the path, −1 right, 0 undecided (or no obstacle)."""
        return self._side if self._hyp is not None else 0

    def predict(self, history: np.ndarray) -> np.ndarray:
        if not self._ready:
            raise RuntimeError("PathHypothesesIntent.predict called before reset")
        row = history[-1]
        total = sum(row[:6].tolist())  # plain floats, as the person filter's guard
        if total - total != 0.0:  # a NaN or an infinity in the row: kept out of every state (the hand's filter)
            return np.full((self.horizon, 2), np.nan)  # the loop's check falls back to the plan for this tick alone
        p, v, w = row[0:2], row[2:4], row[4:6]
        u_h = self._hand(v, w)  # the hand's force, the object's inertia put back
        K, C = self.arm.stiffness, self.arm.damping
        present = p + (u_h + C * v) / K
        if self._hyp is None:
            return present + self._present_steps * v
        return self._filter(self._hyp, p, v, u_h, present)

    def _widest(self, hyp: _Hypotheses) -> int:
        """Samples searched either side of each curve's last phase: ``search_window`` of curve, at least 2."""
        return min(hyp.points.shape[1], max(2, int(math.ceil(self.settings.search_window / hyp.step))))

    def _shared(
        self, hyp: _Hypotheses, p: np.ndarray, v: np.ndarray, u_h: np.ndarray, present: np.ndarray, widest: int
    ) -> np.ndarray | None:
        """The filter's tick where every curve is the nominal path around the tool and as far as the rows
        reach: one curve's projection stands for all, nothing separates the hypotheses (no side or shape
        evidence), and the rows are that curve's. None where the curves may part within reach."""
        i = int(self._idx[0])
        n_pts = hyp.points.shape[1]
        if np.any(self._idx != i) or hyp.first_apart <= i + 2 * widest <= hyp.last_apart + 3 * widest:
            return None
        st = self.settings
        K, C = self.arm.stiffness, self.arm.damping
        ids = np.clip(i + np.arange(-widest, widest + 1), 0, n_pts - 1)
        near = int(ids[np.argmin(np.sum((hyp.points[0, ids] - p) ** 2, axis=1))])
        tan = hyp.tangents[0, near]
        lead = float(tan @ u_h + C * (tan @ v)) / K
        speed = max(float(tan @ v), 0.0)
        # the window searched next tick and the rows' reach must lie where every curve is the nominal path
        reach = int(math.ceil((max(lead, 0.0) + float(self._steps[-1]) * speed) / hyp.step)) + 2
        if not (near + max(widest, reach) < hyp.first_apart or near - widest > hyp.last_apart):
            return None
        self._idx[:] = near
        if self._mix >= 1.0:  # as step 2 where the sides' curves coincide
            q = hyp.points[0, near] + lead * tan
            self._bias += self._b_gain * (float((present - q) @ hyp.n_o) - self._bias)
            self._bias = min(max(self._bias, -st.bias_limit), st.bias_limit)
        ahead = hyp.at(0, hyp.arc[0, near] + lead + self._steps * speed)
        self._mix = 1.0 if self._mix_step >= 1.0 else min(self._mix + self._mix_step, 1.0)
        if self._mix >= 1.0:
            return ahead
        hedge = present + self._hedge_steps * v
        return self._mix * ahead + (1.0 - self._mix) * hedge

    def _filter(
        self, hyp: _Hypotheses, p: np.ndarray, v: np.ndarray, u_h: np.ndarray, present: np.ndarray
    ) -> np.ndarray:
        st = self.settings
        K, C = self.arm.stiffness, self.arm.damping
        widest = self._search_widest
        if self.shared_fast_path:
            fast = self._shared(hyp, p, v, u_h, present, widest)
            if fast is not None:
                return fast
        # 1. the tool's phase on every curve: its nearest point within search_window of the last one, on the
        # curves padded with copies of their ends (:class:`~coassist.scenario.curve_search.CurveSearch`: what a clipped index reads)
        px, py = p.tolist()
        flat = (self._pad_first + self._idx)[:, None] + self._window
        d2 = window_distances(self._pad_x, self._pad_y, flat, px, py)  # = Σ over x, y of (point − p)², bit for bit
        near = self._pad_local.take(flat[:, 0] + d2.argmin(axis=1))  # each curve's nearest sample
        at = near + hyp.row_start  # its flat index
        self._idx = near
        tan = hyp.flat_tangents.take(at, axis=0)
        lead = (tan @ u_h + C * (tan @ v)) / K
        q = hyp.flat_points.take(at, axis=0) + lead[:, None] * tan  # each curve's present estimate
        s_lead = hyp.flat_arc.take(at) + lead
        # 2. side
        cl, cr = hyp.centre[1], hyp.centre[-1]
        sep = q[cl] - q[cr]
        D = float(np.hypot(sep[0], sep[1]))
        mid = 0.5 * (q[cl] + q[cr])
        if D < st.divergence:
            # learnt only while the rows follow the shared path (a person who leaves it earlier than their
            # mean shape is detouring, not riding beside it), and never more than bias_limit
            if self._mix >= 1.0:
                self._bias += self._b_gain * (float((present - mid) @ hyp.n_o) - self._bias)
                self._bias = min(max(self._bias, -st.bias_limit), st.bias_limit)
        elif self._side == 0 or int(near[cl]) < self._obstacle_index:
            # evidence until the tool is level with the obstacle (after it, the return toward the path says
            # nothing of the side taken), at most step_cap per tick: no single tick decides
            z = float((present - mid) @ sep) / D
            gain = self._kappa * (z - self._bias) * D / st.sigma**2
            self._log_odds += min(max(gain, -self._step_cap), self._step_cap)
            self._log_odds = min(max(self._log_odds, -50.0), 50.0)
        # 3. shape, within each side while its curves are apart
        corrected = present - self._bias * hyp.n_o
        r = corrected - q
        r2 = r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1]
        for on in hyp.side_runs:  # slices (views) where a side's curves are one run
            qs = q[on]
            off = qs - np.add.reduce(qs, axis=0) / qs.shape[0]  # the mean's own sum and division
            # the largest distance from the side's mean point (sqrt of the largest square: the same number)
            spread = math.sqrt(float(np.maximum.reduce(off[:, 0] * off[:, 0] + off[:, 1] * off[:, 1])))
            if spread >= st.divergence:
                r2_on = r2[on]
                ll = self._loglik[on] - self._kappa * (r2_on - np.minimum.reduce(r2_on)) / (2 * st.sigma**2)
                ll -= np.maximum.reduce(ll)
                self._loglik[on] = ll
        np.maximum(self._loglik, -60.0, out=self._loglik)
        if abs(self._log_odds) > st.decide:
            side = 1 if self._log_odds > 0 else -1
            if side != self._side and self._side != 0:
                self._mix = 0.0  # a change of mind goes through the present estimate, not across the obstacle
            self._side = side

        # 4. rows
        def along(n: int) -> np.ndarray:
            speed = max(float(tan[n] @ v), 0.0)
            return hyp.at(n, s_lead[n] + self._steps * speed)

        if self._side != 0:
            on = hyp.on_side[0 if self._side == 1 else 1]
            weight = np.exp(self._loglik[on])
            # the shapes that still matter (at most MIXTURE, each ≥ 1 % of the best): their rows, weighted,
            # so the rows slide from one shape to the next instead of jumping
            best = weight.argsort()[::-1][:MIXTURE]
            best = best[weight[best] >= 0.01 * weight[best[0]]]
            w = weight[best] / weight[best].sum()
            ahead = w[0] * along(int(on[best[0]]))
            for wt, n in zip(w[1:], on[best[1:]]):
                ahead += wt * along(int(n))
            target = 1.0
        else:
            ahead = along(cl)
            # the sides disagree over the horizon: the present estimate alone
            # the largest row distance (the largest norm is the root of the largest square, as norm sums them)
            apart = ahead - along(cr)
            apart *= apart
            target = 0.0 if math.sqrt(float(np.maximum.reduce(np.add.reduce(apart, axis=1)))) >= st.divergence else 1.0
        # cross-fade between the curve's rows and the present estimate's (no step in the robot's effort)
        if self._mix_step >= 1.0:
            self._mix = target
        elif target != self._mix:
            self._mix = min(max(self._mix + math.copysign(self._mix_step, target - self._mix), 0.0), 1.0)
        if self._mix >= 1.0:
            return ahead
        hedge = present + self._hedge_steps * v  # built only where it is used
        if self._mix <= 0.0:
            return hedge
        return self._mix * ahead + (1.0 - self._mix) * hedge


# ----------------------------------------------------------------------------- calibration


def fit_detour(
    task: Task,
    pose: np.ndarray,
    *,
    clearances: Sequence[float] | None = None,
    anticipations: Sequence[float] | None = None,
) -> tuple[int, float, float]:
    """(side, clearance [m], anticipation [m]) of the detour curve nearest a logged tool path.

    The side is where the tool passes the obstacle (its offset along the path's normal there);
    clearance and anticipation minimise the mean squared distance from the tool's positions
    (every 12th: 0.1 s apart at 125 Hz) to the curve's vertices (every 4th: about 1 mm apart), on
    log-spaced grids (5 mm–8 cm, 3–30 cm; 13 values each). The tool
    cuts the person's corners a little, so the fit leans toward a smaller clearance and a longer
    anticipation; the filter's shape grid covers that.
    """
    pose = np.asarray(pose, dtype=float)
    if pose.ndim != 2 or pose.shape[1] != 2 or pose.shape[0] < 2:
        raise ValueError(f"pose must have shape (T >= 2, 2), got {pose.shape}")
    cs = np.geomspace(0.005, 0.08, 13) if clearances is None else np.asarray(clearances, dtype=float)
    as_ = np.geomspace(0.03, 0.30, 13) if anticipations is None else np.asarray(anticipations, dtype=float)
    n_o = task.path.normal(task.obstacle_arc)
    centre = np.asarray(task.obstacle.center)
    near = int(np.argmin(np.linalg.norm(pose - centre, axis=1)))
    side = 1 if float((pose[near] - task.path.position(task.obstacle_arc)) @ n_o) > 0.0 else -1
    sample = pose[::12]
    sx, sy = sample[:, 0:1], sample[:, 1:2]  # (S, 1) columns against each curve's (V,) coordinates
    best = (math.inf, float(cs[0]), float(as_[0]))
    for c in cs:
        for a in as_:
            pts, _, taken = deformed_path(task, side, float(c), float(a))
            if taken != side:
                continue
            # the squared distances as dx·dx + dy·dy: the bits of summing the squared differences over the
            # coordinate axis (a sum of two terms), without the (S, V, 2) temporary; a third of the time
            dx, dy = sx - pts[::4, 0], sy - pts[::4, 1]
            cost = float(np.mean(np.min(dx * dx + dy * dy, axis=1)))
            if cost < best[0]:
                best = (cost, float(c), float(a))
    return side, best[1], best[2]


def calibrate(fits: Iterable[tuple[int, float, float]]) -> PersonShape:
    """A person's shape from their fitted detours (:func:`fit_detour`): exp(median(log ·)) of the
    clearances and of the anticipations (the median on a log scale: for an even count, the geometric
    mean of the middle two), and the left preference (n_left + 1)/(n + 2) (Laplace's rule: never
    certain of a side after a few trials)."""
    fits = list(fits)
    if not fits:
        raise ValueError("calibrate needs at least one fitted trial")
    left = sum(1 for side, _, _ in fits if side > 0)
    c = float(np.exp(np.median(np.log([f[1] for f in fits]))))
    a = float(np.exp(np.median(np.log([f[2] for f in fits]))))
    return PersonShape(clearance=c, anticipation=a, left_preference=(left + 1) / (len(fits) + 2), trials=len(fits))


def write_calibration(
    folder: str | Path,
    shapes: Mapping[str, PersonShape],
    *,
    arm: ArmGuess | None = None,
    settings: FilterSettings | None = None,
    default: PersonShape | None = None,
) -> Path:
    """Write a ``paths`` source folder (``path-hypotheses.json``, atomically, with the hash of its content:
    :func:`coassist._io.write_hashed_json`); returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for name, shape in shapes.items():
        if not isinstance(name, str) or not isinstance(shape, PersonShape):
            raise ValueError(f"shapes must map person names to PersonShape, got {name!r}: {type(shape).__name__}")
    doc = {
        "shapes": {k: asdict(v) for k, v in shapes.items()},
        "default": asdict(default or PersonShape()),
        "arm": asdict(arm or ArmGuess()),
        "settings": asdict(settings or FilterSettings()),
    }
    write_hashed_json(folder / CALIBRATION_FILE, doc, format=_FORMAT)
    return folder


def _fields(doc: Mapping[str, object], key: str, where: str) -> dict[str, object]:
    """``doc[key]`` (an object of fields; {} when absent), or a ValueError naming it."""
    value = doc.get(key, {})
    if not isinstance(value, dict):
        raise ValueError(f"{where} must be an object of fields, got {json.dumps(value)[:80]}")
    return value


def read_calibration(folder: str | Path, horizon: int = 50) -> PathHypothesesIntent:
    """The ``paths`` source a folder written by :func:`write_calibration` holds.

    Refused in one line naming the file (and the field): a file that is not there or not JSON, of
    another format, edited after it was written (its hash, :func:`coassist._io.read_hashed_json`), or
    with a field out of its :data:`CALIBRATION_RANGES` range or of the wrong type."""
    path = Path(folder) / CALIBRATION_FILE
    doc = read_hashed_json(path, format=_FORMAT)
    try:
        unknown = sorted(set(doc) - {"shapes", "default", "arm", "settings"})
        if unknown:
            raise ValueError(f"unknown field {unknown[0]!r}")
        shapes = {}
        for name, fields in _fields(doc, "shapes", "shapes").items():
            if not isinstance(fields, dict):
                raise ValueError(f"shapes[{name!r}] must be an object of fields, got {json.dumps(fields)[:80]}")
            shapes[name] = PersonShape(**fields)
        settings = _fields(doc, "settings", "settings")
        grid = settings.get("shape_grid")
        if isinstance(grid, list):
            settings["shape_grid"] = tuple(grid)
        return PathHypothesesIntent(
            horizon,
            shapes=shapes,
            default=PersonShape(**_fields(doc, "default", "default")),  # type: ignore[arg-type]
            arm=ArmGuess(**_fields(doc, "arm", "arm")),  # type: ignore[arg-type]
            settings=FilterSettings(**settings),  # type: ignore[arg-type]
            # as a person model's: the folder's name and the file's digest (person_model.read_person_model)
            model_id=f"paths:{Path(folder).name}@{hashlib.sha256(path.read_bytes()).hexdigest()[:12]}",
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None
