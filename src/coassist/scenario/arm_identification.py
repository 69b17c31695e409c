"""The person's arm, measured from their calibration trials: stiffness K̂ and damping Ĉ of eq. 4.1.

The present estimate of where the person wants the tool (coassist.scenario.person_intent)
solves the arm's law (thesis eq. 4.1, the physical sign of docs/architecture.md)::

    u_h = K (x_ref,h − p) − C v     ⇒     x_ref,h = p + (u_h + C v) / K

for the intent; it needs K and C, and people differ by a factor of several (the simulated
users: 460–1300 N/m; a relaxed or a braced arm, a light or a firm grip).

Under manual guidance alone K cannot be measured: whatever the arm's stiffness, some intent
explains the trial. The calibration trials therefore run with the probe
(coassist.control.probe, controller ``manual-probe``): a small known push r(k) that the
person does not plan. High-passed (zero-phase Butterworth, order 4, ``highpass`` Hz) to remove
the person's deliberate motion, the arm's response is a causal filter of the tool's motion::

    w̃(k) = −Σ_j a_j p̃(k − j) − c ṽ(k) + ñ(k)          j ∈ LAGS (0 … 24 ticks: the measurement's lag
                                                     and a reflex delay up to ~0.15 s at 125 Hz)

per axis, both axes pooled; ñ, the person's own force fluctuations, drives the tool too, so it
correlates with p̃ and ordinary least squares is biased. The probe is independent of the
person: its lags z(k) = [r̃(k), r̃(k − 3), …, r̃(k − 57)] are instruments, and two-stage least
squares (regress [p̃ lags, ṽ] on z, then w̃ on the fitted values) estimates a and c
consistently. Single a_j are poorly determined (neighbouring lags of a smooth motion are
nearly collinear), but what the present estimate needs is the arm at the intent's slow time
scale — the low-frequency end of its impedance — and that is well determined::

    K̂ = Σ_j a_j                       the static stiffness [N/m]
    Ĉ = c − Σ_j a_j · j · dt          the effective damping [N·s/m]: u_h ≈ K̂ (x_ref,h − p) − Ĉ v

(the first-order expansion of the filter, p(k − j) ≈ p(k) − j dt v). A reflex delay τ acting
through a share β of the stiffness lowers Ĉ by β K τ, and the sensor's own lag by K times
it: Ĉ may be negative, and is what the present estimate needs. On a simulated arm of known K
and C (10 probe trials of the curved path at 2.5 N RMS) this recovers K = 350, 700, 1400 N/m
within one standard error (about 9 %), with or without a 80 ms reflex through half the
stiffness (tests/scenario/test_arm_identification.py). The spread is the jackknife over trials.

Without the probe in the trials (plain MG recordings), the arm cannot be measured:
:func:`identify_arm` then says so and returns the assumed arm (:data:`ASSUMED_ARM`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from coassist._checks import check_int, check_real

__all__ = [
    "ARM_SE_MAX",
    "ASSUMED_ARM",
    "DAMPING_RANGE",
    "MIN_TRIAL_S",
    "STIFFNESS_RANGE",
    "ArmEstimate",
    "identify_arm",
    "measured_arm",
]


#: What a person's arm can be: K̂ [N/m] from a limp to a fully braced arm, Ĉ [N·s/m] (may be negative).
STIFFNESS_RANGE = (100.0, 5000.0)
DAMPING_RANGE = (-100.0, 200.0)
#: The largest relative jackknife error of K̂ a measured arm may have to be used (:func:`measured_arm`).
ARM_SE_MAX = 0.5


@dataclass(frozen=True)
class ArmEstimate:
    """The arm the present estimate uses: stiffness K̂ [N/m], effective damping Ĉ [N·s/m] (module
    docstring; may be negative), their jackknife standard errors, the samples and trials measured
    (0 trials: assumed, not measured) and how (``"probe-iv"`` or ``"assumed"``).

    Bounds are what a person's arm can be: K̂ 100–5000 N/m (a limp to a fully braced arm), Ĉ
    −100 … 200 N·s/m."""

    stiffness: float = 800.0
    damping: float = 10.0
    stiffness_se: float = 0.0
    damping_se: float = 0.0
    samples: int = 0
    trials: int = 0
    method: str = "assumed"

    def __post_init__(self) -> None:
        object.__setattr__(self, "stiffness", check_real(self.stiffness, "ArmEstimate.stiffness", *STIFFNESS_RANGE))
        object.__setattr__(self, "damping", check_real(self.damping, "ArmEstimate.damping", *DAMPING_RANGE))
        object.__setattr__(self, "stiffness_se", check_real(self.stiffness_se, "ArmEstimate.stiffness_se", 0.0, 5000.0))
        object.__setattr__(self, "damping_se", check_real(self.damping_se, "ArmEstimate.damping_se", 0.0, 300.0))
        object.__setattr__(self, "samples", check_int(self.samples, "ArmEstimate.samples", 0))
        object.__setattr__(self, "trials", check_int(self.trials, "ArmEstimate.trials", 0))
        if self.method not in ("probe-iv", "assumed"):
            raise ValueError(f"ArmEstimate.method must be 'probe-iv' or 'assumed', got {self.method!r}")


#: The arm assumed where none was measured: the simulated author's relaxed-to-mid arm.
ASSUMED_ARM = ArmEstimate()

#: Lags of the probe used as instruments [ticks]: 0 … 57 every 3 (0.46 s at 125 Hz, the arm's
#: response and the plant's together).
INSTRUMENT_LAGS = tuple(range(0, 60, 3))
#: Lags of the tool's position in the arm's filter [ticks] (module docstring).
LAGS = tuple(range(0, 25, 2))
#: The probe must reach this RMS [N] in the trials' high-passed robot effort to be measured.
MIN_PROBE_RMS = 0.2
#: [s] a shorter trial is not used (the filter's edges, 0.5 s at each end, would leave too little).
MIN_TRIAL_S = 3.0


def _lagged(x: np.ndarray, lags: Sequence[int]) -> np.ndarray:
    out = np.zeros((len(x), len(lags)))
    for j, lag in enumerate(lags):
        out[lag:, j] = x[: len(x) - lag] if lag else x
    return out


def _stage_rows(
    pose: np.ndarray, velocity: np.ndarray, wrench: np.ndarray, probe: np.ndarray, dt: float, highpass: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(y, X, Z) of one trial for the two stages: both axes stacked; the first and last 0.5 s left out
    (the filter's edges)."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, highpass, "highpass", fs=1.0 / dt, output="sos")
    p, v, w, r = (sosfiltfilt(sos, a, axis=0) for a in (pose, velocity, wrench, probe))
    edge = int(round(0.5 / dt))
    ys, xs, zs = [], [], []
    for axis in range(2):
        keep = slice(edge, len(p) - edge)
        ys.append(w[keep, axis])
        xs.append(np.concatenate([_lagged(p[:, axis], LAGS), v[:, axis : axis + 1]], axis=1)[keep])
        zs.append(_lagged(r[:, axis], INSTRUMENT_LAGS)[keep])
    return np.concatenate(ys), np.concatenate(xs), np.concatenate(zs)


def _two_stage(y: np.ndarray, X: np.ndarray, Z: np.ndarray, dt: float) -> tuple[float, float]:
    """(K̂, Ĉ) of the module docstring by two-stage least squares."""
    fitted = Z @ np.linalg.lstsq(Z, X, rcond=None)[0]
    b = np.linalg.lstsq(fitted, y, rcond=None)[0]
    a, c = -b[:-1], -float(b[-1])
    return float(a.sum()), c - float(np.sum(a * np.asarray(LAGS) * dt))


def identify_arm(trials: Sequence, *, highpass: float = 0.8) -> ArmEstimate:
    """K̂ and Ĉ of one person from their calibration trials (module docstring).

    trials : coassist.data.Trial objects of one person with the probe in the loop (``effort_r``
        the robot's effort, planar x-y), the handle (the sensor reads the hand's force).
    highpass : [Hz] the corner below which the person's deliberate motion is removed.

    Trials without the probe (no ``effort_r``, or less than :data:`MIN_PROBE_RMS` of it in the band)
    are skipped; with none left the result is :data:`ASSUMED_ARM`.
    """
    highpass = check_real(highpass, "highpass", 0.1, 10.0)
    rows = []
    dt = 0.0
    for trial in trials:
        if trial.effort_r is None or trial.pose.shape[1] < 2 or len(trial.time) < int(MIN_TRIAL_S / trial.meta.dt):
            continue
        dt = float(trial.meta.dt)
        y, X, Z = _stage_rows(
            trial.pose[:, :2], trial.velocity[:, :2], trial.wrench[:, :2], trial.effort_r[:, :2], dt, highpass
        )
        if math.sqrt(float(np.mean(Z[:, 0] ** 2))) < MIN_PROBE_RMS:
            continue
        rows.append((y, X, Z))
    if not rows:
        return ASSUMED_ARM
    y, X, Z = (np.concatenate([r[i] for r in rows]) for i in range(3))
    stiffness, damping = _two_stage(y, X, Z, dt)
    se = (0.0, 0.0)
    if len(rows) >= 3:  # jackknife over trials
        leave = []
        for j in range(len(rows)):
            rest = [r for i, r in enumerate(rows) if i != j]
            yj, Xj, Zj = (np.concatenate([r[i] for r in rest]) for i in range(3))
            leave.append(_two_stage(yj, Xj, Zj, dt))
        L = np.asarray(leave)
        n = len(rows)
        se = tuple(float(math.sqrt((n - 1) / n * np.sum((L[:, i] - L[:, i].mean()) ** 2))) for i in range(2))  # type: ignore[assignment]
    return ArmEstimate(
        stiffness=min(max(stiffness, STIFFNESS_RANGE[0]), STIFFNESS_RANGE[1]),
        damping=min(max(damping, DAMPING_RANGE[0]), DAMPING_RANGE[1]),
        stiffness_se=min(se[0], 5000.0),
        damping_se=min(se[1], 300.0),
        samples=len(y),
        trials=len(rows),
        method="probe-iv",
    )


def measured_arm(arm: ArmEstimate) -> tuple[ArmEstimate, str]:
    """(the arm to use, why the typical one is assumed: "" when the measured one is used) of :func:`identify_arm`'s
    estimate ``arm``. The typical arm (:data:`ASSUMED_ARM`) is used where nothing was measured, and where the
    measurement says too little to be used: K̂ or Ĉ at the bound of a person's range (:func:`identify_arm` clips
    to it: the clipped value is no measurement), fewer than three trials (no jackknife error to judge it by), or
    K̂'s jackknife error above :data:`ARM_SE_MAX` of it (a few short
    trials: a K̂ of 100 ± 715 N/m, clipped at the bound, would turn the present estimate's hand force into 8 times
    the displacement it is). ``coassist calibrate`` and the study's calibration block both decide so."""
    if arm.method == "assumed":
        return ASSUMED_ARM, "no pushes measured in the trials"
    measured = (
        f"K = {arm.stiffness:.0f} ± {arm.stiffness_se:.0f} N/m, C = {arm.damping:.1f} ± {arm.damping_se:.1f} N·s/m"
    )
    if arm.stiffness in STIFFNESS_RANGE or arm.damping in DAMPING_RANGE:  # identify_arm clips to the range
        return ASSUMED_ARM, f"measured {measured} from {arm.trials} trials: at the bound of a person's range"
    if arm.trials < 3:  # the jackknife needs three: an arm whose error cannot be told is not one to lean on
        return ASSUMED_ARM, (
            f"measured K = {arm.stiffness:.0f} N/m, C = {arm.damping:.1f} N·s/m from {arm.trials} trial(s): its error "
            "cannot be told below 3 (record 3 or more probe trials)"
        )
    if arm.stiffness_se > ARM_SE_MAX * arm.stiffness:
        return ASSUMED_ARM, (
            f"measured {measured} from {arm.trials} trials: too uncertain (error above {100 * ARM_SE_MAX:.0f} % of K)"
        )
    return arm, ""
