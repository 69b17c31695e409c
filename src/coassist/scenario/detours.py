"""Detour families: seeded generators of the simulated person's path round the obstacle and of
their progress along it (issue 40).

The thesis' operator (:func:`coassist.scenario.operator.deformed_path`) detours along one
family: a symmetric smoothstep bump. The families here are the other ways people go round an
obstacle. Each is a frozen dataclass of one person's parameters; :meth:`DetourFamily.trial`
draws the trial's own parameters from them (per-trial jitter, a fixed number of draws from the
trial's intent generator whatever the side, so nothing before the onset depends on the side);
:func:`detour_path` makes the path and :meth:`DetourFamily.windows` the progress' slow-downs.
None of this is told to an intent source: the project's layering test keeps it out of them.

Path
----
Along the nominal path's arc length s the path is shifted along its left normal at the
obstacle n_o (one fixed direction, as the bump's: no folding on curved paths) by::

    d(s) = A · f(u),   u = s − s_o,   P = h_t + clearance   (the plateau's half-length)

with s_o the obstacle's arc length, h_t the box's half-extent along the path and A the
box's half-extent along the normal plus the clearance, on the side drawn. As for the bump,
if the path comes closer to the box than half the clearance, A and P grow (×1.08, +5 mm)
until it does not, or the other side is taken (a sharp corner). Where a family's detour
would not fit between the path's ends (a long return after an obstacle near the end), the
anticipation shrinks until the detour keeps :data:`ROOM` of path at both ends (at least
:data:`MIN_ANTICIPATION`); where no side fits and clears, the trial goes round as the
bump (:class:`Bump`, recorded so: :func:`detour_path`). The unit profile f is exactly
0 before the detour's onset and exactly 0 at the end; S(x) = 6x⁵ − 15x⁴ + 10x³ on x clipped
to [0, 1] is the smoothstep, a the trial's anticipation [m]:

- The return R_ℓ,o,μ(u) = (1 − S₁) − o (S₁ − S₂), S₁ = S((u − P)/ℓ), S₂ = S((u − P − ℓ)/(μ ℓ)):
  from 1 back to the path over ℓ after the plateau, through it to −o where the first stroke
  ends (a return overshoot of o·A) and back onto it over μ ℓ; o = 0: 1 − S₁, the bump's.
- :class:`Asymmetric` (return_ratio ρ, overshoot o): rise over a before the plateau, return
  over ρ·a after it: f = 1 − S((−u − P)/a) for u < 0, R_ρa,o,1 for u ≥ 0. Measured on the
  path, the return's 10–90 % width over the rise's is ρ.
- :class:`Skewed` (skew g, peak ∓1, overshoot o): the bump β (rise, then R_a,o,1) tilted
  across the plateau, f = β (1 + g r), r = 1 − S((u + P)/(2P)) for a peak *before* the
  obstacle, S((u + P)/(2P)) after it: the largest shift, (1 + g)·A, sits at u = −P (or +P),
  and the plateau's other end still clears the box with A.
- :class:`Swing` (overshoot o, settle_ratio μ): the return swings through the path and
  comes back, f = R_a,o,μ for u ≥ 0: the return overshoot is o·A.
- :class:`Corrective` (held out): the detour in several overlapping sub-movements. The way
  out is m_o smoothstep strokes of length ℓ_o = a / (1 + (m_o − 1)(1 − v)) starting every
  ℓ_o (1 − v) (v the overlap) from u = −P − a, weights w_j (Σ = 1); the way back m_b strokes
  over ρ·a from u = P, weights w'_j, then one correcting stroke the length of a back stroke:
  f = (O − B) − o (B − C), O = Σ w_j S_j, B = Σ w'_j S'_j, C the correction; the return
  swings through by o·A. Its progress is made of sub-movements too (below).
- :class:`Hesitant` (held out): the symmetric bump, and the progress hesitates at the onset.
- :class:`Feint` (unseen): a lean the other way first, e·A over 2λa, ending half way up the rise
  of the bump on the side taken: f = β(u) − e (S((u − u_l)/(λa)) − S((u − u_l − λa)/(λa))),
  u_l = −P − a/2 − 2λa. The person starts round one side and goes round the other.
- :class:`Ringing` (unseen): the return rings: from 1 through the path to −o, then to +o r,
  −o r², … (n extremes, each r times the last), then onto the path, each stroke a smoothstep
  between successive extremes, the first over a and the others over μa. n = 1 is the swing's
  return.

Progress
--------
The operator (:func:`~coassist.scenario.operator.intent_trajectory`) follows the nominal
plan's minimum-jerk progress to the onset and re-plans the rest there as a quintic q(τ) to
rest over T_r. The timing families slow that re-plan down through a time warp, u = t − t_on::

    s(t) = q(w(u)),   w'(u) = 1 − Σ_j h_j g((u − c_j)/τ_j),   g(x) = S(x/r) S((1 − x)/r)

each window j (start c_j ≥ 0 [s], width τ_j [s], depth h_j ∈ [0, 1], ramps r ≤ ½ of it) a
slow-down to (1 − h_j) of the re-planned speed, a pause where h_j = 1; each costs
h_j τ_j (1 − r) of time (w is in closed form, :func:`progress_warp`). g and its first two
derivatives vanish at the window's ends, so the progress stays twice differentiable.

- :class:`Hesitant`: one window ``delay`` ≥ 0 after the onset, of its ``depth`` (1: a pause)
  and ``duration``.
- :class:`Corrective`: m_p windows spread over the re-planned motion (window j centred at
  (j + 1)/(m_p + 1) of T_r): the progress in m_p + 1 sub-movements.

Shape or timing family, every one ends at rest at the target (f = 0 there and q ends at
rest), clears the box by half the clearance, and draws the same numbers whatever the side
(tests/scenario/test_detours.py measures each claim on generated paths).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from coassist._checks import check_int, check_real
from coassist.scenario.tasks import Task

__all__ = [
    "FAMILIES",
    "Asymmetric",
    "Bump",
    "Corrective",
    "DetourFamily",
    "Feint",
    "Hesitant",
    "Ringing",
    "Skewed",
    "Swing",
    "Window",
    "detour_path",
    "family_from_extra",
    "progress_warp",
    "smoothstep",
]


def smoothstep(x: np.ndarray) -> np.ndarray:
    """S(x) = 6x⁵ − 15x⁴ + 10x³ on x clipped to [0, 1]: 0 → 1 with zero slope and curvature at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)


