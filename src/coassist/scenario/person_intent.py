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
3. **evidence**: while a way's curves are apart, each curve's log-likelihood grows by −κ‖q − b − qₙ‖²/(2σ²)
   (σ the present estimate's noise measured in the calibration; κ discounts the correlation of successive ticks;
   b the lateral bias learnt on the shared path, as in ``paths``; with ``likelihood_memory`` τ_m the sum forgets at
   the rate 1/τ_m): it weighs a way's curves against each other (the shape), not the ways. The ways' log-odds move
   by the present estimate's offset z − b from the plan beyond a dead zone (``side_rule``: "offset" z·D/σ², the
   linear log-likelihood ratio of two ways whose offsets are ±D/2; "mixture" each way's curves' offsets as a
   mixture; "onset" each way's offset anywhere between the plan and its mean path, how far into the detour the
   person is being unknown: :func:`onset_log_ratio`), at most ``evidence_rate``·dt per tick, from the ways'
   prior (bounded to ``prior_share`` of ``decide``: a habit never decides alone), counted only where the ways'
   mean paths are ``evidence_gap`` apart and, once a way is decided, only until the tool passes the place where they
   are furthest apart: a person still on the plan where their demonstrations had already left it says nothing
   about the way. With ``side_orientation`` the offset counts toward the way whose mean path lies on its side
   there, not the left way wherever it is to the left: a person who leans the wrong way before going round (the
   left way's paths right of the right way's there) is read by their own paths;
