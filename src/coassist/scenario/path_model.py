"""A person's paths on a task, learned from their recorded trials: where they go round whatever is in the way.

What a lab records of a person guiding the tool along a task (the nominal path shown to them,
and where they went) says how *they* go round an obstacle: on which side, how wide, where
they start to move aside and where they come back. This module learns that, told nothing but
the nominal path and the paths the person pursued — no obstacle, no model of how people
detour.

Demonstrations. Each calibration trial gives the path the person pursued (the present
estimate of their intent along the trial, smoothed: coassist.scenario.person_model). A path
is smoothed and stored as the weights of a probabilistic movement primitive over its own arc
length u ∈ [0, 1] (Paraschos et al., NeurIPS 2013: B normalised Gaussian basis functions per
coordinate, ``movement_primitives.promp.ProMP``; the weights by ridge regression,
ProMP.weights), and labelled with the way round it took: the sign of its largest offset from
the nominal path (+1 left, −1 right; 0 when it never leaves the plan by ``detour_threshold``).

The distribution of the person's paths is the mixture over their demonstrations (a kernel
density over paths: each demonstration one component), one mode per way round, with prior
probability (n_way + 1)/(n + 2) for each way (Laplace's rule: a person who went left ten
times may still go right once). The prior counts only the trials where the person chose their way: a trial in
which the lab asked for a way round (:data:`ASKED_WAY` in its meta, what ``calibrate`` asks for when a way is
shown in fewer than :data:`FEW_PATHS` paths) adds that way's path, not the person's preference for it.
:meth:`PathModel.curves` draws its hypotheses for a trial:

- every demonstration that took a way round, shifted along the plan by each of ``shifts``
  (the obstacle, unseen, is never exactly where it was): x'(u) = x(u) + P(s(u) + δ) − P(s(u)),
  s(u) the arc length of x(u)'s nearest point on the nominal path P;
- for a way nobody took, the mirror images of the other way's paths across the plan:
  x'(u) = P(s(u)) − d(u)·n(s(u)), d the offset along the plan's left normal n;
- with no detour in any demonstration, the demonstrations themselves.

Why not a single Gaussian over weights conditioned online (the classic ProMP): tried on the
validation seeds (docs/precision.md), conditioning the shape on the present estimate while
also estimating the phase on the conditioned curve made the two feed each other (a phase a
little ahead warps the curve ahead, which moves the phase further), and the mean of
demonstrations whose detours start at different places is a blurred detour no one takes.
Rigid hypotheses with likelihoods (coassist.scenario.person_intent) keep the person's own
shapes sharp.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from coassist._checks import check_int, check_real, is_integer
from coassist.scenario.tasks import NominalPath

__all__ = [
    "ASKED_WAY",
    "FEW_PATHS",
    "NEAREST_CANDIDATES",
    "PathFrame",
    "PathModel",
    "PathModelSettings",
    "WAY_NAMES",
    "WAY_SIGNS",
    "check_way",
    "few_paths",
    "fit_path_model",
]

#: The vertices :meth:`PathFrame.nearest_vertex` compares each point with before it is sure of the nearest.
NEAREST_CANDIDATES = 8
#: A way round shown in fewer of a person's paths than this (but at least once) is too thin to follow as their habit:
#: the filter follows those few paths there. Both of the report's in-family misses (seed 0's board, seed 2's heavy
#: load) are one operator's way shown once or twice in eight (docs/person-model.md), and with two paths a task the
#: person model's overshoot was 1.25–1.39 × MG's against 0.57–1.06 × with three or more. What calibrate and drive say.
FEW_PATHS = 3
#: The key of a trial's ``meta.extra`` that says the lab asked the person to go round one way in that trial: +1 on the
#: left of the plan, −1 on the right (absent: the person chose). ``collect`` and ``drive`` write it (``--ask-way``).
ASKED_WAY = "asked_way"
#: The ways round by name: +1 on the left of the plan (seen along it), −1 on the right; and by sign.
WAY_SIGNS = {"left": 1, "right": -1}
WAY_NAMES = {sign: name for name, sign in WAY_SIGNS.items()}


def check_way(way: Any, name: str) -> int:
    """``way`` as a way round asked for (:data:`ASKED_WAY`): +1 left, −1 right, 0 none; else a ValueError naming
    ``name``."""
    if not is_integer(way) or way not in (-1, 0, 1):  # 1.0 is no way round: a file written by hand says so
        raise ValueError(
            f"{name} must be +1 (asked to go round on the left), -1 (on the right) or 0 (none asked), got {way!r}"
        )
    return int(way)


def few_paths(sides: np.ndarray) -> dict[str, int]:
    """Each way round ("left", "right") shown in fewer than :data:`FEW_PATHS` of the paths ``sides`` (+1 left, −1
    right, 0 no detour) but at least once: how many times, in that order."""
    counts = {name: int(np.sum(np.asarray(sides) == side)) for name, side in WAY_SIGNS.items()}
    return {name: n for name, n in counts.items() if 0 < n < FEW_PATHS}


class PathFrame:
    """A nominal path as coordinates (s, d): arc length along it and signed offset along its left normal.

    points : (P, 2) the nominal path's polyline [m] (repeated consecutive points are dropped).
    """

    def __init__(self, points: np.ndarray) -> None:
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2 or not np.isfinite(pts).all():
            raise ValueError(f"a nominal path must be finite, shape (P >= 2, 2), got {pts.shape}")
        keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 0.0])
        if keep.sum() < 2:
            raise ValueError("a nominal path must have at least two distinct points")
        self.path = NominalPath("frame", pts[keep])
        self.points = self.path.points
        self.arc = self.path.arc
        self.length = self.path.length
        self.tangents = self.path.tangents
        self.normals = np.stack([-self.tangents[:, 1], self.tangents[:, 0]], axis=1)
        self._tree: Any = None  # the vertices' k-d tree, built at the first nearest_vertex

    def project(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(s, d) of points q (T, 2): the arc length of each point's nearest vertex, moved along that
        vertex's tangent by the point's offset along it (clipped to [0, L]), and the offset along the
        vertex's left normal [m]. The nearest vertex is the first of least squared distance
        (x − x_j)² + (y − y_j)² (:meth:`nearest_vertex`)."""
        q = np.asarray(q, dtype=float).reshape(-1, 2)
        i = self.nearest_vertex(q)
        rel = q - self.points[i]
        out_s = np.clip(self.arc[i] + np.sum(rel * self.tangents[i], axis=1), 0.0, self.length)
        out_d = np.sum(rel * self.normals[i], axis=1)
        return out_s, out_d

    def nearest_vertex(self, q: np.ndarray) -> np.ndarray:
        """Index (T,) of each point of q (T, 2)'s nearest vertex: the first j of least
        f_j = (x − x_j)² + (y − y_j)², as ``argmin`` over every vertex gives it, bit for bit.

        Every vertex is compared only where it must be: a k-d tree of the vertices gives each
        point its :data:`NEAREST_CANDIDATES` nearest, and f is computed for those with the
        same floating-point operations; the least of them (the first index on a tie) is the
        answer when the tree's farthest candidate is farther, by a relative 1e-9, than its
        square root (every other vertex then has a larger f: the tree's distances and f
        differ by a few ulp). Points for which that does not hold (vertices tied with the
        candidates, non-finite points) are compared with every vertex. A trial's person model
        projects ~20 curves of 400 points on a plan of 1 250 vertices: every vertex for every
        point was 12 % of the point-mass person-model trial's CPU time (issue 44)."""
        q = np.asarray(q, dtype=float).reshape(-1, 2)
        n_vertices = len(self.points)
        out = np.zeros(len(q), dtype=np.intp)
        ok = np.isfinite(q).all(axis=1)
        rows = np.flatnonzero(ok)
        if rows.size and n_vertices > NEAREST_CANDIDATES:
            if self._tree is None:
                from scipy.spatial import cKDTree

                self._tree = cKDTree(self.points)
            tree = self._tree
            qx, qy = q[rows, 0], q[rows, 1]
            dist, idx = tree.query(q[rows], k=NEAREST_CANDIDATES)
            found = (idx < n_vertices).all(axis=1)  # the tree gives index n where a distance overflows
            idx = np.minimum(idx, n_vertices - 1)
            f = (qx[:, None] - self.points[idx, 0]) ** 2 + (qy[:, None] - self.points[idx, 1]) ** 2
            least = f.min(axis=1)
            out[rows] = np.where(f == least[:, None], idx, n_vertices).min(axis=1)
            sure = found & (dist[:, -1] ** 2 * (1.0 - 1e-9) > least)  # no vertex outside the candidates can match
            ok[rows[~sure]] = False
        elif rows.size:
            ok[rows] = False  # a few vertices: compare them all
        x, y = self.points[:, 0], self.points[:, 1]
        rest = np.flatnonzero(~ok)
        for j in range(0, rest.size, 256):
            chunk = q[rest[j : j + 256]]
            out[rest[j : j + 256]] = np.argmin(
                (chunk[:, None, 0] - x[None, :]) ** 2 + (chunk[:, None, 1] - y[None, :]) ** 2, axis=1
            )
        return out

    def distance_to(self, other: np.ndarray) -> float:
        """The largest distance [m] from a point of polyline ``other`` to this path's vertices' normals (a
        one-sided Hausdorff distance: 0 when ``other`` lies on this path)."""
        _, d = self.project(other)
        return float(np.max(np.abs(d))) if d.size else 0.0