def _smoothstep_integral(x: np.ndarray) -> np.ndarray:
    """∫₀ˣ S = x⁶ − 3x⁵ + 5x⁴/2 on x clipped to [0, 1] (½ at 1)."""
    x = np.clip(x, 0.0, 1.0)
    return x**4 * (2.5 + x * (x - 3.0))


@dataclass(frozen=True)
class Window:
    """A slow-down of the progress (module docstring, *Progress*): from ``start`` [s] after the
    onset, ``width`` [s] long, the speed × (1 − ``depth``) on its plateau; ``ramp`` ∈ (0, ½] of the
    width to enter and leave it."""

    start: float
    width: float
    depth: float
    ramp: float = 0.25

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", check_real(self.start, "Window.start", 0.0))
        object.__setattr__(self, "width", check_real(self.width, "Window.width", 0.0, open_lo=True))
        object.__setattr__(self, "depth", check_real(self.depth, "Window.depth", 0.0, 1.0))
        object.__setattr__(self, "ramp", check_real(self.ramp, "Window.ramp", 0.0, 0.5, open_lo=True))

    @property
    def time_lost(self) -> float:
        """h τ (1 − r) [s]: how much later the motion ends for this window."""
        return self.depth * self.width * (1.0 - self.ramp)


def _window_shape(x: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray]:
    """g(x) = S(x/r) S((1 − x)/r) and G(x) = ∫₀ˣ g on the window's unit time x (r ≤ ½: the ramps do not meet)."""
    g = smoothstep(x / r) * smoothstep((1.0 - x) / r)
    xc = np.clip(x, 0.0, 1.0)
    G = np.where(
        xc < r,
        r * _smoothstep_integral(xc / r),
        np.where(
            xc <= 1.0 - r,
            0.5 * r + (xc - r),
            0.5 * r + (1.0 - 2.0 * r) + r * (0.5 - _smoothstep_integral((1.0 - xc) / r)),
        ),
    )
    return g, G