4. **rows**: once |log-odds| > ``decide`` the rows run along the decided way's likeliest curves
   (at most :data:`MIXTURE`, weighted) from their present estimates at the tool's speed along
   them (on a way nobody took, with ``follow_mirror`` off, the present estimate's rows instead); while
   undecided and the ways' rows part by more than ``divergence`` over the horizon, the
   rows are the present estimate's, q + ``hedge_velocity``·i·dt·v — neither way, and never the plan
   (with ``hedge_lateral`` off, v's component across the plan is left out: extrapolated, the tool's own
   sideways drift became the robot's push and then evidence for a way; with ``hedge_leaving`` h < 1, while the
   present estimate is beyond the dead zone from the person's line, h·v: the person is leaving the plan, and the
   plan's way on is no longer where they go).
   The two cross-fade over ``blend_time``. With ``residual_time`` τ_r > 0 each way's rows from its curves carry
   the present estimate's offset across the plan from the chosen curves' own present estimates, fading along the
   horizon: row_i += ((q − b − Σₙ wₙ qₙ)·n̂) e^{−i·dt/τ_r} n̂ (n̂ the plan's left normal where the tool is): a
   person off their curves (a turn earlier than any demonstrated) is not pulled back onto them at once. While
   undecided, the two ways' rows compared against ``divergence`` are these rows too.
5. **smoothing**: the rows are low-passed over time with a time constant ``row_smoothing`` and
   advanced by the filter's lag (:class:`~coassist.scenario.row_smoothing.RowSmoothing`): the
   tick-to-tick noise of the phase, the lead and the mixture leaves the robot's effort, and with it
   the tool's jerk.
6. **brake**: with ``brake_time`` τ_b every row then lags the tool by τ_b of its velocity, rows − τ_b·v: the game's
   pull toward the rows damps the motion too (a trade of hand force for overshoot, docs/person-model.md).

Where the tool is far from every curve (``max_offset``: another task, a person who left the plan
for good), the rows are the present estimate's at constant velocity (``extrapolation``); where
the model knows no path for the person or the trial's plan, the present estimate held (as the
default source, ``present-held``). A curve whose phase is held more than ``max_offset`` from the tool (left in a
local minimum round a detour wider than any demonstrated) gives no rows, and a way with none near
gives the present estimate's rows, as on a change of mind.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from coassist._checks import check_int, check_real
from coassist.interfaces import TrialContext
from coassist.scenario.arm_identification import ASSUMED_ARM, ArmEstimate
from coassist.scenario.curve_search import CurveSearch, window_distances
from coassist.scenario.hand_force import HandForce, HandPoint
from coassist.scenario.path_model import PathFrame, PathModel
from coassist.scenario.row_smoothing import RowSmoothing

__all__ = ["PersonFilterSettings", "PersonPathsIntent", "normal_cdf_between", "onset_log_ratio", "same_plan"]

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
    hedge_leaving : the share of that velocity the hedge rows carry while the present estimate is off the person's
        line by more than the dead zone (the person leaving the plan, the way not yet decided): the plan's way on
        is then no longer where the person goes (1: the same as elsewhere).
    pace_time : [s] τ_p. 0: the decided way's rows run along its curves at the tool's speed along each. > 0: at the
        person's pace, the tool's speed plus the rate of the present estimate's lead along the curve (its force and
        damping term, what the person wants beyond where the tool is), that rate the lead's washout over τ_p,
        (ℓ − ℓ̄)/τ_p with ℓ̄ ← ℓ̄ + (1 − e^(−dt/τ_p))(ℓ − ℓ̄): a person who slows pulls back on the tool, and rows
        at the tool's speed carried it on past them.
    follow_mirror : on a way round the person never took in their calibration, follow the mirror images of
        the other way's paths (True), or give the present estimate's rows there (False): the mirror knows
        nothing of how this person goes round that side.
    min_way_paths : a way round shown at least once but in fewer of the calibration's paths than this gives the
        present estimate's rows, as a way nobody took does with ``follow_mirror`` off (a way nobody took is left to
        ``follow_mirror``; 1: every way shown at least once is followed).
    side_orientation : with the "offset" and "onset" rules, read the present estimate's offset as evidence for the way
        whose mean path lies on that side of the other's at this point of the plan (True), or for the left way wherever
        the offset is to the left (False). The two differ only where the left way's mean path lies right of the right
        way's: a person whose paths lean the wrong way before going round (a feint), whose lean read as left-is-left
        decided the way they were not taking.
    likelihood_memory : [s] τ_m. 0: each curve's log-likelihood sums the evidence of the whole trial (step 3). > 0:
        it forgets at the rate 1/τ_m (ℓₙ ← e^(−dt/τ_m)·ℓₙ − the tick's term, where the way's curves are apart): a
        person whose trial follows one demonstration on the way out and another on the way back (a return that rings
        as some trials rang) is read by what they did in the last τ_m or so.
    brake_time : [s] τ_b. Every row the filter gives a led person lags the tool by τ_b of its velocity,
        rows − τ_b·v (v the tool's, or the hand point's with ``object_yaw``): the game's pull toward the rows then
        takes energy out of the motion, a linear damper, where the person's turn comes sooner or harder than the rows
        foresaw (docs/person-model.md, "A brake in the rows"). 0: the rows as predicted.
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
    hedge_leaving: float = 1.0
    pace_time: float = 0.0
    min_way_paths: int = 1
    side_orientation: bool = False
    likelihood_memory: float = 0.0
    brake_time: float = 0.0

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
            ("hedge_leaving", 0.0, 1.0, False),
            ("pace_time", 0.0, 5.0, False),
            ("likelihood_memory", 0.0, 60.0, False),
            ("brake_time", 0.0, 0.5, False),
        ):
            object.__setattr__(
                self, name, check_real(getattr(self, name), f"PersonFilterSettings.{name}", lo, hi, open_lo=open_lo)
            )
        object.__setattr__(
            self, "min_way_paths", check_int(self.min_way_paths, "PersonFilterSettings.min_way_paths", 1, 100)
        )
        for flag in ("object_yaw", "follow_mirror", "hedge_lateral", "side_orientation"):
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
        self.paths_of = {int(w): int(np.sum(model.sides == w)) for w in np.unique(self.ways)}  # demonstrations a way
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
        self.row_last = self.row_start + G - 2  # each curve's last segment
        # the keys after the first: a search in them finds the segment itself (the first key is 0, at or before any);
        # each curve's last key nudged up by one ulp, so its end (where s is clipped) is in its last segment
        self.key_tail = self.flat_key[1:].copy()
        self.key_tail[self.row_last] = np.nextafter(self.key_tail[self.row_last], np.inf)
        self.on_way = {w: np.flatnonzero(self.ways == w) for w in np.unique(self.ways).tolist()}
        # each way's log prior, and its highest: a way's weights are relative to it (while all its curves are near)
        self.way_log_prior = {w: self.log_prior[i] for w, i in self.on_way.items()}
        self.log_prior_max = {w: float(np.max(self.log_prior[i])) for w, i in self.on_way.items()}
        # the curves way by way (each in on_way's order), for the tick's per-way sums and extremes in one call each:
        # by_way (N,) the curves in that order, way_rank (N,) the rank of each one's way there, way_starts
        # (ways,) where each way's run begins, way_slice its run; way_padded (ways, most curves of a way) each
        # way's curves padded with N (a row of zeros the tick appends to its points: a sum in the order of
        # on_way, plus zeros), way_count (ways, 1) their numbers
        counts = [len(i) for i in self.on_way.values()]
        starts = np.cumsum([0, *counts[:-1]])
        self.by_way = np.concatenate(list(self.on_way.values()))
        self.way_rank = np.repeat(np.arange(len(counts)), counts)
        self.way_starts = starts
        self.way_slice = {w: slice(int(a), int(a) + c) for w, a, c in zip(self.on_way, starts, counts)}
        self.way_padded = np.full((len(counts), max(counts)), N)
        for row, i in zip(self.way_padded, self.on_way.values()):
            row[: len(i)] = i
        self.way_count = np.asarray(counts, dtype=float)[:, None]
        self.search = CurveSearch(self.flat_x, self.flat_y, N, G)  # the phase search's tables, per window width
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
        # how far apart the ways' (prior-weighted) mean paths are at each point of the plan [m], and which side of the
        # right way's the left way's lies: +1 left, −1 where it lies right of it (a person who leans the wrong way
        # before going round: a feint)
        apart = mean[1] - mean[-1] if len(mean) == 2 else next(iter(mean.values()))
        self.gap = np.abs(apart)
        # the way taken is settled once the tool passes the place where the ways are furthest apart
        self.peak = int(np.argmax(self.gap))
        # the plan's grid as Python floats, for the tick's scalar arithmetic on one point of it
        self.nominal_list = self.nominal_points.tolist()
        self.normal_list = self.nominal_normals.tolist()
        self.gap_list = self.gap.tolist()
        self.way_sign_list = np.where(apart < 0.0, -1.0, 1.0).tolist()  # read by the side evidence of two ways only

    def along(self, n: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Points of curves n (k,) at their own arc lengths s (k, H), clipped to each curve: (k, H, 2). One
        search over every curve at once: each curve's arc lengths are offset by its index times a stride
        longer than any curve, so the flat array is increasing and one ``searchsorted`` finds every segment
        (at or after the curve's first, whose key is where the clipped s puts it; before its last: the key of
        its end, nudged up, is above any clipped s)."""
        key = np.maximum(s, 0.0)
        np.minimum(key, self.arc_end.take(n)[:, None], out=key)
        key += self.key_start.take(n)[:, None]
        j = self.key_tail.searchsorted(key, side="right")
        t = key - self.flat_key.take(j)
        t *= self.flat_inv.take(j)
        out = t[..., None] * self.flat_step.take(j, axis=0)
        out += self.flat_points.take(j, axis=0)
        return out


#: The hypotheses built in this process, per (path model, shifts): a trial's source is built afresh (its state is
#: the trial's), the person's curves need not be (building them was about 78 ms of CPU a trial; issue 44). What a
#: trial does with them reads them only. Each entry holds its model, so its id is no other model's while held.
_CURVES_MEMO: dict[tuple[int, tuple[float, ...]], tuple[PathModel, PathFrame, _Curves]] = {}
_CURVES_MEMO_SIZE = 64
#: [m] a run's plan is the model's where each lies within this of the other (both ways: one-sided, a plan whose
#: vertices lie on the other's passed); the calibration's own test of one plan (person_calibration.SAME_PATH)
SAME_PLAN = 0.01
#: The run's plans as frames, per content: a run resets a source for every trial, on a few plans.
_FRAME_MEMO: dict[bytes, PathFrame] = {}
_FRAME_MEMO_SIZE = 16


def _frame_of(path: np.ndarray) -> PathFrame:
    key = np.ascontiguousarray(path, dtype=np.float64).tobytes()
    frame = _FRAME_MEMO.get(key)
    if frame is None:
        if len(_FRAME_MEMO) >= _FRAME_MEMO_SIZE:
            _FRAME_MEMO.pop(next(iter(_FRAME_MEMO)))
        frame = _FRAME_MEMO[key] = PathFrame(path)
    return frame


def same_plan(nominal: np.ndarray, path: np.ndarray, frame: PathFrame | None = None) -> bool:
    """Whether a run's plan ``path`` (P, 2) is the plan ``nominal`` a person model was recorded on: their ends within
    :data:`SAME_PLAN` and each within it of the other, both ways (one-sided, a plan whose vertices lie on the other's
    passed: a straight line from the Z's start to its end, the Z's first third). ``frame``: ``nominal``'s, where
    already built. The one test of the source (:meth:`PersonPathsIntent.reset`) and of what ``drive`` says
    (:func:`~coassist.scenario.assistance.assistance_line`)."""
    path = np.asarray(path, dtype=float)
    nominal = np.asarray(nominal, dtype=float)
    ends = max(float(np.linalg.norm(path[0] - nominal[0])), float(np.linalg.norm(path[-1] - nominal[-1])))
    frame = _frame_of(nominal) if frame is None else frame
    return (
        ends <= SAME_PLAN and frame.distance_to(path) <= SAME_PLAN and _frame_of(path).distance_to(nominal) <= SAME_PLAN
    )


class PersonPathsIntent:
    """The intent source of a person model (module docstring), one trial at a time.

    Parameters
    ----------
    horizon : rows predicted.
    paths : person (TrialContext.user) → their :class:`PathModel`.
    arms : person → :class:`ArmEstimate`.
    default_paths : the path model for anyone not in ``paths`` (None: the present estimate held, for them).
    default_arm : the arm for anyone not in ``arms`` (None: the assumed arm).
    settings : the filter's constants.
    model_id : what trials record as the source.
    extrapolation : the share e ∈ [0, 1] of the tool's velocity the present estimate's rows carry where
        there is no path model (or the tool is far from its paths): q + e·i·dt·v (0: held, 1: constant velocity).
    held : the people not led along their paths (the calibration's twin check, :mod:`coassist.sim.person_twin`):
        they get ``present-held``'s rows; :attr:`DEFAULT` among them: whoever gets the default model too.
    default_person : whose calibration ``default_paths`` and ``default_arm`` are (None: not known), for the line
        that says what the person at the handle gets.
    origins : the worlds its calibration trials came from (``TrialMeta.origin``; empty: not recorded): a run in a
        world of another kind refuses it (:func:`~coassist.scenario.assistance.check_person_world`).
    """

    history = 1
    #: The name :attr:`held` gives the default model's person (whoever else is at the handle).
    DEFAULT = "\x00default"

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
        held: Iterable[str] = (),
        default_person: str | None = None,
        origins: Iterable[str] = (),
    ) -> None:
        self.horizon = check_int(horizon, "PersonPathsIntent.horizon", 1)
        self.origins = tuple(sorted({str(o) for o in origins}))
        # the people not led along their paths (their calibration's twin overshot more with the lead than under MG:
        # coassist.sim.person_twin); DEFAULT among them: whoever gets the default model is not led either
        self.held = frozenset(str(name) for name in held)
        self.extrapolation = check_real(extrapolation, "PersonPathsIntent.extrapolation", 0.0, 1.0)
        self.paths = dict(paths or {})
        self.arms = dict(arms or {})
        self.default_paths = default_paths
        #: whose calibration the default model is (a study's own fit names its participant), where known
        self.default_person = default_person
        self.default_arm = ASSUMED_ARM if default_arm is None else default_arm
        self.settings = PersonFilterSettings() if settings is None else settings
        self.model_id = model_id
        self._ready = False

    def _curves(self, model: PathModel) -> tuple[PathFrame, _Curves]:
        """The plan's frame and the hypotheses of ``model`` at this filter's shifts, built once per process
        (:data:`_CURVES_MEMO`)."""
        key = (id(model), self.settings.shifts)
        held = _CURVES_MEMO.get(key)
        if held is None or held[0] is not model:
            if len(_CURVES_MEMO) >= _CURVES_MEMO_SIZE:
                _CURVES_MEMO.pop(next(iter(_CURVES_MEMO)))
            held = _CURVES_MEMO[key] = (model, PathFrame(model.nominal), _Curves(model, self.settings.shifts))
        return held[1], held[2]

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
        self._brake = st.brake_time
        self._smoothing = RowSmoothing(self.dt, st.row_smoothing, self.horizon)
        model = self.paths.get(context.user, self.default_paths)
        led = (context.user if context.user in self.paths else self.DEFAULT) not in self.held
        # a person the calibration's twin check turned away gets what every world gives without a calibration: the
        # present estimate held with the typical arm (present-held: never more force nor overshoot than MG)
        self._unled: PersonPathsIntent | None = None
        if not led:
            self._unled = PersonPathsIntent(self.horizon, extrapolation=0.0, model_id=self.model_id)
            self._unled.reset(context)
        self._hyp: _Curves | None = None
        if model is not None and context.path is not None and led:
            frame, curves = self._curves(model)
            # the model knows one plan: another plan gets the present estimate, held
            if same_plan(model.nominal, context.path, frame):
                self._hyp = curves
        if self._hyp is not None and model is not None:
            hyp = self._hyp
            self._noise = st.noise_scale * model.noise
            self._noise2 = self._noise**2
            self._dead_zone = max(st.dead_zone, st.dead_zone_noise * model.noise)
            self._residual = np.exp(-self._steps / st.residual_time) if st.residual_time > 0.0 else None
            self._kernel2 = self._noise2 + st.kernel**2
            n = len(hyp.ways)
            self._idx = np.zeros(n, dtype=int)
            self._nominal_at = 0
            self._nominal_window = max(2, int(math.ceil(st.search_window / hyp.nominal_step)))
            self._loglik = np.zeros(n)  # in the order of hyp.by_way
            self._memory = math.exp(-self.dt / st.likelihood_memory) if st.likelihood_memory > 0.0 else 1.0
            self._q = np.zeros((n + 1, 2))  # the curves' present estimates, and a row of zeros (hyp.way_padded)
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
            self._pad_x, self._pad_y, self._pad_first, self._window, self._pad_local = hyp.search.tables(self._widest)
            self._window_rows = np.arange(n) * len(self._window)  # each curve's first in the window's (N·(2W + 1),)
            self._max_offset2 = st.max_offset**2
            self._divergence2 = st.divergence**2
            self._two_noise2 = 2.0 * self._noise2
            self._steps_row = self._steps[None, :]
            self._residual_column = None if self._residual is None else self._residual[:, None]
            self._bias = 0.0
            self._side = 0 if self._two else int(hyp.ways[0])
            self._mix = 1.0
            self._mix_step = self.dt / st.blend_time if st.blend_time > 0 else 1.0
            self._pace_gain = 1.0 - math.exp(-self.dt / st.pace_time) if st.pace_time > 0.0 else 0.0
            self._lead_low: np.ndarray | None = None  # each curve's lead, low-passed over pace_time
        self._on_curves = self._hyp is not None
        self._ready = True

    @property
    def side(self) -> int:
        """The way round the rows follow: +1 left, −1 right, 0 undecided (or no model)."""
        return self._side if self._hyp is not None else 0

    @property
    def on_curves(self) -> bool:
        """Whether the last tick found the tool near the person's curves (within ``max_offset`` of one), so the
        rows came from reading its phase along them; False where they are the present estimate's alone (no model
        of this plan, or every curve far from the tool)."""
        return self._hyp is not None and self._on_curves

    def predict(self, history: np.ndarray) -> np.ndarray:
        if not self._ready:
            raise RuntimeError("PersonPathsIntent.predict called before reset")
        if self._unled is not None:
            return self._unled.predict(history)
        # the tick's two-vectors as Python floats: a numpy call on two elements costs more than the arithmetic
        # (each component's operations are those of the vectors', in the same order: the same bits; a dot product
        # of two is x0·y0 + x1·y1, which is what OpenBLAS's ddot gave for it, benchmarks/check_person_rows.py)
        px, py, vx, vy, wx, wy = history[-1, :6].tolist()
        total = px + py + vx + vy + wx + wy
        if total - total != 0.0:  # a NaN or an infinity in the row: kept out of every state (the filters, the odds)
            self._on_curves = False  # nothing read this tick
            return np.full((self.horizon, 2), np.nan)  # the loop's check falls back to the plan for this tick alone
        ux, uy = self._hand.step(vx, vy, wx, wy)  # the hand's force, the object's inertia put back
        if self._yaw is not None:  # the hand point, not the tip: the object's yaw on its mount
            ax, ay = self._hand.acceleration
            dpx, dpy, dvx, dvy = self._yaw.step(ux, uy, ax, ay)
            px, py, vx, vy = px + dpx, py + dpy, vx + dvx, vy + dvy
        K, C, lead = self._K, self._C, self._lead_time
        qx = px + (ux + C * vx) / K + lead * vx
        qy = py + (uy + C * vy) / K + lead * vy
        if self._hyp is None:
            if self.paths or self.default_paths is not None:
                # a person model with no path for this person or plan: the present estimate held, as the default
                # source (present-held) gives it; carried at the tool's velocity it overshot more than MG (7.4 mm
                # against 2.7, for people a model did not hold, in review)
                return np.tile(np.array((qx, qy)), (self.horizon, 1))
            # the named present-estimate sources (no paths at all): their own extrapolation
            return np.array((qx, qy)) + self._present_steps * np.array((vx, vy))
        rows = self._smoothing(self._filter(self._hyp, px, py, vx, vy, ux, uy, qx, qy))
        if self._brake > 0.0:  # every row a little behind the tool: the robot's pull toward them damps its motion
            rows = rows - np.array((self._brake * vx, self._brake * vy))  # a new array: smoothing may hand back its own
        return rows

    def _filter(
        self, hyp: _Curves, px: float, py: float, vx: float, vy: float, ux: float, uy: float, qx: float, qy: float
    ) -> np.ndarray:
        st = self.settings
        self._on_curves = True
        K, C = self._K, self._C
        v = np.array((vx, vy))
        # 2. the tool's phase on every curve: its nearest point within the search window of the last one, on the
        # curves padded with copies of their ends (:class:`~coassist.scenario.curve_search.CurveSearch`: what a clipped index reads)
        # (every step below is a handful of whole-array operations: the tick's cost is their count, not their size)
        flat = (self._pad_first + self._idx)[:, None] + self._window
        d2 = window_distances(self._pad_x, self._pad_y, flat, px, py)
        best = d2.argmin(axis=1)
        pad_at = flat[:, 0] + best
        self._idx = self._pad_local.take(pad_at)
        at = self._idx + hyp.row_start
        d2_at = d2.reshape(-1).take(self._window_rows + best)  # d2[n, best[n]]
        # a curve whose phase is held in a local minimum far from the tool (the person left it, round a detour wider
        # than any demonstrated, and came back elsewhere) gives no rows: followed, its rows pulled the tool back
        # to where it was left (held-out operator, seed 1: 35 N against the person until the time limit)
        near = None  # every curve near
        if np.maximum.reduce(d2_at) > self._max_offset2:
            if np.minimum.reduce(d2_at) > self._max_offset2:
                # the phases are held where the person left: a search for them further along (a corner cut wider
                # than the search's ±2 cm reach) would find, on a path that passes near itself (a hairpin, a Z's
                # legs), a later leg as often as the person: rows leading along it are worse than the present
                # estimate's, which serve until the person is back near a held phase
                self._on_curves = False
                return np.array((qx, qy)) + self._present_steps * v
            near = d2_at <= self._max_offset2
        tan = hyp.flat_tangents.take(at, axis=0)
        point = hyp.flat_points.take(at, axis=0)
        # the tool's place along each curve, between its samples (a phase stuck to the samples would step the
        # rows by their spacing), then the lead along the curve
        p = np.array((px, py))
        along = p - point
        along *= tan
        along = np.add.reduce(along, axis=1)
        np.maximum(along, -hyp.step, out=along)
        np.minimum(along, hyp.step, out=along)
        # t·v and t·u_h stay numpy's (N, 2) @ (2,) products on the tangents in curve order: OpenBLAS's gemv fuses
        # multiply-adds, and how depends on the row's place. The lead (t·u_h + Ĉ t·v)/K̂ + τ t·v, in place
        tv = tan @ v
        lead = tan @ np.array((ux, uy))
        lead += C * tv
        lead /= K
        lead += self._lead_time * tv
        pace = tv
        if self._pace_gain > 0.0:
            # the lead's rate: its washout over τ_p (the lead's first value is its own low-pass: no rate at the start)
            if self._lead_low is None:
                self._lead_low = lead.copy()
            rate = lead - self._lead_low
            self._lead_low += self._pace_gain * rate
            rate /= st.pace_time
            pace = tv + rate
        q = self._q[:-1]
        np.multiply((along + lead)[:, None], tan, out=q)
        q += point
        s_lead = hyp.flat_arc.take(at)
        s_lead += along
        s_lead += lead
        # 3. evidence. The way: the present estimate's offset from the plan (less the person's bias there),
        # toward one way or the other, in proportion to how far apart the ways are at this point of the plan
        # (a detour that comes later or earlier than before fakes no side)
        g, M = self._nominal_at, len(hyp.nominal_list)
        lo, hi = max(0, g - self._nominal_window), min(M, g + self._nominal_window + 1)
        rel = p - hyp.nominal_points[lo:hi]
        rel *= rel
        self._nominal_at = k = lo + int(np.add.reduce(rel, axis=1).argmin())
        nx, ny = hyp.normal_list[k]
        ox, oy = hyp.nominal_list[k]
        z = (qx - ox) * nx + (qy - oy) * ny
        # the hedge's velocity: the tool's, or only its progress along the plan (module docstring, step 4)
        if st.hedge_lateral:
            hvx, hvy = vx, vy
        else:
            vn = vx * nx + vy * ny
            hvx, hvy = vx - vn * nx, vy - vn * ny
        if st.hedge_leaving < 1.0 and abs(z - self._bias) > self._dead_zone:
            hvx, hvy = st.hedge_leaving * hvx, st.hedge_leaving * hvy
        D = hyp.gap_list[k]
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
                if st.side_orientation:
                    off *= hyp.way_sign_list[k]  # toward the way whose mean path lies on that side here
                off = math.copysign(max(abs(off) - self._dead_zone, 0.0), off)
                if st.side_rule == "onset":
                    gain = self._kappa * onset_log_ratio(off, 0.5 * D, self._noise)
                else:
                    gain = self._kappa * off * D / self._noise2
            self._log_odds += min(max(gain, -self._step_cap), self._step_cap)
            self._log_odds = min(max(self._log_odds, -st.odds_limit), st.odds_limit)
        # the shape: each hypothesis' likelihood relative to its way's best, while the way's curves are apart
        cx, cy = qx - self._bias * nx, qy - self._bias * ny
        # way by way (hyp.by_way): each way's mean present estimate, and how far its curves' are from it
        ranks, starts = hyp.way_rank, hyp.way_starts
        mean = np.add.reduce(self._q.take(hyp.way_padded, axis=0), axis=1)
        mean /= hyp.way_count
        qs = self._q.take(hyp.by_way, axis=0)
        off = qs - mean.take(ranks, axis=0)
        off *= off
        apart = (np.maximum.reduceat(np.add.reduce(off, axis=1), starts) >= self._divergence2).tolist()
        loglik = self._loglik
        if any(apart):
            r = np.array((cx, cy)) - qs
            r *= r
            ll = np.add.reduce(r, axis=1)
            ll -= np.minimum.reduceat(ll, starts).take(ranks)
            ll *= self._kappa
            ll /= self._two_noise2
            # the evidence of long ago fades (likelihood_memory; without it the factor is 1, which changes no bit)
            np.subtract(self._memory * loglik, ll, out=ll)
            ll -= np.maximum.reduceat(ll, starts).take(ranks)
            if all(apart):
                self._loglik = loglik = ll
            else:
                for way, moves in zip(hyp.on_way, apart):
                    if moves:
                        loglik[hyp.way_slice[way]] = ll[hyp.way_slice[way]]
        np.maximum(loglik, -60.0, out=loglik)
        if self._two and abs(self._log_odds) > st.decide:
            side = 1 if self._log_odds > 0 else -1
            if side != self._side and self._side != 0:
                self._mix = 0.0  # a change of mind goes through the present estimate, not across the obstacle
            self._side = side

        # 4. rows
        def mixture(way: int) -> np.ndarray:
            on, mine = hyp.on_way[way], loglik[hyp.way_slice[way]]
            if near is None:  # every curve near: the way's prior and its highest are known
                prior, top = hyp.way_log_prior[way], hyp.log_prior_max[way]
            else:
                keep = near.take(on)
                on, mine = on[keep], mine[keep]
                prior = hyp.log_prior.take(on)
                top = np.maximum.reduce(prior)
            weight = mine + prior
            weight -= top
            np.exp(weight, out=weight)
            best = weight.argsort()[::-1][:MIXTURE]
            w = weight.take(best)
            # the weights are in decreasing order: those above a hundredth of the first are the first few
            first = w.tolist()
            if not first[-1] >= 0.01 * first[0]:
                kept = sum(x >= 0.01 * first[0] for x in first)
                best, w = best[:kept], w[:kept]
            w /= np.add.reduce(w)
            n = on.take(best)
            # every chosen curve's rows at once, from its present estimate at the tool's speed along it
            speed = np.maximum(pace.take(n), 0.0)
            rows = hyp.along(n, s_lead.take(n)[:, None] + speed[:, None] * self._steps_row)
            out = (w @ rows.reshape(len(w), -1)).reshape(-1, 2)
            if self._residual is not None:
                # the present estimate's offset across the plan from these curves' own present estimates, carried
                # into the rows and fading: a person off their curves is not pulled back onto them at once
                mx, my = (w @ q.take(n, axis=0)).tolist()
                lateral = (cx - mx) * nx + (cy - my) * ny
                out += lateral * self._residual_column * hyp.nominal_normals[k]
            return out

        if (not st.follow_mirror and self._side in hyp.unseen) or 0 < hyp.paths_of.get(
            self._side, 0
        ) < st.min_way_paths:
            self._mix = 0.0  # a way this person never showed (or too few times): no curves of theirs to follow there
            return np.array((qx, qy)) + self._hedge_steps * np.array((hvx, hvy))
        ways = (self._side,) if self._side != 0 or not self._two else (1, -1)
        if near is not None and not all(near[hyp.on_way[w]].any() for w in ways):
            self._mix = 0.0  # no near curve of a way the rows need: the present estimate's rows, as on a change of mind
            return np.array((qx, qy)) + self._hedge_steps * np.array((hvx, hvy))
        if self._side != 0 or not self._two:
            ahead = mixture(self._side)
            target = 1.0
        else:
            ahead = mixture(1)
            apart = ahead - mixture(-1)
            apart *= apart
            target = 0.0 if np.maximum.reduce(np.add.reduce(apart, axis=1)) >= self._divergence2 else 1.0
        if self._mix_step >= 1.0:
            self._mix = target
        elif target != self._mix:
            self._mix = min(max(self._mix + math.copysign(self._mix_step, target - self._mix), 0.0), 1.0)
        if self._mix >= 1.0:
            return ahead
        hedge = np.array((qx, qy)) + self._hedge_steps * np.array((hvx, hvy))
        if self._mix <= 0.0:
            return hedge
        return self._mix * ahead + (1.0 - self._mix) * hedge