@dataclass(frozen=True)
class PathModelSettings:
    """How a path model is fitted and sampled (module docstring); chosen on validation seeds.

    n_basis : B, basis functions per coordinate of each demonstration's primitive (4 … 200).
    ridge : the ridge on the primitive's weights (movement_primitives' ``lmbda``).
    samples : G, points each curve is sampled at (uniform in its own arc length).
    detour_threshold : [m] a demonstration whose offset never exceeds it took no detour.
    """

    n_basis: int = 60
    ridge: float = 1e-8
    samples: int = 400
    detour_threshold: float = 0.02

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_basis", check_int(self.n_basis, "PathModelSettings.n_basis", 4, 200))
        object.__setattr__(self, "ridge", check_real(self.ridge, "PathModelSettings.ridge", 0.0, 1.0))
        object.__setattr__(self, "samples", check_int(self.samples, "PathModelSettings.samples", 20, 5000))
        object.__setattr__(
            self,
            "detour_threshold",
            check_real(self.detour_threshold, "PathModelSettings.detour_threshold", 0.0, 0.5, open_lo=True),
        )


def _primitive(n_basis: int):
    from movement_primitives.promp import ProMP

    return ProMP(n_dims=2, n_weights_per_dim=n_basis)


def _phases(n: int) -> np.ndarray:
    return np.linspace(0.0, 1.0, n)


