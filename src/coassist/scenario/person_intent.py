"""The person's intent from what an arm measures and what their own trials taught: the online half of the person model.

An :class:`~coassist.interfaces.IntentSource` that reads only the last feature row (tool
position p, velocity v, wrench w) and the nominal path (``TrialContext.path``, public like
the plan), with a person's :class:`~coassist.scenario.path_model.PathModel` and
:class:`~coassist.scenario.arm_identification.ArmEstimate` fitted to their calibration trials
(coassist.scenario.person_model). It is told no obstacle: where the person goes round
whatever is in the way, their own demonstrations say.

Hypotheses. Every demonstrated path that took a way round, shifted along the plan by each of
``shifts`` (the obstacle, unseen, is never exactly where it was), and mirrored for a way round
nobody took: N rigid curves Cₙ on the nominal path's arc-length grid, each with its way round
σₙ ∈ {+1, −1} and prior πₙ (:meth:`PathModel.curves`). Every tick:

1. **present estimate** q = p + (w + m a + Ĉ v)/K̂ (eq. 4.1 solved for the intent; m a puts back
   the carried object's inertia, a low-pass filtered over ``accel_time``); with ``object_yaw`` p and
   v are the hand point's, not the tip's, on an object that yaws on its mount (the board's grasp is
   0.61 m from the cup: :class:`~coassist.scenario.hand_force.HandPoint`);
2. **phase**: the tool's nearest point on each curve within ``search_window`` of its last, and each
   curve's present estimate qₙ = Cₙ(sₙ + ℓₙ) with the lead ℓₙ = tₙ·(w + m a + Ĉ v)/K̂ along it;
3. **evidence**: each curve's log-likelihood grows by −κ‖q − b − qₙ‖²/(2σ²) (σ the present estimate's
   noise measured in the calibration; κ discounts the correlation of successive ticks; b the
   lateral bias learnt on the shared path, as in ``paths``). The ways' log-odds move with the
   change of their marginal log-likelihoods log Σₙ πₙ exp(ℓₙ) per way, at most ``evidence_rate``·dt
   per tick, from the ways' prior (bounded to ``prior_share`` of ``decide``: a habit never decides
   alone), until the tool passes the place where the ways are furthest apart. With ``side_rule``
   "onset" the way's evidence is the log-likelihood ratio of the present estimate's offset z from the
   plan when each way's offset there is anywhere between the plan and its mean path (how far into the
   detour the person is, unknown: :func:`onset_log_ratio`), counted only where the ways' mean paths are
   ``evidence_gap`` apart: a person still on the plan where their demonstrations had already left it
   says nothing about the way;
4. **rows**: once |log-odds| > ``decide`` the rows run along the decided way's likeliest curves
   (at most :data:`MIXTURE`, weighted) from their present estimates at the tool's speed along
   them (on a way nobody took, with ``follow_mirror`` off, the present estimate's rows instead); while
   undecided and the ways' rows part by more than ``divergence`` over the horizon, the
   rows are the present estimate's, q + ``hedge_velocity``·i·dt·v — neither way, and never the plan
   (with ``hedge_lateral`` off, v's component across the plan is left out: extrapolated, the tool's own
   sideways drift became the robot's push and then evidence for a way).
   The two cross-fade over ``blend_time``. With ``residual_time`` τ_r > 0 each way's rows from its curves carry
   the present estimate's offset across the plan from the chosen curves' own present estimates, fading along the
   horizon: row_i += ((q − b − Σₙ wₙ qₙ)·n̂) e^{−i·dt/τ_r} n̂ (n̂ the plan's left normal where the tool is): a
   person off their curves (a turn earlier than any demonstrated) is not pulled back onto them at once. While
   undecided, the two ways' rows compared against ``divergence`` are these rows too.
5. **smoothing**: the rows are low-passed over time with a time constant ``row_smoothing`` and
   advanced by the filter's lag (:class:`~coassist.scenario.row_smoothing.RowSmoothing`): the
   tick-to-tick noise of the phase, the lead and the mixture leaves the robot's effort, and with it
   the tool's jerk.

Where the tool is far from every curve (``max_offset``: another task, a person who left the plan
for good) or the model knows no path for the trial's plan, the rows are the present estimate's
at constant velocity. A curve whose phase is held more than ``max_offset`` from the tool (left in a
local minimum round a detour wider than any demonstrated) gives no rows, and a way with none near
gives the present estimate's rows, as on a change of mind.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from coassist._checks import check_int, check_real
from coassist.interfaces import TrialContext
from coassist.scenario.arm_identification import ASSUMED_ARM, ArmEstimate
from coassist.scenario.hand_force import HandForce, HandPoint
from coassist.scenario.path_model import PathFrame, PathModel
from coassist.scenario.row_smoothing import RowSmoothing

__all__ = ["PersonFilterSettings", "PersonPathsIntent", "normal_cdf_between", "onset_log_ratio"]

#: The control period [s] κ was chosen at; at another rate κ scales by dt / REFERENCE_DT.
REFERENCE_DT = 0.008
#: The spacing [m] of the grid of the plan the side evidence reads offsets on.
NOMINAL_STEP = 0.002
#: The most curves whose rows a decided way mixes.
MIXTURE = 4
_SQRT2 = math.sqrt(2.0)
_TINY = 1e-300


@dataclass(frozen=True)
class PersonFilterSettings:
    """The online filter's constants (module docstring), chosen on validation seeds (docs/precision.md).

    kappa : κ ∈ (0, 1]. decide : log-odds at which the rows follow a way round. prior_share : the share
    of ``decide`` the prior may give. divergence : [m] at which curves (or rows) count as apart.
    evidence_rate : [1/s]. accel_time, blend_time, bias_time : [s]. bias_limit : [m]. hedge_velocity :
    ∈ [0, 1]. search_window : [m] of each curve searched for the phase. max_offset : [m] beyond it the
    rows are the present estimate's. shifts : [m] along the plan each demonstration is tried at.
    noise_scale : σ in the likelihoods is this times the present estimate's noise in the calibration.
    kernel : [m] the width each hypothesis' offset stands for in the side evidence (besides σ).
    odds_limit : the log-odds never exceed it (a mind may change).
    dead_zone : [m] the present estimate's offset from the person's line counts as evidence for a way only beyond it.
    dead_zone_noise : the dead zone is at least this many times the present estimate's noise σ₀ measured in the
        person's calibration (:attr:`PathModel.noise`, before ``noise_scale``): the estimate's error is smooth (its
        correlation time ~0.18 s, some 22 ticks), so an error of 2–3 σ₀ lasts long enough for the per-tick evidence
        to decide a way the person is not taking (docs/person-model.md). 0: the fixed ``dead_zone`` alone.
    reaction_lead : [s] the present estimate is put this far ahead along the tool's velocity. With a
        measured arm, Ĉ holds the person's reaction delay (the force answers the intent of τ ago:
        Ĉ = C − K̂τ), so q̂ is where the person wanted the tool τ ago; the lead brings it to now.
    object_yaw : estimate the hand point on an object that yaws on its mount (the board:
        :class:`~coassist.scenario.hand_force.HandPoint`) instead of taking the tip for it.
    row_smoothing : [s] the time constant of the rows' low-pass over time, its lag advanced away
        (:class:`~coassist.scenario.row_smoothing.RowSmoothing`; 0: the rows as computed).
    residual_time : [s] τ_r, how long along the horizon the rows of a way's curves keep the present estimate's
        offset across the plan from those curves (step 4; 0: the curves' rows as they are).
    side_rule : the way's evidence per tick: "offset" (z·D/σ², the linear log-likelihood ratio of two ways whose
        offsets are ±D/2), "mixture" (each way's hypotheses' offsets as a mixture) or "onset" (each way's offset
        anywhere between the plan and ±D/2: :func:`onset_log_ratio`).
    evidence_gap : [m] the side evidence counts only where the ways' mean paths are at least this far apart.
    hedge_lateral : the hedge rows carry the tool's whole velocity (True) or only its component along the plan.
    follow_mirror : on a way round the person never took in their calibration, follow the mirror images of
        the other way's paths (True), or give the present estimate's rows there (False): the mirror knows
        nothing of how this person goes round that side.
    """

    kappa: float = 0.2
    decide: float = 1.0
    prior_share: float = 0.9
    divergence: float = 0.0005
    evidence_rate: float = 30.0
    accel_time: float = 0.02
    blend_time: float = 0.1
    bias_time: float = 0.4
    bias_limit: float = 0.005
    hedge_velocity: float = 0.5
    search_window: float = 0.02
    max_offset: float = 0.1
    shifts: tuple[float, ...] = (-0.015, 0.0, 0.015)
    noise_scale: float = 2.0
    kernel: float = 0.005
    odds_limit: float = 10.0
    shared_gap: float = 0.005
    dead_zone: float = 0.002
    dead_zone_noise: float = 0.0
    residual_time: float = 0.0
    side_rule: str = "offset"
    reaction_lead: float = 0.0
    object_yaw: bool = False
    row_smoothing: float = 0.0
    follow_mirror: bool = True
    evidence_gap: float = 0.0
    hedge_lateral: bool = True

    def __post_init__(self) -> None:
        for name, lo, hi, open_lo in (
            ("kappa", 0.0, 1.0, True),
            ("decide", 0.0, 20.0, False),
            ("prior_share", 0.0, 1.0, False),
            ("divergence", 0.0, 0.1, True),
            ("evidence_rate", 0.0, 1000.0, True),
            ("accel_time", 0.0, 1.0, False),
            ("blend_time", 0.0, 2.0, False),
            ("bias_time", 0.0, 10.0, True),
            ("bias_limit", 0.0, 0.05, False),
            ("hedge_velocity", 0.0, 1.0, False),
            ("search_window", 0.004, 0.2, False),
            ("max_offset", 0.01, 1.0, False),
            ("noise_scale", 0.1, 20.0, False),
            ("kernel", 0.0, 0.1, False),
            ("odds_limit", 1.0, 100.0, False),
            ("shared_gap", 0.0, 0.05, False),
            ("dead_zone", 0.0, 0.05, False),
            ("dead_zone_noise", 0.0, 10.0, False),
            ("residual_time", 0.0, 2.0, False),
            ("reaction_lead", 0.0, 0.3, False),
            ("row_smoothing", 0.0, 1.0, False),
            ("evidence_gap", 0.0, 0.1, False),
        ):
            object.__setattr__(
                self, name, check_real(getattr(self, name), f"PersonFilterSettings.{name}", lo, hi, open_lo=open_lo)
            )
        for flag in ("object_yaw", "follow_mirror", "hedge_lateral"):
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"PersonFilterSettings.{flag} must be true or false, got {getattr(self, flag)!r}")
        if self.side_rule not in ("offset", "mixture", "onset"):
            raise ValueError(
                f"PersonFilterSettings.side_rule must be 'offset', 'mixture' or 'onset', got {self.side_rule!r}"
            )
        if isinstance(self.shifts, (str, bytes)) or not hasattr(self.shifts, "__iter__"):
            raise ValueError(f"PersonFilterSettings.shifts must be a list of lengths [m], got {self.shifts!r}")
        shifts = tuple(check_real(x, "PersonFilterSettings.shifts", -0.2, 0.2) for x in self.shifts)
        if not shifts or len(shifts) > 9 or list(shifts) != sorted(set(shifts)):
            raise ValueError(
                f"PersonFilterSettings.shifts must be 1 to 9 distinct lengths in increasing order, got {self.shifts!r}"
            )
        object.__setattr__(self, "shifts", shifts)


def normal_cdf_between(a: float, b: float) -> float:
    """Φ(a) − Φ(b) for a ≥ b (Φ the standard normal CDF), from the tail nearer to both: no cancellation where
    both are far in the upper tail."""
    if b > 0.0:
        return 0.5 * (math.erfc(b / _SQRT2) - math.erfc(a / _SQRT2))
    return 0.5 * (math.erfc(-a / _SQRT2) - math.erfc(-b / _SQRT2))


def onset_log_ratio(z: float, h: float, sigma: float) -> float:
    """log p₊(z) / p₋(z) of an offset z [m] from the plan when under way + the person's offset there is uniform on
    [0, h] and under way − on [−h, 0] (how far into its detour the person is, unknown), each seen through Gaussian
    noise σ [m]: p₊(z) ∝ Φ(z/σ) − Φ((z − h)/σ), p₋(z) ∝ Φ((z + h)/σ) − Φ(z/σ).

    For h ≪ σ it is z·h/σ² (two Gaussians at the ways' mean offsets ±h/2: the "offset" rule with D = h); for
    h ≫ σ it no longer grows with h, only with z/σ: where the ways are far apart an offset of a millimetre is not
    the evidence of a whole way round. Odd in
    z, 0 at z = 0 or h = 0. Densities below 1e-300 are taken as 1e-300 (|z| beyond some 37 σ)."""
    if h <= 0.0:
        return 0.0
    up = normal_cdf_between(z / sigma, (z - h) / sigma)
    down = normal_cdf_between((z + h) / sigma, z / sigma)
    return math.log(max(up, _TINY)) - math.log(max(down, _TINY))


class _Curves:
    """One trial's hypotheses (module docstring): points (N, G, 2), their arc lengths (N, G) and unit
    tangents (N, G, 2), flat copies for the per-tick gathers; ways (N,), log prior (N,). And the plan
    on a grid of NOMINAL_STEP: its points and left normals (M, 2), each way's mean offset there (M,),
    and the grid index where the ways are furthest apart."""

    def __init__(self, model: PathModel, shifts: tuple[float, ...]) -> None:
        self.points, self.ways, prior = model.curves(shifts)
        # the ways round whose curves are mirror images: nobody took them in the calibration
        self.unseen = {int(w) for w in np.unique(self.ways)} - {int(w) for w in model.sides}
        self.log_prior = np.log(prior)
        N, G = self.points.shape[:2]
        seg = np.hypot(*np.moveaxis(np.diff(self.points, axis=1), 2, 0))
        self.arc = np.concatenate([np.zeros((N, 1)), np.cumsum(seg, axis=1)], axis=1)
        self.step = float(np.min(self.arc[:, -1])) / (G - 1)  # the finest spacing of any curve
        tan = np.gradient(self.points, axis=1)
        self.tangents = tan / np.maximum(np.linalg.norm(tan, axis=2, keepdims=True), 1e-12)
        self.flat_x = np.ascontiguousarray(self.points[:, :, 0]).ravel()
        self.flat_y = np.ascontiguousarray(self.points[:, :, 1]).ravel()
        self.flat_points = self.points.reshape(N * G, 2)
        self.flat_tangents = self.tangents.reshape(N * G, 2)
        self.flat_arc = self.arc.ravel()
        # for :meth:`along`: the arc lengths of curve n offset by n times a stride longer than any curve (one
        # increasing array), each segment's point step and inverse length (0 for a repeated point)
        self.arc_end = self.arc[:, -1].copy()
        self.key_start = np.arange(N) * (float(np.max(self.arc_end)) + 1.0)
        self.flat_key = (self.arc + self.key_start[:, None]).ravel()
        seg_len = np.diff(self.flat_key, append=self.flat_key[-1])
        self.flat_inv = np.divide(1.0, seg_len, out=np.zeros_like(seg_len), where=seg_len > 0.0)
        self.flat_step = np.diff(self.flat_points, axis=0, append=self.flat_points[-1:])
        self.row_start = np.arange(N) * G
        self.row_last = self.row_start + G - 2
        self.curves = np.arange(N)
        self.on_way = {w: np.flatnonzero(self.ways == w) for w in np.unique(self.ways).tolist()}
        frame = PathFrame(model.nominal)
        M = max(2, int(math.ceil(frame.length / NOMINAL_STEP)) + 1)
        s = np.linspace(0.0, frame.length, M)
        self.nominal_step = float(s[1] - s[0])
        self.nominal_points = frame.path.position(s)
        self.nominal_normals = frame.path.normal(s)
        # every hypothesis' offset from the plan at each grid point (where it first reaches it): the side
        # evidence compares the present estimate's offset with them
        offsets = []
        for n in range(N):
            sn, dn = frame.project(self.points[n])
            sn = np.maximum.accumulate(sn)
            first = np.concatenate([[True], np.diff(sn) > 0.0])
            offsets.append(np.interp(s, sn[first], dn[first]))
        self.offsets = np.asarray(offsets)  # (N, M)
        self.spread = np.ptp(self.offsets, axis=0)  # (M,) how far the hypotheses disagree there
        mean = {
            w: np.exp(self.log_prior[i] - np.logaddexp.reduce(self.log_prior[i])) @ self.offsets[i]
            for w, i in self.on_way.items()
        }
        # how far apart the ways' (prior-weighted) mean paths are at each point of the plan [m]
        self.gap = np.abs(mean[1] - mean[-1]) if len(mean) == 2 else np.abs(next(iter(mean.values())))
        # the way taken is settled once the tool passes the place where the ways are furthest apart
        self.peak = int(np.argmax(self.gap))

    def along(self, n: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Points of curves n (k,) at their own arc lengths s (k, H), clipped to each curve: (k, H, 2). One
        search over every curve at once: each curve's arc lengths are offset by its index times a stride
        longer than any curve, so the flat array is increasing and one ``searchsorted`` finds every segment."""
        s = np.minimum(np.maximum(s, 0.0), self.arc_end[n][:, None])
        key = s + self.key_start[n][:, None]
        j = np.minimum(
            np.maximum(self.flat_key.searchsorted(key, side="right") - 1, self.row_start[n][:, None]),
            self.row_last[n][:, None],
        )
        t = ((key - self.flat_key[j]) * self.flat_inv[j])[..., None]
        return self.flat_points[j] + t * self.flat_step[j]


class PersonPathsIntent:
    """The intent source of a person model (module docstring), one trial at a time.

    Parameters
    ----------
    horizon : rows predicted.
    paths : person (TrialContext.user) → their :class:`PathModel`.
    arms : person → :class:`ArmEstimate`.
    default_paths : the path model for anyone not in ``paths`` (None: the present estimate alone for them).
    default_arm : the arm for anyone not in ``arms`` (None: the assumed arm).
    settings : the filter's constants.
    model_id : what trials record as the source.
    extrapolation : the share e ∈ [0, 1] of the tool's velocity the present estimate's rows carry where
        there is no path model (or the tool is far from its paths): q + e·i·dt·v (0: held, 1: constant velocity).
    """

    history = 1

    def __init__(
        self,
        horizon: int = 50,
        *,
        paths: Mapping[str, PathModel] | None = None,
        arms: Mapping[str, ArmEstimate] | None = None,
        default_paths: PathModel | None = None,
        default_arm: ArmEstimate | None = None,
        settings: PersonFilterSettings | None = None,
        model_id: str = "person",
        extrapolation: float = 1.0,
    ) -> None:
        self.horizon = check_int(horizon, "PersonPathsIntent.horizon", 1)
        self.extrapolation = check_real(extrapolation, "PersonPathsIntent.extrapolation", 0.0, 1.0)
        self.paths = dict(paths or {})
        self.arms = dict(arms or {})
        self.default_paths = default_paths
        self.default_arm = ASSUMED_ARM if default_arm is None else default_arm
        self.settings = PersonFilterSettings() if settings is None else settings
        self.model_id = model_id
        self._ready = False
        self._cache: dict[int, tuple[PathFrame, _Curves]] = {}

    def _curves(self, model: PathModel) -> tuple[PathFrame, _Curves]:
        key = id(model)
        if key not in self._cache:
            self._cache[key] = (PathFrame(model.nominal), _Curves(model, self.settings.shifts))
        return self._cache[key]

    def reset(self, context: TrialContext) -> None:
        st = self.settings
        self.dt = float(context.dt)
        self._steps = self.dt * np.arange(1, self.horizon + 1)
        self._present_steps = (self.extrapolation * self._steps)[:, None]
        self._hedge_steps = (st.hedge_velocity * self._steps)[:, None]
        self._hand = HandForce(self.dt, st.accel_time, context.object)
        self._yaw = HandPoint(self.dt, context.object) if st.object_yaw else None
        self._b_gain = 1.0 - math.exp(-self.dt / st.bias_time)
        arm = self.arms.get(context.user, self.default_arm)
        self._K, self._C = arm.stiffness, arm.damping
        self._lead_time = st.reaction_lead
        self._smoothing = RowSmoothing(self.dt, st.row_smoothing, self.horizon)
        model = self.paths.get(context.user, self.default_paths)
        self._hyp: _Curves | None = None
        if model is not None and context.path is not None:
            frame, curves = self._curves(model)
            # the model knows one plan: another plan gets the present estimate alone
            if frame.distance_to(np.asarray(context.path, dtype=float)) <= 0.01:
                self._hyp = curves
        if self._hyp is not None and model is not None:
            hyp = self._hyp
            self._noise = st.noise_scale * model.noise
            self._noise2 = self._noise**2
            self._dead_zone = max(st.dead_zone, st.dead_zone_noise * model.noise)
            self._residual = np.exp(-self._steps / st.residual_time) if st.residual_time > 0.0 else None
            self._kernel2 = self._noise2 + st.kernel**2
            n = len(hyp.ways)
            self._idx = np.zeros(len(hyp.curves), dtype=int)
            self._nominal_at = 0
            self._nominal_window = max(2, int(math.ceil(st.search_window / hyp.nominal_step)))
            self._loglik = np.zeros(n)
            self._two = len(hyp.on_way) == 2
            bound = st.prior_share * st.decide
            if self._two:
                lp = {w: float(np.logaddexp.reduce(hyp.log_prior[i])) for w, i in hyp.on_way.items()}
                self._way_prior = lp[1] - lp[-1]  # the evidence per tick is the likelihood ratio alone
                self._log_odds = min(max(self._way_prior, -bound), bound)
            else:
                self._log_odds = self._way_prior = 0.0
            self._kappa = st.kappa * self.dt / REFERENCE_DT
            self._step_cap = st.evidence_rate * self.dt
            self._widest = max(2, int(math.ceil(st.search_window / hyp.step)))
            self._offsets = np.arange(-self._widest, self._widest + 1)[None, :]
            self._bias = 0.0
            self._side = 0 if self._two else int(hyp.ways[0])
            self._mix = 1.0
            self._mix_step = self.dt / st.blend_time if st.blend_time > 0 else 1.0
        self._ready = True

    @property
    def side(self) -> int:
        """The way round the rows follow: +1 left, −1 right, 0 undecided (or no model)."""
        return self._side if self._hyp is not None else 0

    def predict(self, history: np.ndarray) -> np.ndarray:
        if not self._ready:
            raise RuntimeError("PersonPathsIntent.predict called before reset")
        row = history[-1]
        p, v, w = row[0:2], row[2:4], row[4:6]
        u_h = self._hand(v, w)  # the hand's force, the object's inertia put back
        if self._yaw is not None:  # the hand point, not the tip: the object's yaw on its mount
            dp, dv = self._yaw(u_h, self._hand.acc)
            p, v = p + dp, v + dv
        present = p + (u_h + self._C * v) / self._K + self._lead_time * v
        if self._hyp is None:
            return present + self._present_steps * v
        return self._smoothing(self._filter(self._hyp, p, v, u_h, present))

    def _filter(self, hyp: _Curves, p: np.ndarray, v: np.ndarray, u_h: np.ndarray, present: np.ndarray) -> np.ndarray:
        st = self.settings
        K, C = self._K, self._C
        G = hyp.points.shape[1]
        # 2. the tool's phase on every curve: its nearest point within the search window of the last one
        # (every step below is a handful of whole-array operations: the tick's cost is their count, not their size)
        flat = np.minimum(np.maximum(self._idx[:, None] + self._offsets, 0), G - 1) + hyp.row_start[:, None]
        dx = hyp.flat_x[flat] - p[0]
        dy = hyp.flat_y[flat] - p[1]
        d2 = dx * dx + dy * dy
        best = d2.argmin(axis=1)
        at = flat[hyp.curves, best]
        self._idx = at - hyp.row_start
        d2_at = d2[hyp.curves, best]
        if float(d2_at.min()) > st.max_offset**2:
            return present + self._present_steps * v
        # a curve whose phase is held in a local minimum far from the tool (the person left it, round a detour wider
        # than any demonstrated, and came back elsewhere) gives no rows: followed, its rows pulled the tool back
        # to where it was left (held-out operator, seed 1: 35 N against the person until the time limit)
        near = d2_at <= st.max_offset**2
        tan = hyp.flat_tangents[at]
        point = hyp.flat_points[at]
        # the tool's place along each curve, between its samples (a phase stuck to the samples would step the
        # rows by their spacing), then the lead along the curve
        along = np.minimum(np.maximum(((p - point) * tan).sum(axis=1), -hyp.step), hyp.step)
        tv = tan @ v
        lead = (tan @ u_h + C * tv) / K + self._lead_time * tv
        q = point + (along + lead)[:, None] * tan
        s_lead = hyp.flat_arc[at] + along + lead
        # 3. evidence. The way: the present estimate's offset from the plan (less the person's bias there),
        # toward one way or the other, in proportion to how far apart the ways are at this point of the plan
        # (a detour that comes later or earlier than before fakes no side)
        g, M = self._nominal_at, len(hyp.nominal_points)
        lo, hi = max(0, g - self._nominal_window), min(M, g + self._nominal_window + 1)
        rel = p - hyp.nominal_points[lo:hi]
        self._nominal_at = k = lo + int(np.argmin(rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1]))
        normal = hyp.nominal_normals[k]
        z = float((present - hyp.nominal_points[k]) @ normal)
        # the hedge's velocity: the tool's, or only its progress along the plan (module docstring, step 4)
        hv = v if st.hedge_lateral else v - float(v @ normal) * normal
        D = float(hyp.gap[k])
        if D < st.shared_gap:
            if self._mix >= 1.0:  # the bias: learnt where the ways are still one path
                self._bias += self._b_gain * (z - self._bias)
                self._bias = min(max(self._bias, -st.bias_limit), st.bias_limit)
        if self._two and D >= st.divergence and D >= st.evidence_gap and (self._side == 0 or k < hyp.peak):
            if st.side_rule == "mixture":
                # each way's likelihood of the offset: a mixture over its hypotheses' offsets here
                e = hyp.offsets[:, k] - (z - self._bias)
                ll = hyp.log_prior - 0.5 * e * e / self._kernel2
                gain = self._kappa * float(
                    np.logaddexp.reduce(ll[hyp.on_way[1]]) - np.logaddexp.reduce(ll[hyp.on_way[-1]]) - self._way_prior
                )
            else:
                # the offset from the person's line, beyond a dead zone, toward the way it points to, in
                # proportion to how far the ways are apart here: staying on the line is no evidence against
                # a way that would have left it already (its detour may come later this time)
                off = z - self._bias
                off = math.copysign(max(abs(off) - self._dead_zone, 0.0), off)
                if st.side_rule == "onset":
                    gain = self._kappa * onset_log_ratio(off, 0.5 * D, self._noise)
                else:
                    gain = self._kappa * off * D / self._noise2
            self._log_odds += min(max(gain, -self._step_cap), self._step_cap)
            self._log_odds = min(max(self._log_odds, -st.odds_limit), st.odds_limit)
        # the shape: each hypothesis' likelihood relative to its way's best, while the way's curves are apart
        corrected = present - self._bias * normal
        r = corrected - q
        r2 = r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1]
        for on in hyp.on_way.values():
            qs = q[on]
            off = qs - qs.sum(axis=0) / len(on)
            if float((off * off).sum(axis=1).max()) >= st.divergence**2:
                r2_on = r2[on]
                ll = self._loglik[on] - self._kappa * (r2_on - r2_on.min()) / (2.0 * self._noise2)
                self._loglik[on] = ll - ll.max()
        np.maximum(self._loglik, -60.0, out=self._loglik)
        if self._two and abs(self._log_odds) > st.decide:
            side = 1 if self._log_odds > 0 else -1
            if side != self._side and self._side != 0:
                self._mix = 0.0  # a change of mind goes through the present estimate, not across the obstacle
            self._side = side

        # 4. rows
        def mixture(on: np.ndarray) -> np.ndarray:
            on = on[near[on]]
            weight = np.exp(self._loglik[on] + hyp.log_prior[on] - hyp.log_prior[on].max())
            best = np.argsort(weight)[::-1][:MIXTURE]
            best = best[weight[best] >= 0.01 * weight[best[0]]]
            w = weight[best] / weight[best].sum()
            n = on[best]
            # every chosen curve's rows at once, from its present estimate at the tool's speed along it
            speed = np.maximum(tv[n], 0.0)
            rows = hyp.along(n, s_lead[n][:, None] + speed[:, None] * self._steps[None, :])
            out = (w @ rows.reshape(len(w), -1)).reshape(-1, 2)
            if self._residual is not None:
                # the present estimate's offset across the plan from these curves' own present estimates, carried
                # into the rows and fading: a person off their curves is not pulled back onto them at once
                lateral = float((corrected - w @ q[n]) @ normal)
                out = out + (lateral * self._residual)[:, None] * normal
            return out

        if not st.follow_mirror and self._side in hyp.unseen:
            self._mix = 0.0  # a way this person never showed: no curves of theirs to follow there
            return present + self._hedge_steps * hv
        ways = (self._side,) if self._side != 0 or not self._two else (1, -1)
        if not all(near[hyp.on_way[w]].any() for w in ways):
            self._mix = 0.0  # no near curve of a way the rows need: the present estimate's rows, as on a change of mind
            return present + self._hedge_steps * hv
        if self._side != 0 or not self._two:
            ahead = mixture(hyp.on_way[self._side])
            target = 1.0
        else:
            ahead = mixture(hyp.on_way[1])
            other = mixture(hyp.on_way[-1])
            apart = ahead - other
            target = 0.0 if float((apart * apart).sum(axis=1).max()) >= st.divergence**2 else 1.0
        if self._mix_step >= 1.0:
            self._mix = target
        elif target != self._mix:
            self._mix = min(max(self._mix + math.copysign(self._mix_step, target - self._mix), 0.0), 1.0)
        if self._mix >= 1.0:
            return ahead
        hedge = present + self._hedge_steps * hv
        if self._mix <= 0.0:
            return hedge
        return self._mix * ahead + (1.0 - self._mix) * hedge