def progress_warp(u: np.ndarray, windows: tuple[Window, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(w(u), w'(u)) of the module docstring at times u [s] after the onset (w = u before it)."""
    u = np.asarray(u, dtype=float)
    w, dw = u.copy(), np.ones_like(u)
    for win in windows:
        g, G = _window_shape((u - win.start) / win.width, win.ramp)
        w = w - win.depth * win.width * G
        dw = dw - win.depth * g
    return w, np.maximum(dw, 0.0)


def _num(owner: str, name: str, value: object, lo: float, hi: float = math.inf, *, open_lo: bool = False) -> float:
    return check_real(value, f"{owner}.{name}", lo, hi, open_lo=open_lo)


@dataclass(frozen=True)
class DetourFamily:
    """One person's way round the obstacle (module docstring). Subclasses set ``name``, ``kind``
    ("shape": one smooth stroke out and back, the progress one re-plan; "segmented": sub-movements
    or hesitation in the progress; "reversing": a lean the other way first, or a return that rings)
    and the profile f.

    jitter : trial-to-trial standard deviation (relative, log-normal) of the family's own
        parameters, drawn by :meth:`trial` after the operator's side, pace and shape.
    """

    name: ClassVar[str] = ""
    kind: ClassVar[str] = ""
    jitter: float = 0.15

    def __post_init__(self) -> None:
        object.__setattr__(self, "jitter", _num(type(self).__name__, "jitter", self.jitter, 0.0, 1.0))

    def trial(self, rng: np.random.Generator) -> DetourFamily:
        """This trial's parameters: the person's, jittered (a fixed number of draws from ``rng``)."""
        raise NotImplementedError

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        """The unit lateral profile f(u) at u = s − s_o [m] (module docstring); P = ``plateau`` [m]."""
        raise NotImplementedError

    def windows(self, remaining_time: float) -> tuple[Window, ...]:
        """The progress' slow-downs after the onset, for a re-planned motion of ``remaining_time`` [s] (none: a shape family)."""
        return ()

    def reach(self) -> tuple[float, float]:
        """(k_b, k_a): f ≠ 0 only on −P − k_b a < u < P + k_a a (the anticipations before and after the plateau)."""
        return 1.0, 1.0

    def to_extra(self) -> dict:
        """JSON-able: ``{"family": name, parameters…}`` (trial metadata)."""
        out: dict[str, object] = {"family": self.name}
        for key, value in asdict(self).items():
            out[key] = list(value) if isinstance(value, tuple) else value
        return out


def _bump(u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
    """The symmetric bump β(u) = 1 − S((|u| − P)/a)."""
    return 1.0 - smoothstep((np.abs(u) - plateau) / anticipation)


def _rise(u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
    """1 − S((−u − P)/a): the bump's rising half (1 from u = −P on)."""
    return 1.0 - smoothstep((-u - plateau) / anticipation)


def _lognormal(rng: np.random.Generator, sigma: float) -> float:
    return float(np.exp(rng.normal(0.0, sigma)))


def _return(u: np.ndarray, plateau: float, length: float, overshoot: float, settle: float) -> np.ndarray:
    """(1 − S₁) − o (S₁ − S₂), S₁ = S((u − P)/ℓ), S₂ = S((u − P − ℓ)/(μ ℓ)): from 1 back over ℓ =
    ``length`` after the plateau, through the path to −o, and back onto it over μ ℓ (o = 0: 1 − S₁)."""
    s1 = smoothstep((u - plateau) / length)
    if overshoot == 0.0:
        return 1.0 - s1
    s2 = smoothstep((u - plateau - length) / (settle * length))
    return (1.0 - s1) - overshoot * (s1 - s2)


@dataclass(frozen=True)
class Asymmetric(DetourFamily):
    """Rise over the anticipation a, return over ``return_ratio`` · a, swinging through the path by
    ``overshoot`` · A on the way back (module docstring)."""

    name: ClassVar[str] = "asymmetric"
    kind: ClassVar[str] = "shape"
    return_ratio: float = 1.0
    overshoot: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "return_ratio", _num("Asymmetric", "return_ratio", self.return_ratio, 0.05, 20.0))
        object.__setattr__(self, "overshoot", _num("Asymmetric", "overshoot", self.overshoot, 0.0, 1.0))

    def trial(self, rng: np.random.Generator) -> Asymmetric:
        jit = rng.normal(0.0, self.jitter, 2)
        return replace(
            self,
            return_ratio=self.return_ratio * float(np.exp(jit[0])),
            overshoot=min(1.0, self.overshoot * float(np.exp(jit[1]))),
        )

    def reach(self) -> tuple[float, float]:
        return 1.0, self.return_ratio * (2.0 if self.overshoot > 0.0 else 1.0)

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        back = _return(u, plateau, self.return_ratio * anticipation, self.overshoot, 1.0)
        return np.where(u < 0.0, _rise(u, plateau, anticipation), back)


@dataclass(frozen=True)
class Skewed(DetourFamily):
    """The bump tilted across its plateau: the largest shift (1 + ``skew``) A before the obstacle
    (``peak`` = −1) or after it (+1); the return swings through by ``overshoot`` (× the tilt there)
    (module docstring)."""

    name: ClassVar[str] = "skewed"
    kind: ClassVar[str] = "shape"
    skew: float = 0.3
    peak: int = -1
    overshoot: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "skew", _num("Skewed", "skew", self.skew, 0.0, 5.0))
        peak = check_int(self.peak, "Skewed.peak", -1, 1)
        if peak == 0:
            raise ValueError("Skewed.peak must be -1 (before the obstacle) or +1 (after it), got 0")
        object.__setattr__(self, "peak", peak)
        object.__setattr__(self, "overshoot", _num("Skewed", "overshoot", self.overshoot, 0.0, 1.0))

    def trial(self, rng: np.random.Generator) -> Skewed:
        jit = rng.normal(0.0, self.jitter, 2)
        return replace(
            self, skew=self.skew * float(np.exp(jit[0])), overshoot=min(1.0, self.overshoot * float(np.exp(jit[1])))
        )

    def reach(self) -> tuple[float, float]:
        return 1.0, 2.0 if self.overshoot > 0.0 else 1.0

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        across = smoothstep((u + plateau) / (2.0 * plateau))
        tilt = 1.0 - across if self.peak < 0 else across
        base = np.where(
            u < 0.0, _rise(u, plateau, anticipation), _return(u, plateau, anticipation, self.overshoot, 1.0)
        )
        return base * (1.0 + self.skew * tilt)


@dataclass(frozen=True)
class Swing(DetourFamily):
    """The return swings through the path by ``overshoot`` · A and settles over ``settle_ratio`` ·
    the anticipation (module docstring)."""

    name: ClassVar[str] = "swing"
    kind: ClassVar[str] = "shape"
    overshoot: float = 0.2
    settle_ratio: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "overshoot", _num("Swing", "overshoot", self.overshoot, 0.0, 1.0))
        object.__setattr__(self, "settle_ratio", _num("Swing", "settle_ratio", self.settle_ratio, 0.05, 20.0))

    def trial(self, rng: np.random.Generator) -> Swing:
        jit = rng.normal(0.0, self.jitter, 2)
        return replace(
            self,
            overshoot=min(1.0, self.overshoot * float(np.exp(jit[0]))),
            settle_ratio=self.settle_ratio * float(np.exp(jit[1])),
        )

    def reach(self) -> tuple[float, float]:
        return 1.0, 1.0 + self.settle_ratio

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        back = _return(u, plateau, anticipation, self.overshoot, self.settle_ratio)
        return np.where(u < 0.0, _rise(u, plateau, anticipation), back)


def _strokes(u: np.ndarray, first: float, span: float, weights: tuple[float, ...], overlap: float) -> np.ndarray:
    """Σ_j w_j S((u − u_j)/ℓ) of overlapping strokes covering [first, first + span] (module docstring,
    :class:`Corrective`); exactly 0 before the first and exactly Σ w = 1 after the last."""
    m = len(weights)
    length = span / (1.0 + (m - 1) * (1.0 - overlap))
    stride = length * (1.0 - overlap)
    out = np.zeros_like(u)
    for j, w in enumerate(weights):
        out += w * smoothstep((u - first - j * stride) / length)
    return np.where(u >= first + span, 1.0, np.where(u <= first, 0.0, out))


@dataclass(frozen=True)
class Corrective(DetourFamily):
    """The detour in overlapping sub-movements, out and back, swinging through the path on the
    return, and the progress in sub-movements (module docstring).

    out_weights, back_weights : the strokes' shares of the way out and back (each normalised to Σ = 1).
    overlap : v ∈ [0, 0.9], the share of a stroke the next one overlaps.
    overshoot : o, the return's swing through the path, a share of A.
    return_ratio : ρ, the way back's length over the anticipation.
    dips : m_p ≥ 0 slow-downs of the progress; dip_depth : h ∈ [0, 1]; dip_width : τ [s].
    """

    name: ClassVar[str] = "corrective"
    kind: ClassVar[str] = "segmented"
    out_weights: tuple[float, ...] = (0.5, 0.5)
    back_weights: tuple[float, ...] = (0.5, 0.5)
    overlap: float = 0.25
    overshoot: float = 0.2
    return_ratio: float = 1.0
    dips: int = 2
    dip_depth: float = 0.5
    dip_width: float = 0.4

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("out_weights", "back_weights"):
            raw = getattr(self, name)
            if isinstance(raw, (str, bytes)) or not hasattr(raw, "__len__") or len(raw) < 1:
                raise ValueError(f"Corrective.{name} must be a non-empty sequence of weights > 0, got {raw!r}")
            values = [_num("Corrective", name, v, 0.0, open_lo=True) for v in raw]
            total = math.fsum(values)
            object.__setattr__(self, name, tuple(v / total for v in values))
        object.__setattr__(self, "overlap", _num("Corrective", "overlap", self.overlap, 0.0, 0.9))
        object.__setattr__(self, "overshoot", _num("Corrective", "overshoot", self.overshoot, 0.0, 1.0))
        object.__setattr__(self, "return_ratio", _num("Corrective", "return_ratio", self.return_ratio, 0.05, 20.0))
        object.__setattr__(self, "dips", check_int(self.dips, "Corrective.dips", 0, 10))
        object.__setattr__(self, "dip_depth", _num("Corrective", "dip_depth", self.dip_depth, 0.0, 1.0))
        object.__setattr__(self, "dip_width", _num("Corrective", "dip_width", self.dip_width, 0.0, open_lo=True))

    def trial(self, rng: np.random.Generator) -> Corrective:
        m = len(self.out_weights) + len(self.back_weights)
        jit = rng.normal(0.0, self.jitter, m + 3)
        weights = np.asarray(self.out_weights + self.back_weights) * np.exp(jit[:m])
        n_out = len(self.out_weights)
        return replace(
            self,
            out_weights=tuple(float(v) for v in weights[:n_out]),
            back_weights=tuple(float(v) for v in weights[n_out:]),
            overshoot=min(1.0, self.overshoot * float(np.exp(jit[m]))),
            dip_depth=min(1.0, self.dip_depth * float(np.exp(jit[m + 1]))),
            dip_width=self.dip_width * float(np.exp(jit[m + 2])),
        )

    def reach(self) -> tuple[float, float]:
        m = len(self.back_weights)
        return 1.0, self.return_ratio * (1.0 + 1.0 / (1.0 + (m - 1) * (1.0 - self.overlap)))

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        back_span = self.return_ratio * anticipation
        out = _strokes(u, -plateau - anticipation, anticipation, self.out_weights, self.overlap)
        back = _strokes(u, plateau, back_span, self.back_weights, self.overlap)
        m = len(self.back_weights)
        stroke = back_span / (1.0 + (m - 1) * (1.0 - self.overlap))
        correction = smoothstep((u - plateau - back_span) / stroke)
        return (out - back) - self.overshoot * (back - correction)

    def windows(self, remaining_time: float) -> tuple[Window, ...]:
        if self.dips == 0 or self.dip_depth == 0.0:
            return ()
        spacing = remaining_time / (self.dips + 1)
        width = min(self.dip_width, 0.9 * spacing)  # windows never overlap
        return tuple(
            Window(start=max(0.0, (j + 1) * spacing - 0.5 * width), width=width, depth=self.dip_depth)
            for j in range(self.dips)
        )


@dataclass(frozen=True)
class Hesitant(DetourFamily):
    """The symmetric bump, the progress slowed to (1 − ``depth``) (a pause at 1) for ``duration``
    [s] from ``delay`` [s] after the onset (module docstring)."""

    name: ClassVar[str] = "hesitant"
    kind: ClassVar[str] = "segmented"
    depth: float = 0.8
    duration: float = 0.6
    delay: float = 0.05
    ramp: float = 0.25

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "depth", _num("Hesitant", "depth", self.depth, 0.0, 1.0))
        object.__setattr__(self, "duration", _num("Hesitant", "duration", self.duration, 0.0, open_lo=True))
        object.__setattr__(self, "delay", _num("Hesitant", "delay", self.delay, 0.0))
        object.__setattr__(self, "ramp", _num("Hesitant", "ramp", self.ramp, 0.0, 0.5, open_lo=True))

    def trial(self, rng: np.random.Generator) -> Hesitant:
        jit = rng.normal(0.0, self.jitter, 3)
        return replace(
            self,
            depth=min(1.0, self.depth * float(np.exp(0.5 * jit[0]))),
            duration=self.duration * float(np.exp(jit[1])),
            delay=self.delay * float(np.exp(jit[2])),
        )

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        return _bump(u, plateau, anticipation)

    def windows(self, remaining_time: float) -> tuple[Window, ...]:
        if self.depth == 0.0:
            return ()
        return (Window(start=self.delay, width=self.duration, depth=self.depth, ramp=self.ramp),)


@dataclass(frozen=True)
class Feint(DetourFamily):
    """A lean the other way, ``lean`` · A over 2 ``lean_ratio`` · the anticipation, before the bump on the side
    taken (module docstring): the person starts round one side and goes round the other."""

    name: ClassVar[str] = "feint"
    kind: ClassVar[str] = "reversing"
    lean: float = 0.2
    lean_ratio: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "lean", _num("Feint", "lean", self.lean, 0.0, 1.0))
        object.__setattr__(self, "lean_ratio", _num("Feint", "lean_ratio", self.lean_ratio, 0.05, 10.0))

    def trial(self, rng: np.random.Generator) -> Feint:
        jit = rng.normal(0.0, self.jitter, 2)
        return replace(
            self,
            lean=min(1.0, self.lean * float(np.exp(jit[0]))),
            lean_ratio=min(10.0, self.lean_ratio * float(np.exp(jit[1]))),
        )

    def reach(self) -> tuple[float, float]:
        return max(1.0, 0.5 + 2.0 * self.lean_ratio), 1.0

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        width = self.lean_ratio * anticipation
        start = -plateau - 0.5 * anticipation - 2.0 * width
        lean = smoothstep((u - start) / width) - smoothstep((u - start - width) / width)
        return _bump(u, plateau, anticipation) - self.lean * lean


