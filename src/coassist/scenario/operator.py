"""The simulated operator: intent around the obstacle, an arm that pulls toward it, a population.

Intent (docs/architecture.md, *The simulated world*)
----------------------------------------------------
The operator wants the nominal path deformed smoothly around the obstacle, which
only they can see. A profile with a detour family (``OperatorProfile.detour``,
:mod:`coassist.scenario.detours`: asymmetric, skewed, swinging through, corrective
sub-movements, hesitation; the populations of :mod:`coassist.scenario.populations`) goes round
in the family's shape and may slow its progress after the onset; the timing below, and
everything before the onset, is the same for every family. Without one (the thesis
population, :func:`operator_profile`), along the arc length s the path is shifted sideways,
along the path's left normal n_o at the obstacle, by::

    d(s) = A · b(s),   b = 1 within ±(h_t + clearance) of the obstacle's arc length s_o,
                       rising and falling over the anticipation distance with the
                       smoothstep 6u⁵ − 15u⁴ + 10u³

where h_t is the box's half-extent along the path and the amplitude A is the box's
half-extent along the normal plus the operator's clearance, on the side they pick
(if the deformed path still comes closer to the box than half the clearance, A grows
until it does not).

Timing: the operator plans a minimum-jerk motion (Flash & Hogan 1985) of the *nominal*
length with their own pace: it starts ``start_delay`` after the planner's and lasts
T = T_plan / pace (pace jittered per trial), so the intent can lead or lag the robot's
reference. Up to the detour's onset (where the shift b(s) starts to rise) their path is
the nominal one, and so is their progress along it, s(t) = L σ((t − t₀)/T), whichever
side they will take. At the onset they commit to a side and re-plan the rest as the
minimum-jerk motion over their own path's remaining length D (a quintic in time from the
onset's arc length, speed and acceleration to the end at rest) lasting
T_r = T_rest,nominal · (D / D_nominal)^κ, κ = :data:`DETOUR_TIME_EXPONENT`: a longer
detour takes somewhat longer (κ = 1 would keep the mean speed, κ = 0 the duration, the
isochrony of human movements; Viviani & McCollum 1983). So nothing in the intent before
the onset says which side comes (timing the whole detoured path with one profile, as
before, made an operator going round the longer side run ahead from the start).

Arm (thesis eq. 4.1, the physical sign of docs/architecture.md's conventions)
-----------------------------------------------------------------------------
::

    u_h(k) = K_h(k) [(1 − β) e(k) + β e(k − d)] − C_h ṗ(k) + n(k),   e = x_ref,h − p

p is the hand point (the tip for the handle), d = round(reaction_delay / dt) ticks,
β = ``reflex_share``: the share of the stiffness that acts through the delayed
(reflex and voluntary) pathway, the rest being the muscles' intrinsic stiffness,
which acts at once. With β = 0 or no delay this is exactly eq. 4.1 plus noise. n is
motor noise, a first-order (Ornstein–Uhlenbeck) process of standard deviation
``motor_noise`` and correlation time ``motor_noise_time``. The force is scaled, not
clipped per axis, to at most ``force_limit`` in norm.

Reacting to the robot: stiffness adapts to the error (Franklin et al. 2008: the
nervous system co-contracts when errors grow and relaxes when they shrink)::

    ē ← ē + (dt/τ_a)(|e(k)| − ē),   K_h = clip(K_min + κ ē, K_min, K_max)

A robot that helps where the operator wants to go keeps |e| small, so the arm
relaxes and pushes less; a robot pulling elsewhere (e.g. toward the nominal path
around the obstacle) raises |e|, and the operator stiffens and pushes harder.

Population
----------
:func:`operator_profile` (user_index, population_seed): user 0 plays the thesis' author
(fixed parameters tuned against the real user-a recordings, see docs/realism.md);
users ≥ 1 are drawn from a seeded population around it. This is the ``thesis`` population,
the main job's; :func:`coassist.scenario.populations.population_profile` names the others
(``varied``: detour families to tune on, arms 0.5–2 × the author's; ``held-out``: families of
another kind, to report only).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np

from coassist._checks import check_int, check_real
from coassist._rows import RowConstants
from coassist.scenario.detours import DetourFamily, detour_path, progress_warp, smoothstep
from coassist.scenario.tasks import Task, quintic


def _num(value, name: str, lo: float = 0.0, hi: float = math.inf, *, lo_open: bool = False) -> float:
    return check_real(value, f"OperatorProfile.{name}", lo, hi, open_lo=lo_open)


@dataclass(frozen=True)
class OperatorProfile:
    """One operator's personal parameters (module docstring for the model). SI units.

    stiffness_min, stiffness_max : K_min ≤ K_max [N/m], the relaxed and fully
        co-contracted arm stiffness.
    stiffness_gain : κ [N/m per m of filtered error].
    adaptation_time : τ_a [s] of the error filter.
    damping : C_h [N·s/m].
    reaction_delay : [s] of the delayed pathway; reflex_share : β ∈ [0, 1].
    force_limit : largest hand force [N] (norm).
    motor_noise : [N] standard deviation; motor_noise_time : [s] correlation time.
    clearance : [m] kept from the obstacle; anticipation : [m] of path over which
        the operator moves aside before (and back after) the obstacle.
    pace : > 0, the operator's speed relative to the planner (1 = same);
        pace_jitter : trial-to-trial standard deviation of the pace (relative).
    shape_jitter : trial-to-trial standard deviation (relative, log-normal) of the
        clearance and the anticipation: nobody walks round an obstacle the same way twice.
    start_delay : [s] from the planner's start to the operator's.
    left_preference : probability of passing the obstacle on the left of the path.
    detour : the person's detour family (:mod:`coassist.scenario.detours`); None: the thesis'
        symmetric bump (:func:`deformed_path`), as every profile of :func:`operator_profile`.
    """

    name: str
    stiffness_min: float = 550.0
    stiffness_max: float = 1300.0
    stiffness_gain: float = 12000.0
    adaptation_time: float = 0.4
    damping: float = 10.0
    reaction_delay: float = 0.08
    reflex_share: float = 0.5
    force_limit: float = 40.0
    motor_noise: float = 0.6
    motor_noise_time: float = 0.15
    clearance: float = 0.025
    anticipation: float = 0.06
    pace: float = 1.0
    pace_jitter: float = 0.04
    shape_jitter: float = 0.2
    start_delay: float = 0.4
    left_preference: float = 0.5
    detour: DetourFamily | None = None

    def __post_init__(self) -> None:
        if self.detour is not None and not isinstance(self.detour, DetourFamily):
            raise ValueError(f"OperatorProfile.detour must be a DetourFamily or None, got {type(self.detour).__name__}")
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"OperatorProfile.name must be a non-empty string, got {self.name!r}")
        for name, lo, hi, lo_open in (
            ("stiffness_min", 0.0, math.inf, True),
            ("stiffness_max", 0.0, math.inf, True),
            ("stiffness_gain", 0.0, math.inf, False),
            ("adaptation_time", 0.0, math.inf, True),
            ("damping", 0.0, math.inf, False),
            ("reaction_delay", 0.0, 1.0, False),
            ("reflex_share", 0.0, 1.0, False),
            ("force_limit", 0.0, math.inf, True),
            ("motor_noise", 0.0, math.inf, False),
            ("motor_noise_time", 0.0, math.inf, True),
            ("clearance", 0.0, math.inf, False),
            ("anticipation", 0.0, math.inf, True),
            ("pace", 0.0, math.inf, True),
            ("pace_jitter", 0.0, 0.5, False),
            ("shape_jitter", 0.0, 1.0, False),
            ("start_delay", 0.0, math.inf, False),
            ("left_preference", 0.0, 1.0, False),
        ):
            object.__setattr__(self, name, _num(getattr(self, name), name, lo, hi, lo_open=lo_open))
        if self.stiffness_max < self.stiffness_min:
            raise ValueError(
                f"OperatorProfile.stiffness_max ({self.stiffness_max}) must be >= stiffness_min ({self.stiffness_min})"
            )

    def to_extra(self) -> dict:
        """JSON-able (trial metadata); ``detour`` (the family and its parameters) only where there is one,
        so a thesis profile's record is what it was before families existed."""
        out = asdict(self)
        del out["detour"]
        if self.detour is not None:
            out["detour"] = self.detour.to_extra()
        return out


