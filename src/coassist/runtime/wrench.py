"""The wrench pipeline: from the raw force/torque reading to the hand wrench in the base frame.

Once per control tick (125 Hz or 500 Hz) the loop hands :meth:`WrenchPipeline.update`
the sensor's raw reading ``w_raw = [f; τ]`` [N, N·m] in the *sensor* frame (sign:
the force the tool applies to the sensor, :mod:`coassist.runtime.world`), the sensor's
orientation R (3×3, columns = sensor axes in the base frame), the sensor's sample
counter and the tick time. It returns :class:`WrenchReading`: the hand wrench
``[f_h; τ_h]`` in the base frame (torque about the sensor origin), the tick's
:class:`~coassist.interfaces.Fault` flags and whether a new sample went into it.

Stages, in order::

    1. validate      w_raw not 6 finite reals, or R not finite with |r_ij| ≤ 1
                                                       → 0, NONFINITE_WRENCH / INVALID_INPUT
    2. stale         seq unchanged for > max_sample_age, or new samples
                     bit-identical for > max_frozen_time → 0, SENSOR_STALE
    3. spike         |w_raw,i| > 1.5·range, or |Δw_raw,i| > spike_jump (sample to sample)
                                                       → hold, WRENCH_SPIKE
    4. saturation    |w_raw,i| ≥ range                  → hold, SENSOR_SATURATED
    5. bias          w_s = w_raw − b                                (b: sensor frame)
    6. payload       w_s ← w_s − [F_g; c × F_g],   F_g = m Rᵀ g     (sensor frame)
    7. base frame    f_h = R f_s,   τ_h = R τ_s                     (about the sensor origin)
    8. low-pass      y_k = y_{k−1} + (1 − e^{−2π f_c dt}) (x_k − y_{k−1})   every tick
    9. deadband      f ← f · max(‖f‖ − d_f, 0)/‖f‖,  τ ← τ · max(‖τ‖ − d_τ, 0)/‖τ‖

Payload (stage 6). The tool of mass m [kg] with centre of mass c [m] (sensor frame)
hangs on the sensor. Quasi-statically the sensor carries everything applied to the
tool, so with this sign convention it reads the hand's wrench plus the tool's weight,
both as wrenches about the sensor origin, plus the sensor's bias b::

    w_raw = b + [F_g; c × F_g] + w_hand,s,     F_g = m Rᵀ g   [N]

where g (base frame, default (0, 0, −9.81) m/s²) is gravity and Rᵀ g is gravity in the
sensor frame; :func:`payload_wrench` computes ``[F_g; c × F_g]``. Hence
``w_hand,s = w_raw − b − [F_g; c × F_g]``. The bias is measured with nobody touching
the tool: ``b = mean_i(w_raw,i − payload(R_i))`` (:meth:`WrenchPipeline.zero`, or
:meth:`WrenchPipeline.request_zero` from the next accepted samples).

What each fault does, and why:

- Zero-output faults (invalid input, stale sensor, :data:`Fault.INTERNAL_ERROR`): the
  output is exactly zero, as if the hand had let go, so the admittance stops driving
  the robot. The filter and the held wrench restart from zero, so the output ramps back
  through the filter when readings return. A stale sensor also forgets the spike
  reference (after a gap, a large change from the last sample is plausible).
- Hold faults (spike, saturation): the reading is not the hand force, so the last
  accepted hand wrench is held (and still filtered). The pipeline does not stop
  anything; the safety layer reads the flag and decides whether to decelerate or stop.
- A spike is a reading beyond 1.5× the sensor's range (never physical: never accepted)
  or a jump from the last accepted sample larger than ``spike_jump_*`` on any channel.
  A jump that persists is a real step: its ``spike_hold``-th consecutive sample, each
  within ``spike_jump_*`` of the one before, is accepted (``spike_hold = 1`` turns the
  jump test off). Jumps that do not agree with each other (noise bursts) never are.

Timing. The 100 Hz Robotiq FT300 read at 125 Hz repeats one sample in five: a repeated
``seq`` is normal and the held wrench is used; only when ``seq`` has not moved for more
than ``max_sample_age`` (measured on the tick clock ``t`` from the tick that first saw
the current sample) is the sensor stale. That clock must go forward: a tick whose ``t`` is not
after the last tick's is INVALID_INPUT (a clock that stopped or ran back hid a stuck sensor, and
the arm followed its last push to the workspace's edge: a review, 2026-12-07), and the sample
ages run on from the latest ``t`` seen. The low-pass filter runs on *every* tick, on
the held value, so its time base is the control period ``dt`` and its step response
at tick k after a step accepted at tick 0 is exactly ``1 − exp(−2π f_c (k+1) dt)``.

:meth:`WrenchPipeline.update` never raises and costs a few microseconds (scalar math on
floats, no per-tick linear algebra).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_int, is_real_number
from coassist._rows import RowConstants
from coassist.interfaces import Fault

__all__ = [
    "MEASURED_FROZEN_TIME",
    "WrenchConfig",
    "WrenchPipeline",
    "WrenchPipelineBatch",
    "WrenchReading",
    "payload_wrench",
]

log = logging.getLogger(__name__)

#: A reading beyond this multiple of the sensor's range cannot be physical (a corrupted
#: packet, a 5 kN value): it is a spike however long it lasts.
IMPLAUSIBLE_RANGE_FACTOR = 1.5
#: WrenchConfig.max_frozen_time for a measured sensor [s]: a real F/T sensor's noise moves
#: some channel every sample, so 0.1 s of bit-identical samples is a stuck sensor.
MEASURED_FROZEN_TIME = 0.1
#: Largest entry of a sensor rotation accepted (a rotation's entries are cosines, |r_ij| ≤ 1;
#: the margin covers rounding of a composed or quaternion-made matrix).
_R_MAX = 1.0 + 1e-6
#: How far a sensor rotation's columns may be from unit length and orthogonal (|RᵀR − I|, entry by entry), as
#: :meth:`WrenchPipeline.zero` allows: rounding of a composed or quaternion-made matrix.
_R_ORTHO = 1e-6


def _is_rotation(
    r00: float, r01: float, r02: float, r10: float, r11: float, r12: float, r20: float, r21: float, r22: float
) -> bool:
    """Whether the 3 × 3 matrix of these entries (row by row, Python floats) is a rotation: RᵀR = I within
    :data:`_R_ORTHO` and det R > 0 (a mirrored frame turns the hand force)."""
    t = _R_ORTHO
    return (
        abs(r00 * r00 + r10 * r10 + r20 * r20 - 1.0) <= t
        and abs(r01 * r01 + r11 * r11 + r21 * r21 - 1.0) <= t
        and abs(r02 * r02 + r12 * r12 + r22 * r22 - 1.0) <= t
        and abs(r00 * r01 + r10 * r11 + r20 * r21) <= t
        and abs(r00 * r02 + r10 * r12 + r20 * r22) <= t
        and abs(r01 * r02 + r11 * r12 + r21 * r22) <= t
        and r00 * (r11 * r22 - r12 * r21) - r01 * (r10 * r22 - r12 * r20) + r02 * (r10 * r21 - r11 * r20) > 0.0
    )


#: Relative margin under the range at which a channel counts as saturated (the sensor
#: clips exactly at its range; float noise must not hide it).
_SATURATION_MARGIN = 1e-6


class WrenchReading(NamedTuple):
    """What the pipeline gives the tick.

    hand : (6,) hand wrench ``[fx, fy, fz, τx, τy, τz]`` [N, N·m] in the base frame,
        torque about the sensor origin; a new array every tick (safe to keep).
    fault : the tick's fault flags (``Fault.NONE`` when all is well).
    fresh : True when a new sensor sample was accepted and went into ``hand`` this tick
        (False on a repeated sample, a rejected or saturated one, a fault, or zeroing).
    """

    hand: np.ndarray
    fault: Fault
    fresh: bool


def _finite_float(value: object, name: str) -> float:
    if not is_real_number(value):
        raise ValueError(f"{name} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return out


def _vector3(value: object, name: str) -> tuple[float, float, float]:
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name} must be 3 numbers, got {value!r}")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 numbers, got {value!r}") from None
    if arr.dtype.kind not in "fiu" or arr.shape != (3,):
        raise ValueError(f"{name} must be 3 real numbers, got {value!r}")
    arr = arr.astype(float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass(frozen=True)
class WrenchConfig:
    """Parameters of the wrench pipeline (module docstring for the stages).

    Attributes
    ----------
    tool_mass : mass of everything mounted after the sensor (handle, gripper, object
        held rigidly) [kg], ≥ 0. Its weight is removed from the reading at every
        orientation; 0 turns payload compensation off.
    tool_com : centre of mass of that payload in the sensor frame [m], 3 numbers. Sets
        the torque the weight makes about the sensor origin.
    gravity : gravity vector in the robot base frame [m/s²], 3 numbers; (0, 0, −9.81)
        for a floor-mounted robot with z up.
    cutoff_hz : cutoff of the first-order low-pass filter on each channel [Hz], > 0, or
        None for no filtering. Lower is smoother but lags the hand: the filter's time
        constant is 1/(2π·cutoff_hz) (15 Hz: 10.6 ms).
    deadband_force : force magnitude treated as no push [N], ≥ 0. Forces below it read
        zero, above it the magnitude is reduced by it (continuous, direction kept), so
        sensor noise and drift do not creep the robot. 0.2 N: four times the FT300's
        noise (≈ 0.05 N), and 2 % of a light 10 N push (the admittance then renders
        (F − 0.2 N)/D).
    deadband_torque : the same for the torque magnitude [N·m], ≥ 0.
    force_range : the sensor's force range per axis [N], > 0 (FT300: 300). A channel at
        it is saturated; beyond 1.5× it the reading is impossible (a spike).
    torque_range : the sensor's torque range per axis [N·m], > 0 (FT300: 30).
    max_sample_age : longest time without a new sensor sample before the sensor counts
        as stale and the output goes to zero [s], > 0 and ≥ the control period. A 100 Hz
        sensor read at 125 Hz has gaps of up to 16 ms between new samples.
    spike_jump_force : largest believable change of one force channel between two
        consecutive samples [N], > 0; a larger change is held back as a spike.
    spike_jump_torque : the same for a torque channel [N·m], > 0.
    spike_hold : number of consecutive samples a jump must persist to be accepted as a
        real step, ≥ 1 (the first ``spike_hold − 1`` are rejected; 1: no jump test).
    max_frozen_time : longest time [s] the sensor may send new samples (``seq`` moving)
        whose six values are bit-identical to the previous sample's before it counts as
        stale (a stuck sensor with a live counter), > 0, or None to turn the check off.
        A real force/torque sensor is never bit-identical from sample to sample: its
        noise (FT300 ≈ 0.05 N rms, several counts of its resolution) moves some channel
        every sample, so :data:`MEASURED_FROZEN_TIME` = 0.1 s (10 samples at 100 Hz) of
        identical values is never noise, and it bounds how long a stuck 15 N can drive
        the admittance; the arm worlds (``robot.drive``: the real UR, MuJoCo with sensor
        noise) set it. The default None is for noise-free inputs, which repeat exactly
        on a constant push (the point-mass world, the browser hand, a MuJoCo sensor with
        zero noise, synthetic signals).
    zero_samples : number of accepted samples averaged by
        :meth:`WrenchPipeline.request_zero` to measure the bias, ≥ 1 (25: 0.25 s at 100 Hz).
    """

    tool_mass: float = 0.0
    tool_com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    cutoff_hz: float | None = 15.0
    deadband_force: float = 0.2
    deadband_torque: float = 0.05
    force_range: float = 300.0
    torque_range: float = 30.0
    max_sample_age: float = 0.03
    spike_jump_force: float = 150.0
    spike_jump_torque: float = 15.0
    spike_hold: int = 3
    max_frozen_time: float | None = None
    zero_samples: int = 25

    def __post_init__(self) -> None:
        def name(field: str) -> str:
            return f"WrenchConfig.{field}"

        def put(field: str, value: object) -> None:
            object.__setattr__(self, field, value)  # frozen: normalise once, here

        for field in ("tool_mass", "deadband_force", "deadband_torque"):
            value = _finite_float(getattr(self, field), name(field))
            if value < 0.0:
                raise ValueError(f"{name(field)} must be >= 0, got {value!r}")
            put(field, value)
        for field in ("force_range", "torque_range", "max_sample_age", "spike_jump_force", "spike_jump_torque"):
            value = _finite_float(getattr(self, field), name(field))
            if value <= 0.0:
                raise ValueError(f"{name(field)} must be > 0, got {value!r}")
            put(field, value)
        if self.max_frozen_time is not None:
            value = _finite_float(self.max_frozen_time, name("max_frozen_time"))
            if value <= 0.0:
                raise ValueError(f"{name('max_frozen_time')} must be > 0 or None, got {value!r}")
            put("max_frozen_time", value)
        if self.cutoff_hz is not None:
            value = _finite_float(self.cutoff_hz, name("cutoff_hz"))
            if value <= 0.0:
                raise ValueError(f"{name('cutoff_hz')} must be > 0 or None, got {value!r}")
            put("cutoff_hz", value)
        put("tool_com", _vector3(self.tool_com, name("tool_com")))
        put("gravity", _vector3(self.gravity, name("gravity")))
        for field in ("spike_hold", "zero_samples"):
            value = getattr(self, field)
            put(field, check_int(value, name(field), 1))


def payload_wrench(mass: float, com: ArrayLike, gravity: ArrayLike, rotation: ArrayLike) -> np.ndarray:
    """The tool's gravity wrench as the sensor reads it, in the sensor frame.

    ``[F_g; τ_g] = [m Rᵀ g; c × m Rᵀ g]`` [N, N·m]: the weight (gravity g in the base
    frame, turned into the sensor frame by Rᵀ) and its torque about the sensor origin
    from the centre of mass c (sensor frame).

    Parameters
    ----------
    mass : [kg].
    com : (3,) the centre of mass [m], sensor frame.
    gravity : (3,) [m/s²], base frame.
    rotation : (3, 3) sensor orientation in the base frame (columns: sensor axes), or a
        stack (..., 3, 3).

    Returns
    -------
    (6,) or (..., 6).
    """
    R = np.asarray(rotation, dtype=float)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"rotation must have shape (..., 3, 3), got {R.shape}")
    c = np.asarray(com, dtype=float).reshape(3)
    g = np.asarray(gravity, dtype=float).reshape(3)
    force = float(mass) * np.einsum("...ji,j->...i", R, g)  # m Rᵀ g
    torque = np.cross(c, force)
    return np.concatenate([force, torque], axis=-1)


_ZERO6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_NO_FAULT = Fault.NONE


class WrenchPipeline:
    """Raw sensor reading → hand wrench in the base frame, one call per control tick.

    Parameters
    ----------
    config : :class:`WrenchConfig`.
    dt : the control period [s] (0.008 at 125 Hz, 0.002 at 500 Hz): the filter's time base.

    The bias starts at zero; set it with :meth:`zero` (or :meth:`request_zero`) before
    the person takes the handle. :meth:`reset` clears the per-trial state and keeps it.
    """

    def __init__(self, config: WrenchConfig, dt: float) -> None:
        if not isinstance(config, WrenchConfig):
            raise ValueError(f"config must be a WrenchConfig, got {type(config).__name__}")
        dt = _finite_float(dt, "dt")
        if dt <= 0.0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        if config.max_sample_age < dt:
            # Otherwise every repeated sample of a slower sensor would read as stale.
            raise ValueError(f"WrenchConfig.max_sample_age ({config.max_sample_age}) must be >= dt ({dt})")
        self.config = config
        self.dt = dt
        c = config
        # Per-tick constants as plain floats: scalar math beats numpy on 6-vectors.
        self._mg = tuple(c.tool_mass * gi for gi in c.gravity)
        self._com = c.tool_com
        self._has_payload = c.tool_mass > 0.0
        self._alpha = None if c.cutoff_hz is None else 1.0 - math.exp(-2.0 * math.pi * c.cutoff_hz * dt)
        self._db_f = c.deadband_force
        self._db_t = c.deadband_torque
        self._sat_f = c.force_range * (1.0 - _SATURATION_MARGIN)
        self._sat_t = c.torque_range * (1.0 - _SATURATION_MARGIN)
        self._max_f = c.force_range * IMPLAUSIBLE_RANGE_FACTOR
        self._max_t = c.torque_range * IMPLAUSIBLE_RANGE_FACTOR
        self._jump_f = c.spike_jump_force
        self._jump_t = c.spike_jump_torque
        # 1 ns of slack: a tick time on an exact multiple of max_sample_age must not be
        # decided by float rounding of k·dt.
        self._max_age = c.max_sample_age + 1e-9
        self._max_frozen = None if c.max_frozen_time is None else c.max_frozen_time + 1e-9
        self._bias = _ZERO6
        self._error_logged = False
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Forget the per-trial state (filter, held wrench, spike and sample tracking,
        a pending re-zero); the bias is kept."""
        self._y = list(_ZERO6)  # filter state, base frame
        self._held = _ZERO6  # last accepted hand wrench, base frame (filter input)
        self._ref: tuple[float, ...] | None = None  # last accepted raw sample (spike test)
        self._cand: tuple[float, ...] | None = None  # last rejected jump sample
        self._cand_n = 0  # consecutive, mutually consistent jump samples so far
        self._seq: object = None
        self._seq_t = 0.0  # tick time at which the current seq was first seen
        self._last_t = -math.inf  # the latest tick time seen (the clock must go forward)
        self._last_raw: tuple[float, ...] | None = None  # the previous new sample's raw values
        self._same_t = 0.0  # tick time of the first sample with those values
        self._frozen = False  # those values have repeated for longer than max_frozen_time
        self._zero_left = 0
        self._zero_n = 0
        self._zero_sum = [0.0] * 6

    @property
    def bias(self) -> np.ndarray:
        """(6,) sensor bias ``[f; τ]`` [N, N·m] in the sensor frame (a copy)."""
        return np.array(self._bias)

    @property
    def zeroing(self) -> bool:
        """True while :meth:`request_zero` is collecting samples (the output is zero)."""
        return self._zero_left > 0

    def zero(self, raw_samples: ArrayLike, rotations: ArrayLike) -> np.ndarray:
        """Set the bias from readings taken with nobody touching the tool.

        ``b = mean_i(w_raw,i − payload_wrench(m, c, g, R_i))`` in the sensor frame.
        Several orientations are not needed for the bias (the payload is modelled), but
        averaging over them also averages out a small error in m or c.

        Parameters
        ----------
        raw_samples : (n, 6) raw readings [N, N·m], sensor frame.
        rotations : (n, 3, 3) the sensor orientation at each, or one (3, 3) for all.

        Returns the new bias (6,). Raises ValueError on bad input (not a per-tick call).
        """
        raw = np.asarray(raw_samples, dtype=float)
        if raw.ndim != 2 or raw.shape[1] != 6 or raw.shape[0] < 1:
            raise ValueError(f"raw_samples must have shape (n >= 1, 6), got {raw.shape}")
        R = np.asarray(rotations, dtype=float)
        if R.shape == (3, 3):
            R = np.broadcast_to(R, (raw.shape[0], 3, 3))
        if R.shape != (raw.shape[0], 3, 3):
            raise ValueError(f"rotations must have shape ({raw.shape[0]}, 3, 3) or (3, 3), got {R.shape}")
        if not (np.all(np.isfinite(raw)) and np.all(np.isfinite(R))):
            raise ValueError("raw_samples and rotations must be finite")
        err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max()
        if err > 1e-6:
            raise ValueError(f"rotations must be rotation matrices (max |RᵀR − I| = {err:.3g})")
        c = self.config
        bias = (raw - payload_wrench(c.tool_mass, c.tool_com, c.gravity, R)).mean(axis=0)
        self._bias = tuple(float(v) for v in bias)
        self._zero_left = 0
        return self.bias

    def request_zero(self, n: int | None = None) -> None:
        """Re-measure the bias from the next ``n`` accepted samples (default ``zero_samples``).

        Call it with nobody touching the tool. Until the n-th sample the output is exactly
        zero, ``fresh`` is False and :attr:`zeroing` is True; no fault is flagged (this is
        an intended pause, not a failure). Rejected (spike, saturated, invalid) samples do
        not count. The filter restarts from zero afterwards.
        """
        if n is None:
            n = self.config.zero_samples
        self._zero_left = check_int(n, "n", 1)
        self._zero_n = 0
        self._zero_sum = [0.0] * 6
        self._y = list(_ZERO6)
        self._held = _ZERO6

    # ------------------------------------------------------------------ tick

    def update(self, raw: ArrayLike, sensor_rotation: ArrayLike, seq: int, t: float) -> WrenchReading:
        """One tick: raw reading (6,) sensor frame, R (3, 3), sample counter, tick time [s].

        Never raises: an unexpected error gives zero output and ``Fault.INTERNAL_ERROR``.
        """
        try:
            return self._update(raw, sensor_rotation, seq, t)
        except Exception:  # the loop must keep running; the hand "lets go"
            if not self._error_logged:
                log.exception("wrench pipeline raised; zero hand wrench used")
                self._error_logged = True
            self._let_go(forget_reference=True)
            return WrenchReading(np.zeros(6), Fault.INTERNAL_ERROR, False)

    def _let_go(self, forget_reference: bool) -> None:
        self._y = list(_ZERO6)
        self._held = _ZERO6
        self._cand = None
        self._cand_n = 0
        if forget_reference:
            self._ref = None

    def _update(self, raw, sensor_rotation, seq, t) -> WrenchReading:
        fault = _NO_FAULT
        # --- time and sample counter
        if type(t) is not float:
            t = float(t) if is_real_number(t) else math.nan
        if type(seq) is not int:
            seq = int(seq) if isinstance(seq, np.integer) else None
        new = stale = False
        if t <= self._last_t:  # a clock that stopped or ran back: the ages below would stop with it
            fault |= Fault.INVALID_INPUT
            t = self._last_t
        elif math.isfinite(t):  # (a NaN or ±inf is flagged below and does not become the clock)
            self._last_t = t
        if seq is not None and math.isfinite(t):
            if seq != self._seq:
                new = True
                self._seq = seq
                self._seq_t = t
            elif t - self._seq_t > self._max_age:
                stale = True
        else:
            fault |= Fault.INVALID_INPUT

        # --- 1. validate the rotation and the reading
        R = sensor_rotation
        if not (type(R) is np.ndarray and R.shape == (3, 3) and R.dtype.kind == "f"):
            R = self._as_real(R, (3, 3))
        if R is None:
            fault |= Fault.INVALID_INPUT
        else:
            (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
            # x·0 is 0 for a finite x and NaN for ±inf/NaN: one comparison checks all nine.
            s = (r00 + r01 + r02 + r10 + r11 + r12 + r20 + r21 + r22) * 0.0
            if s != s:
                fault |= Fault.INVALID_INPUT
            elif max(abs(r00), abs(r01), abs(r02), abs(r10), abs(r11), abs(r12), abs(r20), abs(r21), abs(r22)) > _R_MAX:
                # not a rotation (its entries are cosines): a 1e300 would poison the filter for seconds
                fault |= Fault.INVALID_INPUT
            elif not _is_rotation(r00, r01, r02, r10, r11, r12, r20, r21, r22):
                # cosines, but not a rotation (zeros, a scaled or mirrored frame): the hand force read too small
                # (all zeros: no force, no contact stop) or turned
                fault |= Fault.INVALID_INPUT
        w = raw
        if not (type(w) is np.ndarray and w.shape == (6,) and w.dtype.kind == "f"):
            w = self._as_real(w, (6,))
        if w is None:
            fault |= Fault.INVALID_INPUT
        else:
            w0, w1, w2, w3, w4, w5 = w = tuple(w.tolist())
            s = w0 * 0.0 + w1 * 0.0 + w2 * 0.0 + w3 * 0.0 + w4 * 0.0 + w5 * 0.0
            if s != s:
                fault |= Fault.NONFINITE_WRENCH

        # --- 2. stale sensor: no new sample, or new samples that repeat bit for bit
        if new and not fault and self._max_frozen is not None:
            if w == self._last_raw:
                self._frozen = t - self._same_t > self._max_frozen
            else:
                self._last_raw = w
                self._same_t = t
                self._frozen = False
        stale = stale or self._frozen  # also on the ticks between samples, until the values move
        if stale:
            fault |= Fault.SENSOR_STALE
        if fault:
            self._let_go(forget_reference=stale)
            return WrenchReading(np.zeros(6), fault, False)

        fresh = False
        if new:
            # --- 3. spike: impossible value, or an unbelievable jump that has not persisted
            a0, a1, a2, a3, a4, a5 = abs(w0), abs(w1), abs(w2), abs(w3), abs(w4), abs(w5)
            mf = max(a0, a1, a2)
            mt = max(a3, a4, a5)
            if mf > self._max_f or mt > self._max_t:
                accepted = False
                self._cand = None
                self._cand_n = 0
            elif self._ref is None or not self._jumps(w, self._ref):
                accepted = True
            else:
                cand = self._cand
                self._cand_n = self._cand_n + 1 if cand is not None and not self._jumps(w, cand) else 1
                self._cand = w
                accepted = self._cand_n >= self.config.spike_hold
            if not accepted:
                fault |= Fault.WRENCH_SPIKE
            else:
                self._ref = w
                self._cand = None
                self._cand_n = 0
                # --- 4. saturation: a clipped channel is not the hand force; hold
                if mf >= self._sat_f or mt >= self._sat_t:
                    fault |= Fault.SENSOR_SATURATED
                else:
                    # --- 6. payload gravity wrench in the sensor frame: F = m Rᵀ g, τ = c × F
                    if self._has_payload:
                        gx, gy, gz = self._mg
                        fx = r00 * gx + r10 * gy + r20 * gz
                        fy = r01 * gx + r11 * gy + r21 * gz
                        fz = r02 * gx + r12 * gy + r22 * gz
                        cx, cy, cz = self._com
                        w0 -= fx
                        w1 -= fy
                        w2 -= fz
                        w3 -= cy * fz - cz * fy
                        w4 -= cz * fx - cx * fz
                        w5 -= cx * fy - cy * fx
                    if self._zero_left > 0:
                        self._collect_zero((w0, w1, w2, w3, w4, w5))
                    else:
                        # --- 5. bias (sensor frame)
                        b = self._bias
                        w0 -= b[0]
                        w1 -= b[1]
                        w2 -= b[2]
                        w3 -= b[3]
                        w4 -= b[4]
                        w5 -= b[5]
                        # --- 7. into the base frame
                        self._held = (
                            r00 * w0 + r01 * w1 + r02 * w2,
                            r10 * w0 + r11 * w1 + r12 * w2,
                            r20 * w0 + r21 * w1 + r22 * w2,
                            r00 * w3 + r01 * w4 + r02 * w5,
                            r10 * w3 + r11 * w4 + r12 * w5,
                            r20 * w3 + r21 * w4 + r22 * w5,
                        )
                        fresh = True

        if self._zero_left > 0:
            return WrenchReading(np.zeros(6), fault, False)

        # --- 8. low-pass, every tick on the held value (time base: the control period)
        a = self._alpha
        if a is None:
            y0, y1, y2, y3, y4, y5 = self._held
        else:
            y = self._y
            h = self._held
            y0 = y[0] + a * (h[0] - y[0])
            y1 = y[1] + a * (h[1] - y[1])
            y2 = y[2] + a * (h[2] - y[2])
            y3 = y[3] + a * (h[3] - y[3])
            y4 = y[4] + a * (h[4] - y[4])
            y5 = y[5] + a * (h[5] - y[5])
            self._y = [y0, y1, y2, y3, y4, y5]

        # --- 9. deadband on the vector norms (direction kept, continuous at the edge)
        db = self._db_f
        if db > 0.0:
            n = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
            k = (n - db) / n if n > db else 0.0
            y0 *= k
            y1 *= k
            y2 *= k
        db = self._db_t
        if db > 0.0:
            n = math.sqrt(y3 * y3 + y4 * y4 + y5 * y5)
            k = (n - db) / n if n > db else 0.0
            y3 *= k
            y4 *= k
            y5 *= k
        return WrenchReading(np.array((y0, y1, y2, y3, y4, y5)), fault, fresh)

    def _jumps(self, w: tuple[float, ...], ref: tuple[float, ...]) -> bool:
        """True when any channel of w differs from ref by more than its spike_jump."""
        jf, jt = self._jump_f, self._jump_t
        return (
            abs(w[0] - ref[0]) > jf
            or abs(w[1] - ref[1]) > jf
            or abs(w[2] - ref[2]) > jf
            or abs(w[3] - ref[3]) > jt
            or abs(w[4] - ref[4]) > jt
            or abs(w[5] - ref[5]) > jt
        )

    def _collect_zero(self, w: tuple[float, ...]) -> None:
        """Accumulate one payload-compensated sample for the bias; finish after the last."""
        acc = self._zero_sum
        for i in range(6):
            acc[i] += w[i]
        self._zero_n += 1
        self._zero_left -= 1
        if self._zero_left == 0:
            self._bias = tuple(v / self._zero_n for v in acc)
            self._y = list(_ZERO6)
            self._held = _ZERO6

    @staticmethod
    def _as_real(value: object, shape: tuple[int, ...]) -> np.ndarray | None:
        """The slow path: value as a float array of ``shape``, or None (wrong shape or type)."""
        if isinstance(value, (str, bytes)):
            return None
        try:
            arr = np.asarray(value)
        except Exception:  # ragged lists, objects that refuse conversion
            return None
        if arr.dtype.kind not in "fiu" or arr.shape != shape:  # bool, complex, str, object
            return None
        return arr.astype(float)


class WrenchPipelineBatch:
    """:meth:`WrenchPipeline.update` for B pipelines at once on the fault-free tick: its array twin.

    For planar readings (f_x, f_y; f_z and the torques 0, as the point-mass world's) into
    pipelines without filter, deadband, payload or zeroing (:meth:`accepts`): what is left of
    the stages is the sample tracking, the checks, the bias and the rotation, and on a tick
    without a fault flag :meth:`update` gives row for row the same floats as each pipeline's
    ``update(...).hand[:3]``. A row it cannot answer for is not ``clean``: a stale or
    non-finite reading, an implausible, jumping or saturated sample, or a new sample equal
    to the last accepted one while the frozen check is on (the pipeline may or may not call
    that stale yet). A caller runs such a row on the pipeline itself (the point-mass array
    path, :mod:`coassist.sim.array_runner`, runs the whole trial again on the reference path); the
    batch's state for it is then no longer meaningful.

    Parameters
    ----------
    pipes : the B pipelines (:meth:`accepts`), nothing seen yet.
    rotation : (3, 3) the sensor's orientation in the base frame, shared by the B sensors.
    """

    @staticmethod
    def accepts(pipe: object) -> bool:
        """Whether ``pipe`` can join a batch: a :class:`WrenchPipeline` without filter, deadband or
        payload, not zeroing, that has seen no sample yet."""
        return (
            type(pipe) is WrenchPipeline
            and pipe._alpha is None
            and pipe._db_f == 0.0
            and pipe._db_t == 0.0
            and not pipe._has_payload
            and pipe._zero_left == 0
            and pipe._seq is None
            and pipe._ref is None
        )

    def __init__(self, pipes: Sequence[WrenchPipeline], rotation: np.ndarray) -> None:
        for i, p in enumerate(pipes):
            if not self.accepts(p):
                raise ValueError(f"pipes[{i}] cannot join a WrenchPipelineBatch (WrenchPipelineBatch.accepts is False)")
        R = np.asarray(rotation, dtype=float)
        if R.shape != (3, 3) or not np.isfinite(R).all():
            raise ValueError(f"rotation must be a finite (3, 3) matrix, got shape {R.shape}")
        if not _is_rotation(*R.ravel().tolist()):  # the pipelines' own check: every row would be INVALID_INPUT
            raise ValueError("rotation must be a rotation matrix (RᵀR = I within 1e-6, det > 0)")
        B = len(pipes)

        def f(seq) -> np.ndarray:
            return np.array(seq, dtype=float)

        self._R = [[float(R[r, c]) for c in range(3)] for r in range(3)]
        self._R_columns = tuple(np.array([self._R[r][c] for r in range(3)]) for c in range(3))  # (3,) each: R[:, c]
        self._max_age = f([p._max_age for p in pipes])
        self._frozen_checked = np.array([p._max_frozen is not None for p in pipes], dtype=bool)
        self._max_f, self._sat_f, self._jump_f = (
            f([p._max_f for p in pipes]),
            f([p._sat_f for p in pipes]),
            f([p._jump_f for p in pipes]),
        )
        self._bias = f([p._bias for p in pipes]).reshape(B, 6)
        self._seq = np.full(B, -1, dtype=np.int64)  # nothing seen yet (a sensor's counter starts at 0)
        self._seq_t = np.zeros(B)
        self._ref = np.zeros((B, 2))  # the last accepted sample (the spike test's reference)
        self._has_ref = np.zeros(B, dtype=bool)
        #: (B, 3) the hand force held by each pipeline [N], base frame.
        self.hand = np.zeros((B, 3))
        # the pipelines' constants, gathered once per set of rows (those with a new sample: another set)
        self._ages = RowConstants((self._max_age,))
        self._checks = RowConstants((self._frozen_checked, self._jump_f, self._max_f, self._sat_f, self._bias))

    def update(self, rows: np.ndarray, raw: np.ndarray, seq: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """One tick of the pipelines ``rows`` (indices): raw readings (len(rows), 2) [N] (f_x, f_y;
        the rest 0), sensor frame, their sample counters (len(rows),), the tick time t [s].

        Returns (hand (len(rows), 3) [N] in the base frame, clean (len(rows),) bool): where
        clean, each pipeline's ``update`` gives that force and no fault flag (class docstring).
        """
        new = seq != self._seq[rows]
        (max_age,) = self._ages.take(rows)
        clean = new | ~(t - self._seq_t[rows] > max_age)  # no new sample for too long: stale
        clean &= np.isfinite(raw).all(axis=1)
        if new.all():  # every row has a new sample (the sensors share their sample ticks): no row to pick
            at, w, fresh = rows, raw, seq
        else:
            at, w, fresh = rows[new], raw[new], seq[new]
        if at.size:
            self._seq[at] = fresh
            self._seq_t[at] = t
            ref = self._ref[at]
            has_ref = self._has_ref[at]
            frozen_checked, jf, max_f, sat_f, b = self._checks.take(at)
            repeat = (w[:, 0] == ref[:, 0]) & (w[:, 1] == ref[:, 1]) & has_ref & frozen_checked
            # the reading's f_z and torques are 0 (below every range and jump, which are > 0)
            mf = np.maximum(np.abs(w[:, 0]), np.abs(w[:, 1]))
            jump = has_ref & ((np.abs(w[:, 0] - ref[:, 0]) > jf) | (np.abs(w[:, 1] - ref[:, 1]) > jf))
            bad = repeat | jump | (mf > max_f) | (mf >= sat_f)
            clean[np.flatnonzero(new)[bad] if at is not rows else bad] = False
            self._ref[at] = w
            self._has_ref[at] = True
            # bias (sensor frame), then into the base frame (WrenchPipeline._update's stages 5 and 7)
            c0, c1, c2 = w[:, 0] - b[:, 0], w[:, 1] - b[:, 1], 0.0 - b[:, 2]
            # hand[:, r] = R[r][0] c0 + R[r][1] c1 + R[r][2] c2 for r = 0, 1, 2 in one (len(at), 3) pass:
            # the same products (x·y = y·x in IEEE arithmetic) summed in the same order
            R0, R1, R2 = self._R_columns
            self.hand[at] = c0[:, None] * R0 + c1[:, None] * R1 + c2[:, None] * R2
        return self.hand[rows], clean