@dataclass(frozen=True)
class Ringing(DetourFamily):
    """The return rings: through the path by ``overshoot`` · A, then ``swings`` − 1 more extremes each ``decay``
    times the last, alternating sides, before it settles; the strokes after the first over ``swing_ratio`` · the
    anticipation (module docstring)."""

    name: ClassVar[str] = "ringing"
    kind: ClassVar[str] = "reversing"
    overshoot: float = 0.2
    decay: float = 0.5
    swings: int = 3
    swing_ratio: float = 0.7

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "overshoot", _num("Ringing", "overshoot", self.overshoot, 0.0, 1.0))
        object.__setattr__(self, "decay", _num("Ringing", "decay", self.decay, 0.0, 1.0))
        object.__setattr__(self, "swings", check_int(self.swings, "Ringing.swings", 1, 10))
        object.__setattr__(self, "swing_ratio", _num("Ringing", "swing_ratio", self.swing_ratio, 0.05, 20.0))

    def trial(self, rng: np.random.Generator) -> Ringing:
        jit = rng.normal(0.0, self.jitter, 3)
        return replace(
            self,
            overshoot=min(1.0, self.overshoot * float(np.exp(jit[0]))),
            decay=min(1.0, self.decay * float(np.exp(jit[1]))),
            swing_ratio=min(20.0, self.swing_ratio * float(np.exp(jit[2]))),
        )

    def reach(self) -> tuple[float, float]:
        return 1.0, 1.0 + self.swings * self.swing_ratio

    def extremes(self) -> np.ndarray:
        """(swings + 2,) the return's levels: 1, −o, +o r, −o r², …, then 0 (the path)."""
        k = np.arange(self.swings)
        ringing = self.overshoot * (-1.0) ** (k + 1) * self.decay**k
        return np.concatenate([[1.0], ringing, [0.0]])

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        levels = self.extremes()
        back = np.full_like(u, levels[0])
        start, length = plateau, anticipation
        for k in range(1, len(levels)):
            back = back + (levels[k] - levels[k - 1]) * smoothstep((u - start) / length)
            start, length = start + length, self.swing_ratio * anticipation
        # on the path from the last stroke's end: the sum of the strokes' steps leaves a rounding there (~1e-16)
        back = np.where(u >= start, 0.0, back)
        return np.where(u < 0.0, _rise(u, plateau, anticipation), back)