#: User 0: "the author" of the iterative experiments (tuned on user-a, docs/realism.md).
AUTHOR = OperatorProfile(name="user-0")


def operator_profile(user_index: int, population_seed: int = 0) -> OperatorProfile:
    """The operator profile of ``user_index`` in the population ``population_seed``.

    User 0 is :data:`AUTHOR` (the same in every population). Users ≥ 1 are drawn
    from a Generator seeded by SeedSequence([population_seed, user_index]), so a
    user's profile does not depend on how many others were drawn. Spreads (log-normal
    unless stated): stiffness ×/÷ 1.35, damping ×/÷ 1.4, delay 0.05–0.14 s, noise
    ×/÷ 1.5, clearance 0.01–0.05 m, anticipation 0.05–0.2 m, pace ×/÷ 1.15, force
    limit 30–60 N, left preference 0.1–0.9.
    """
    user_index = check_int(user_index, "user_index", 0)
    population_seed = check_int(population_seed, "population_seed", 0)
    if user_index == 0:
        return AUTHOR
    rng = np.random.default_rng(np.random.SeedSequence([int(population_seed), int(user_index)]))
    a = AUTHOR

    def lognormal(spread: float) -> float:
        return float(np.exp(rng.normal(0.0, np.log(spread))))

    stiff = lognormal(1.35)
    return OperatorProfile(
        name=f"user-{int(user_index)}",
        stiffness_min=a.stiffness_min * stiff,
        stiffness_max=a.stiffness_max * stiff * lognormal(1.15),
        stiffness_gain=a.stiffness_gain * lognormal(1.5),
        adaptation_time=a.adaptation_time * lognormal(1.4),
        damping=a.damping * lognormal(1.4),
        reaction_delay=float(rng.uniform(0.05, 0.14)),
        reflex_share=float(rng.uniform(0.3, 0.7)),
        force_limit=float(rng.uniform(30.0, 60.0)),
        motor_noise=a.motor_noise * lognormal(1.5),
        motor_noise_time=a.motor_noise_time * lognormal(1.3),
        clearance=float(rng.uniform(0.01, 0.05)),
        anticipation=float(rng.uniform(0.05, 0.20)),
        pace=a.pace * lognormal(1.15),
        pace_jitter=float(rng.uniform(0.02, 0.08)),
        start_delay=float(rng.uniform(0.1, 0.5)),
        left_preference=float(rng.uniform(0.1, 0.9)),
    )