@dataclass(frozen=True, eq=False)
class PathModel:
    """A person's paths on one task (module docstring).

    nominal : (P, 2) the nominal path [m] the demonstrations followed.
    weights : (J, 2B) each demonstration's primitive weights (movement_primitives' layout: x's B, then y's).
    sides : (J,) the way round each took: +1 left, −1 right, 0 no detour.
    noise : σ [m] of the present estimate about the person's intent (its RMS per axis in the calibration).
    settings : how it was fitted.
    asked : (J,) bool, whether the lab asked for the way in that demonstration's trial (:data:`ASKED_WAY`): its
        path is one of the way's, but the ways' prior leaves it out. None: none was asked.
    """

    nominal: np.ndarray
    weights: np.ndarray
    sides: np.ndarray
    noise: float
    settings: PathModelSettings
    asked: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.settings, PathModelSettings):
            raise ValueError(f"PathModel.settings must be PathModelSettings, got {type(self.settings).__name__}")
        nominal = np.asarray(self.nominal, dtype=float)
        weights = np.asarray(self.weights, dtype=float)
        sides = np.asarray(self.sides)
        PathFrame(nominal)  # validates the nominal path
        B = self.settings.n_basis
        if weights.ndim != 2 or weights.shape[0] < 1 or weights.shape[1] != 2 * B or not np.isfinite(weights).all():
            raise ValueError(f"PathModel.weights must be finite, shape (J >= 1, {2 * B}), got {weights.shape}")
        if sides.shape != (weights.shape[0],) or not np.isin(sides, (-1, 0, 1)).all():
            raise ValueError(f"PathModel.sides must be one of -1, 0, 1 per demonstration, got {sides.tolist()}")
        asked = np.zeros(sides.shape, dtype=bool) if self.asked is None else np.asarray(self.asked)
        if asked.shape != sides.shape or asked.dtype != bool:
            raise ValueError(f"PathModel.asked must be one bool per demonstration, got {asked.tolist()}")
        object.__setattr__(self, "nominal", nominal)
        object.__setattr__(self, "weights", weights)
        object.__setattr__(self, "sides", sides.astype(int))
        object.__setattr__(self, "asked", asked)
        object.__setattr__(self, "noise", check_real(self.noise, "PathModel.noise", 0.0, 0.05, open_lo=True))

    def demonstrations(self) -> np.ndarray:
        """The demonstrated paths as the primitives give them: (J, G, 2) [m], G = ``settings.samples``."""
        promp = _primitive(self.settings.n_basis)
        return np.stack([promp.trajectory_from_weights(_phases(self.settings.samples), w) for w in self.weights])

    def ways(self) -> dict[int, float]:
        """The ways round the model knows and their prior probabilities (module docstring): {+1, −1}
        whenever a demonstration took one, else {0}. The prior counts the ways the person chose (not those asked)."""
        if not np.any(self.sides != 0):
            return {0: 1.0}
        chosen = self.sides[(self.sides != 0) & ~np.asarray(self.asked, dtype=bool)]
        n = chosen.size
        return {side: (int(np.sum(chosen == side)) + 1) / (n + 2) for side in (1, -1)}

    def curves(self, shifts: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The hypotheses of a trial (module docstring): (points (N, G, 2) [m], ways (N,), prior (N,),
        summing to 1 over all)."""
        frame = PathFrame(self.nominal)
        demos = self.demonstrations()
        out, ways, prior = [], [], []
        for way, p_way in self.ways().items():
            mine = np.flatnonzero(self.sides == way) if way else np.arange(len(self.sides))
            mirror = bool(way) and mine.size == 0
            if mirror:  # nobody went this way: the mirror images of the other way's paths
                mine = np.flatnonzero(self.sides == -way)
            for j in mine:
                s, d = frame.project(demos[j])
                base = frame.path.position(s) - d[:, None] * frame.path.normal(s) if mirror else demos[j]
                s = np.maximum.accumulate(s)
                for shift in shifts:
                    out.append(base + frame.path.position(s + float(shift)) - frame.path.position(s))
                    ways.append(way)
                    prior.append(p_way / (mine.size * len(shifts)))
        return np.asarray(out), np.asarray(ways, dtype=int), np.asarray(prior)

    def demonstration_offsets(self, s: np.ndarray) -> np.ndarray:
        """(J, len(s)) each demonstration's offset d from the plan [m] at arc lengths s (where it was first at s)."""
        frame = PathFrame(self.nominal)
        per_demo = []
        for demo in self.demonstrations():
            sd, dd = frame.project(demo)
            sd = np.maximum.accumulate(sd)
            first = np.concatenate([[True], np.diff(sd) > 0.0])
            per_demo.append(np.interp(s, sd[first], dd[first]))
        return np.asarray(per_demo)

    def repeatability(self) -> float | None:
        """How far the person's detours repeat: the median over the demonstrations that went round (way ±1) of
        ‖d_j − d̄_{−j}‖ / ‖d_j‖, d_j a demonstration's offset from the plan over 5–95 % of its length, d̄_{−j} the
        mean of the others of its way (RMS over the arc length). Near 0: the others say where this one went; near 1
        or above: no better than the plan (free deviations, not a scene gone round the same way). None: no way
        round taken twice. Paths that took no detour (way 0) are left out: their offset is the person's noise
        about the plan, which the ratio would read as paths that do not repeat."""
        L = PathFrame(self.nominal).length
        D = self.demonstration_offsets(np.linspace(0.05 * L, 0.95 * L, 91))
        ratios = []
        for j in np.flatnonzero(self.sides != 0):
            others = np.flatnonzero(self.sides == self.sides[j])
            others = others[others != j]
            own = float(np.sqrt(np.mean(D[j] ** 2)))
            if others.size and own > 0.0:
                ratios.append(float(np.sqrt(np.mean((D[j] - D[others].mean(axis=0)) ** 2))) / own)
        return float(np.median(ratios)) if ratios else None

    def way_offsets(self, s: np.ndarray) -> dict[int, np.ndarray]:
        """Each way's mean offset from the plan [m] at arc lengths s: the mean over its demonstrations (the
        mirrored mean for a way nobody took) of each one's offset d at s (where it was first at s)."""
        D = self.demonstration_offsets(s)
        out = {}
        for way in self.ways():
            mine = self.sides == way if way else np.ones(len(self.sides), dtype=bool)
            out[way] = D[mine].mean(axis=0) if mine.any() else -D[self.sides == -way].mean(axis=0)
        return out


def fit_path_model(
    nominal: np.ndarray,
    demonstrations: Sequence[np.ndarray],
    *,
    noise: float,
    settings: PathModelSettings | None = None,
    asked: Sequence[bool] | None = None,
) -> PathModel:
    """The :class:`PathModel` of a person's demonstrated paths (each (T_j, 2) [m], the intent they pursued,
    in the order they moved) against the nominal path (P, 2) (module docstring). ``noise``: σ [m] of the
    present estimate about the intent. ``asked``: per demonstration, whether the lab asked for its way round
    (:attr:`PathModel.asked`); None: none was."""
    settings = PathModelSettings() if settings is None else settings
    if not demonstrations:
        raise ValueError("fit_path_model needs at least one demonstrated path")
    if asked is not None and (len(asked) != len(demonstrations) or not all(isinstance(a, bool) for a in asked)):
        raise ValueError(f"asked must be one bool per demonstration ({len(demonstrations)}), got {list(asked)!r}")
    frame = PathFrame(nominal)
    promp = _primitive(settings.n_basis)
    weights, sides = [], []
    for j, demo in enumerate(demonstrations):
        demo = np.asarray(demo, dtype=float)
        if demo.ndim != 2 or demo.shape[1] != 2 or len(demo) < 2 or not np.isfinite(demo).all():
            raise ValueError(f"demonstration {j} must be a finite (T >= 2, 2) path, got shape {demo.shape}")
        seg = np.hypot(*np.diff(demo, axis=0).T)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        if arc[-1] <= 0.0:
            raise ValueError(f"demonstration {j} does not move")
        # resampled uniformly in its own arc length: the primitive's phase is how far along their path they are
        u = _phases(max(settings.samples, 2 * settings.n_basis))
        pts = np.stack([np.interp(u * arc[-1], arc, demo[:, k]) for k in (0, 1)], axis=1)
        weights.append(promp.weights(u.copy(), pts, lmbda=settings.ridge))
        _, d = frame.project(pts)
        peak = int(np.argmax(np.abs(d)))
        sides.append(int(math.copysign(1, d[peak])) if abs(d[peak]) > settings.detour_threshold else 0)
    return PathModel(
        nominal=frame.points.copy(),
        weights=np.asarray(weights),
        sides=np.asarray(sides),
        noise=noise,
        settings=settings,
        asked=None if asked is None else np.asarray(asked, dtype=bool),
    )