@dataclass(frozen=True)
class Bump(DetourFamily):
    """The thesis' symmetric bump, f = β(u) = 1 − S((|u| − P)/a): in no population of
    :mod:`coassist.scenario.populations` (whose thesis population runs
    :func:`~coassist.scenario.operator.deformed_path` itself), the way round a trial falls back on
    where its family's shape does not fit (:func:`detour_path`)."""

    name: ClassVar[str] = "bump"
    kind: ClassVar[str] = "shape"

    def trial(self, rng: np.random.Generator) -> Bump:
        return self

    def profile(self, u: np.ndarray, plateau: float, anticipation: float) -> np.ndarray:
        return _bump(u, plateau, anticipation)


#: The families by name.
FAMILIES: dict[str, type[DetourFamily]] = {
    f.name: f for f in (Asymmetric, Skewed, Swing, Corrective, Hesitant, Feint, Ringing, Bump)
}


def family_from_extra(extra: dict) -> DetourFamily:
    """The family :meth:`DetourFamily.to_extra` wrote (a trial's metadata)."""
    if not isinstance(extra, dict) or extra.get("family") not in FAMILIES:
        raise ValueError(f"detour family must be a dict with 'family' one of {tuple(FAMILIES)}, got {extra!r}")
    cls = FAMILIES[extra["family"]]
    names = {f.name for f in fields(cls)}
    unknown = set(extra) - names - {"family"}
    if unknown:
        raise ValueError(f"detour family {extra['family']!r}: unknown parameters {sorted(unknown)}")
    kwargs: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in extra.items() if k != "family"}
    return cls(**kwargs)