#: κ of the detour's re-planned duration (module docstring): between isochrony (0) and
#: constant mean speed (1).
DETOUR_TIME_EXPONENT = 0.5


@dataclass(frozen=True, eq=False)
class Intent:
    """The operator's desired trajectory on the tick grid.

    positions, velocities : (n, 2) [m, m/s] at t = k·dt.
    side : +1 passing on the left of the path, −1 on the right.
    amplitude : |A| [m], the largest lateral shift.
    pace : the trial's pace; end_time : [s] when the operator's motion ends.
    detour : the trial's detour family and parameters (:meth:`DetourFamily.trial
        <coassist.scenario.detours.DetourFamily.trial>`); None: the thesis' bump.
    """

    positions: np.ndarray
    velocities: np.ndarray
    side: int
    amplitude: float
    pace: float
    end_time: float
    detour: DetourFamily | None = None


def deformed_path(task: Task, side: int, clearance: float, anticipation: float) -> tuple[np.ndarray, float, int]:
    """The nominal path's dense points shifted around the obstacle: ((P, 2) points, |A|, side taken).

    The shift is along the path's normal *at the obstacle*, n_o, for every point:
    d(s) = A b(s) n_o. A fixed direction keeps the deformed path smooth on curved
    paths, where offsetting along the local normal would fold the curve wherever the
    radius of curvature is below the offset (the sinusoid's troughs: ≈4 cm).
    """
    path, box = task.path, task.obstacle
    s = path.arc
    s_o = task.obstacle_arc
    t_o = path.tangent(s_o)
    n_o = path.normal(s_o)
    half = 0.5 * np.asarray(box.size)
    h_t = float(abs(t_o[0]) * half[0] + abs(t_o[1]) * half[1])
    h_n = float(abs(n_o[0]) * half[0] + abs(n_o[1]) * half[1])
    # The box centre's offset from the path along the normal (0 when centred on it).
    offset = float(np.dot(np.asarray(box.center) - path.position(s_o), n_o))
    dist = np.abs(s - s_o)
    # Grow the shift (and the stretch it covers) until the path clears the box by at
    # least clearance/2; at a sharp corner (the Z) the inside may be impossible, and the
    # operator goes round the outside instead.
    for sgn in (side, -side):
        amp, plateau = h_n + clearance, h_t + clearance
        for _ in range(40):
            bump = 1.0 - smoothstep((dist - plateau) / anticipation)
            A = offset + sgn * amp
            pts = path.points + (A * bump)[:, None] * n_o
            if box.signed_distance(pts).min() >= 0.5 * clearance:
                return pts, abs(A), sgn
            amp *= 1.08
            plateau += 0.005
    return pts, abs(A), -side