#: [m] of nominal path kept before the detour departs and after it is back (the anticipation shrinks to fit).
ROOM = 0.02
#: [m] the least anticipation the fitting leaves.
MIN_ANTICIPATION = 0.01


def detour_path(
    task: Task, side: int, clearance: float, anticipation: float, family: DetourFamily
) -> tuple[np.ndarray, float, int, DetourFamily]:
    """The nominal path's dense points shifted by A·f(u) along n_o (module docstring): ((P, 2)
    points, |A| [m], side taken, the family that shaped them). ``family`` is the trial's
    (:meth:`DetourFamily.trial`). Where no way round in its shape both fits between the path's
    ends and clears the box (a sharp corner or a long return near the end; 1 trial in ~2400 of
    the drawn populations' on the four paths), the trial goes round as the thesis' symmetric
    bump (:class:`Bump`) does, and says so."""
    path, box = task.path, task.obstacle
    s_o = task.obstacle_arc
    u = path.arc - s_o
    t_o = path.tangent(s_o)
    n_o = path.normal(s_o)
    half = 0.5 * np.asarray(box.size)
    h_t = float(abs(t_o[0]) * half[0] + abs(t_o[1]) * half[1])
    h_n = float(abs(n_o[0]) * half[0] + abs(n_o[1]) * half[1])
    offset = float(np.dot(np.asarray(box.center) - path.position(s_o), n_o))
    k_before, k_after = family.reach()
    room_before, room_after = s_o - ROOM, path.length - s_o - ROOM
    for sgn in (side, -side):
        amp, plateau = h_n + clearance, h_t + clearance
        for _ in range(40):
            A = offset + sgn * amp
            # the detour departs after the start and is back on the path before the end
            fit = min(anticipation, (room_before - plateau) / k_before, (room_after - plateau) / k_after)
            if fit < MIN_ANTICIPATION:
                break  # grown past the room there is: this side does not fit
            pts = path.points + (A * family.profile(u, plateau, fit))[:, None] * n_o
            if box.signed_distance(pts).min() >= 0.5 * clearance:
                return pts, abs(A), sgn, family
            amp *= 1.08
            plateau += 0.005
    # the bump's way round (coassist.scenario.operator.deformed_path's), fitted as far as it can be
    bump = Bump(jitter=0.0)
    for sgn in (side, -side):
        amp, plateau = h_n + clearance, h_t + clearance
        for _ in range(40):
            A = offset + sgn * amp
            fit = max(min(anticipation, room_before - plateau, room_after - plateau), MIN_ANTICIPATION)
            pts = path.points + (A * bump.profile(u, plateau, fit))[:, None] * n_o
            if box.signed_distance(pts).min() >= 0.5 * clearance:
                return pts, abs(A), sgn, bump
            amp *= 1.08
            plateau += 0.005
    return pts, abs(A), -side, bump