def trial_shape(profile: OperatorProfile, rng: np.random.Generator) -> tuple[float, float]:
    """This trial's (clearance, anticipation) [m]: the profile's, each ×/÷ exp(N(0, shape_jitter))."""
    jitter = rng.normal(0.0, profile.shape_jitter, 2)
    return profile.clearance * float(np.exp(jitter[0])), profile.anticipation * float(np.exp(jitter[1]))


def _quintic_to_rest(
    s0: float, v0: float, a0: float, s1: float, duration: float, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The minimum-jerk motion from (s0, v0, a0) to (s1, 0, 0) over ``duration`` [s], at times t ≥ 0.

    q(t) = s0 + v0 t + a0 t²/2 + c3 t³ + c4 t⁴ + c5 t⁵, with c3…c5 from the three end
    conditions; held at s1 after ``duration``. Returns (q, q̇).
    """
    T = float(duration)
    A = np.array([[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4], [6 * T, 12 * T**2, 20 * T**3]])
    b = np.array([s1 - s0 - v0 * T - 0.5 * a0 * T * T, -v0 - a0 * T, -a0])
    c3, c4, c5 = np.linalg.solve(A, b)
    tc = np.clip(t, 0.0, T)
    q = s0 + tc * (v0 + tc * (0.5 * a0 + tc * (c3 + tc * (c4 + tc * c5))))
    qd = v0 + tc * (a0 + tc * (3 * c3 + tc * (4 * c4 + tc * 5 * c5)))
    return q, np.where(t < T, qd, 0.0)


def detour_onset(task: Task, points: np.ndarray) -> int:
    """Index of the last point of the nominal path's polyline that ``points`` (a deformed path on the
    same samples) still shares: the detour's onset (0 when it departs from the start)."""
    differs = np.any(points != task.path.points, axis=1)
    return max(int(np.argmax(differs)) - 1, 0) if differs.any() else len(points) - 1


def asked_to_go(profile: OperatorProfile, way: int) -> OperatorProfile:
    """The operator of ``profile`` asked to go round the obstacle one way in a trial (+1 left of the plan, −1 right;
    0: ``profile`` itself, their own choice): the side draw of :func:`intent_trajectory` forced (a uniform draw is
    always < 1 and never < 0), every other draw of the trial as without the asking."""
    return profile if not way else replace(profile, left_preference=1.0 if way > 0 else 0.0)


def intent_trajectory(task: Task, profile: OperatorProfile, rng: np.random.Generator, n: int, dt: float) -> Intent:
    """The operator's intent for this trial on n ticks of dt [s] (module docstring).

    ``rng`` draws the trial's side, pace jitter and shape jitter (clearance, anticipation), in
    that order, then, for a profile with a detour family, the family's own jitter
    (:meth:`~coassist.scenario.detours.DetourFamily.trial`); the family shapes the path
    (:func:`~coassist.scenario.detours.detour_path`) and may slow the re-planned progress
    (s(t) = q(w(t − t_on)), :func:`~coassist.scenario.detours.progress_warp`). Up to the detour's
    onset the intent is the same, bit for bit, whichever side is drawn.
    """
    side = 1 if rng.random() < profile.left_preference else -1
    pace = profile.pace * float(np.exp(rng.normal(0.0, profile.pace_jitter)))
    clearance, anticipation = trial_shape(profile, rng)
    family = None if profile.detour is None else profile.detour.trial(rng)
    if family is None:
        pts, amp, side = deformed_path(task, side, clearance, anticipation)
    else:
        pts, amp, side, family = detour_path(task, side, clearance, anticipation, family)
    path = task.path
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    L, Ld = path.length, float(arc[-1])
    t0 = task.planner.start_delay + profile.start_delay
    T = task.planner.duration / pace
    t = np.arange(int(n)) * float(dt)
    # the nominal plan: progress along the (shared) path before the onset
    sigma, dsigma, ddsigma = quintic((t - t0) / T)
    inside = ((t - t0) > 0.0) & ((t - t0) < T)
    s = L * sigma
    sdot = np.where(inside, dsigma * L / T, 0.0)
    i_on = detour_onset(task, pts)
    s_on = float(path.arc[i_on])
    if i_on < len(pts) - 1:
        # the onset's phase on the nominal profile (σ is monotone on [0, 1]: bisection to the last bit)
        lo, hi = 0.0, 1.0
        target = s_on / L
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if quintic(np.array(mid))[0] < target else (lo, mid)
        tau_on = lo
        sig_on, dsig_on, ddsig_on = (float(v) for v in quintic(np.array(tau_on)))
        t_on = t0 + tau_on * T
        v_on, a_on = (dsig_on * L / T, ddsig_on * L / T**2) if 0.0 < tau_on < 1.0 else (0.0, 0.0)
        remaining, remaining_nominal = Ld - s_on, L - s_on
        T_r = (1.0 - tau_on) * T * (remaining / remaining_nominal) ** DETOUR_TIME_EXPONENT
        after = t >= t_on
        windows = () if family is None else family.windows(T_r)
        if windows:  # the family slows the re-planned motion down: q at the warped time, q̇ · w'
            warped, rate = progress_warp(t[after] - t_on, windows)
            q, qd = _quintic_to_rest(s_on, v_on, a_on, Ld, T_r, warped)
            qd = qd * rate
        else:
            q, qd = _quintic_to_rest(s_on, v_on, a_on, Ld, T_r, t[after] - t_on)
        s = np.where(after, 0.0, s)
        sdot = np.where(after, 0.0, sdot)
        s[after], sdot[after] = np.clip(q, s_on, Ld), np.maximum(qd, 0.0)
        end_time = t_on + (_unwarp(T_r, windows) if windows else T_r)
    else:
        end_time = t0 + T
    pos = np.stack([np.interp(s, arc, pts[:, 0]), np.interp(s, arc, pts[:, 1])], axis=1)
    tan = np.gradient(pts, arc, axis=0)
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    # before the onset the nominal path's own tangents: the shared part's velocities do not see the detour
    tan[: i_on + 1] = path.tangents[: i_on + 1]
    vel = np.stack([np.interp(s, arc, tan[:, 0]), np.interp(s, arc, tan[:, 1])], axis=1) * sdot[:, None]
    return Intent(positions=pos, velocities=vel, side=side, amplitude=amp, pace=pace, end_time=end_time, detour=family)


def _unwarp(duration: float, windows) -> float:
    """The first time u [s] after the onset with w(u) = ``duration`` (w non-decreasing, w(u) ≥ u − Σ lost):
    duration + Σ lost where every window has ended by then, else bisection to the last bit."""
    lost = sum(w.time_lost for w in windows)
    if all(w.start + w.width <= duration + lost for w in windows):
        return float(duration) + lost
    lo, hi = float(duration), float(duration) + lost + 1e-9
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if float(progress_warp(np.array([mid]), windows)[0][0]) < duration else (lo, mid)
    return hi


class OperatorArm:
    """The operator's arm for one trial: call :meth:`force` once per tick, in order.

    Parameters
    ----------
    profile : the operator.
    intent : (n, 2) desired hand-frame positions x_ref,h [m] on the tick grid (the
        tip's intent; the world adds the object's grasp offset itself).
    dt : tick [s].
    noise : (n, 2) the trial's motor noise [N], precomputed (see :func:`motor_noise`).
    """

    def __init__(self, profile: OperatorProfile, intent: np.ndarray, dt: float, noise: np.ndarray) -> None:
        self.profile = profile
        self.intent, self.noise, self.dt = intent, noise, float(dt)  # what built it (SimulatedHand.to_dict)
        self._ix = intent[:, 0].tolist()  # plain floats: the tick is scalar arithmetic
        self._iy = intent[:, 1].tolist()
        self._nx = noise[:, 0].tolist()
        self._ny = noise[:, 1].tolist()
        self._n = len(self._ix)
        self.delay_ticks = int(round(profile.reaction_delay / dt))
        size = self.delay_ticks + 1
        self._ex = [0.0] * size  # ring buffers of the error, for the delayed pathway
        self._ey = [0.0] * size
        self._size = size
        self._ebar = 0.0
        self._alpha = dt / profile.adaptation_time
        self.stiffness = profile.stiffness_min

    def force(self, k: int, px: float, py: float, vx: float, vy: float) -> tuple[float, float]:
        """u_h(k) [N] for hand position (px, py) [m] and velocity (vx, vy) [m/s] at tick k."""
        p = self.profile
        i = k if k < self._n else self._n - 1
        ex = self._ix[i] - px
        ey = self._iy[i] - py
        slot = k % self._size
        self._ex[slot] = ex
        self._ey[slot] = ey
        # The oldest slot of the ring is e(k − d) (e(0) before d ticks have passed: at rest).
        old = (k + 1) % self._size if k >= self.delay_ticks else 0
        dx = self._ex[old]
        dy = self._ey[old]
        self._ebar += self._alpha * (math.sqrt(ex * ex + ey * ey) - self._ebar)
        K = p.stiffness_min + p.stiffness_gain * self._ebar
        if K > p.stiffness_max:
            K = p.stiffness_max
        self.stiffness = K
        b = p.reflex_share
        fx = _axis_force(K, b, ex, dx, p.damping, vx, self._nx[i])
        fy = _axis_force(K, b, ey, dy, p.damping, vy, self._ny[i])
        norm = math.sqrt(fx * fx + fy * fy)
        if norm > p.force_limit:
            scale = p.force_limit / norm
            fx *= scale
            fy *= scale
        return fx, fy

    @staticmethod
    def batch(arms: Sequence[OperatorArm]) -> OperatorArmBatch:
        """The array twin of ``arms`` (each an :class:`OperatorArm`, none called yet) for the point-mass array path
        (:class:`~coassist.sim.point_mass.PointMassWorldBatch` builds its arms' batch with their type's ``batch``)."""
        return OperatorArmBatch(arms)


def _axis_force(K, b, e, e_delayed, damping, v, noise):
    """Eq. 4.1 on one axis before the force limit: K [(1 − β) e + β e(k − d)] − C_h v + n.

    Elementwise, floats or arrays: :class:`OperatorArm` and :class:`OperatorArmBatch` share it."""
    return K * ((1.0 - b) * e + b * e_delayed) - damping * v + noise


class OperatorArmBatch:
    """:meth:`OperatorArm.force` for B arms at once, row for row the same floats: its array twin.

    The point-mass array path (:mod:`coassist.sim.array_runner`) calls :meth:`force` once per
    tick for the rows still going; each row keeps its arm's ring of errors, filtered error
    ē and stiffness exactly as the arm would (the same formulas: :func:`_axis_force`, and
    the others written elementwise in the arm's order of operations).

    Parameters
    ----------
    arms : the B arms, none called yet (their next tick is 0).
    """

    def __init__(self, arms: Sequence[OperatorArm]) -> None:
        if not all(type(a) is OperatorArm for a in arms):
            raise ValueError("OperatorArmBatch takes OperatorArm objects")
        B = len(arms)
        self.n = np.array([a._n for a in arms], dtype=np.intp)
        L = int(self.n.max()) if B else 0
        self.intent = np.stack([_ragged([a._ix for a in arms], L), _ragged([a._iy for a in arms], L)], axis=2)
        self.noise = np.stack([_ragged([a._nx for a in arms], L), _ragged([a._ny for a in arms], L)], axis=2)
        self.delay = np.array([a.delay_ticks for a in arms], dtype=np.intp)
        self._size = self.delay + 1
        self._err = np.zeros((B, int(self._size.max()) if B else 1, 2))  # each row's ring of e, as the arm's
        self.filtered_error = np.array([a._ebar for a in arms], dtype=float)
        self._alpha = np.array([a._alpha for a in arms], dtype=float)
        profiles = [a.profile for a in arms]

        def column(name: str) -> np.ndarray:
            return np.array([getattr(p, name) for p in profiles], dtype=float)

        self._k_min, self._k_gain, self._k_max = (
            column("stiffness_min"),
            column("stiffness_gain"),
            column("stiffness_max"),
        )
        self._reflex, self._damping, self._force_limit = (
            column("reflex_share"),
            column("damping"),
            column("force_limit"),
        )
        self.stiffness = np.array([a.stiffness for a in arms], dtype=float)
        # the per-arm constants, gathered once per set of rows still going
        self._constants = RowConstants(
            (
                self.n - 1,  # the last tick of each arm's intent and noise
                self._size,
                self.delay,
                self._alpha,
                self._k_min,
                self._k_gain,
                self._k_max,
                self._reflex[:, None],  # β and C_h as columns: _axis_force on both axes at once
                self._damping[:, None],
                self._force_limit,
            )
        )

    def force(self, k: int, rows: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        """u_h(k) [N], (len(rows), 2), of the arms ``rows`` (indices) for their hand points p and
        velocities v, (len(rows), 2) [m, m/s]: each row what its arm's ``force(k, …)`` gives."""
        last, size, delay, alpha, k_min, k_gain, k_max, b, damping, limit = self._constants.take(rows)
        i = np.minimum(k, last)
        e = self.intent[rows, i] - p
        self._err[rows, k % size] = e
        # the oldest slot of the ring is e(k − d) (e(0) before d ticks have passed: at rest)
        old = np.where(k >= delay, (k + 1) % size, 0)
        de = self._err[rows, old]
        ebar = self.filtered_error[rows]
        ebar = ebar + alpha * (np.sqrt(e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1]) - ebar)
        self.filtered_error[rows] = ebar
        K = k_min + k_gain * ebar
        K = np.where(K > k_max, k_max, K)
        self.stiffness[rows] = K
        noise = self.noise[rows, i]
        # both axes in one pass, each row's K, β and C_h broadcast along its axes (the same
        # operations on each element as one axis at a time)
        f = _axis_force(K[:, None], b, e, de, damping, v, noise)
        norm = np.sqrt(f[:, 0] * f[:, 0] + f[:, 1] * f[:, 1])
        over = norm > limit
        if over.any():
            f[over] *= (limit[over] / norm[over])[:, None]
        return f


def _ragged(seqs: Sequence[Sequence[float]], n: int) -> np.ndarray:
    """(len(seqs), n): each sequence's first n values, zero-padded."""
    out = np.zeros((len(seqs), n))
    for b, s in enumerate(seqs):
        m = min(len(s), n)
        out[b, :m] = s[:m]
    return out


def motor_noise(profile: OperatorProfile, rng: np.random.Generator, n: int, dt: float) -> np.ndarray:
    """(n, 2) Ornstein–Uhlenbeck motor noise [N], stationary std ``profile.motor_noise``."""
    rho = math.exp(-dt / profile.motor_noise_time)
    white = rng.standard_normal((int(n), 2)) * (profile.motor_noise * math.sqrt(1.0 - rho * rho))
    white[0] = rng.standard_normal(2) * profile.motor_noise  # start in the stationary distribution
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -rho], white, axis=0)
