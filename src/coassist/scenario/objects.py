"""Objects between the operator's hand and the force sensor, and the sensor itself.

Physics (planar, small yaw angles; docs/architecture.md, *The simulated world*)
-------------------------------------------------------------------------------------
The robot renders the admittance M a + D v = F_s + u_r (eq. 3.1, K = 0), where F_s is
the force the sensor measures. An object of mass m sits between the hand and the
sensor, so the sensor does not see the hand force F_h but what is left after
accelerating the object::

    F_s = F_h − m (a + θ̈ J r_c)                       (translation of the object's centre)

(J r = (−r_y, r_x) turns a vector by +90°). Substituting, the tip moves as if the
rendered inertia had grown by m::

    (M + m) a + D v = F_h + u_r − m θ̈ J r_c + n_s + b_res

We integrate it exactly (zero-order hold) with the *measured* force noise n_s and the
residual bias b_res included, because the admittance moves on what the sensor says.
This treats the sensor as read continuously by the admittance (the robot's inner
loop is much faster than the object); a sampled loop with a one-tick sensing delay
would go unstable once m approaches the virtual mass M, which real set-ups avoid by
filtering and payload compensation, not modelled here.

Off-centre grasp (the board): the vacuum cup at the tip holds the board at a point
that is not its centre, and the hand holds it at r_h from the cup. The cup's rubber
is compliant in torsion, so the board yaws by a small angle θ about the cup::

    I_c θ̈ + c_θ θ̇ + k_θ θ = r_h × F_h − m r_c × a     (torques about the cup, z axis)
    p_hand = x + r_h + θ J r_h                         (the hand point the operator moves)

so a lateral hand force twists the board, the hand lags or leads the tip sideways,
and the sensor sees the board's angular acceleration (m θ̈ J r_c). I_c = I_cm + m|r_c|²
(rectangular plate: I_cm = m (a² + b²)/12). θ̈ enters the tip equation from the
previous tick (the yaw mode is slow compared with dt). Objects without a yaw mode
(handle, the compact load held at its centre) skip this.

Sensor (Robotiq FT300 on the thesis' UR5): samples at 100 Hz, so at 125 Hz about one
tick in five sees the previous sample again (the real user-a logs repeat the wrench
on 20–35 % of ticks); white noise; a bias (offset plus the weight leaking into x-y
through a small tilt of the sensor frame) that is zeroed at the start of the trial,
with the object attached and nobody touching it, by averaging ``zero_samples``
readings — the residual bias is minus the mean noise of those samples. Readings
saturate at ±327.67 N.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from coassist._checks import check_int, check_positive_scalar

GRAVITY = 9.81  # m/s²


def _nonneg(value: float, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not (np.isfinite(v) and v >= 0.0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


def _vec2(value, name: str) -> tuple[float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (2,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be 2 finite numbers [m], got {value!r}")
    return float(arr[0]), float(arr[1])


@dataclass(frozen=True)
class CarriedObject:
    """A rigid planar object between hand and sensor (module docstring for the model).

    Parameters
    ----------
    name : "handle", "board", "heavy", …
    mass : m [kg], ≥ 0 (0: nothing between hand and sensor).
    size : (a, b) planar extent [m] (for the inertia and the plots).
    grasp_offset : r_h (2,) [m], the hand point from the cup, in the base frame at θ = 0.
    center_offset : r_c (2,) [m], the object's centre from the cup.
    yaw_stiffness : k_θ [N·m/rad] of the cup's torsion; 0 means no yaw mode (rigid).
    yaw_damping : c_θ [N·m·s/rad].
    """

    name: str
    mass: float = 0.0
    size: tuple[float, float] = (0.0, 0.0)
    grasp_offset: tuple[float, float] = (0.0, 0.0)
    center_offset: tuple[float, float] = (0.0, 0.0)
    yaw_stiffness: float = 0.0
    yaw_damping: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"CarriedObject.name must be a non-empty string, got {self.name!r}")
        object.__setattr__(self, "mass", _nonneg(self.mass, "CarriedObject.mass"))
        object.__setattr__(self, "size", _vec2(self.size, "CarriedObject.size"))
        object.__setattr__(self, "grasp_offset", _vec2(self.grasp_offset, "CarriedObject.grasp_offset"))
        object.__setattr__(self, "center_offset", _vec2(self.center_offset, "CarriedObject.center_offset"))
        object.__setattr__(self, "yaw_stiffness", _nonneg(self.yaw_stiffness, "CarriedObject.yaw_stiffness"))
        object.__setattr__(self, "yaw_damping", _nonneg(self.yaw_damping, "CarriedObject.yaw_damping"))
        if self.has_yaw and self.mass == 0.0:
            raise ValueError("CarriedObject.mass must be > 0 when yaw_stiffness > 0 (a yaw mode needs inertia)")

    @property
    def has_yaw(self) -> bool:
        return self.yaw_stiffness > 0.0

    def yaw_constants(self) -> YawConstants:
        """Its :class:`YawConstants` (I_c = 1 without a yaw mode, where nothing divides by it)."""
        rh, rc = self.grasp_offset, self.center_offset
        inertia = self.yaw_inertia if self.has_yaw else 1.0
        return YawConstants(rh[0], rh[1], rc[0], rc[1], self.mass, self.yaw_stiffness, self.yaw_damping, inertia)

    @property
    def yaw_inertia(self) -> float:
        """I_c = m (a² + b²)/12 + m |r_c|² [kg·m²], about the cup."""
        a, b = self.size
        rc2 = self.center_offset[0] ** 2 + self.center_offset[1] ** 2
        return self.mass * (a * a + b * b) / 12.0 + self.mass * rc2

    def to_extra(self) -> dict:
        return {
            "name": self.name,
            "mass": self.mass,
            "size": list(self.size),
            "grasp_offset": list(self.grasp_offset),
            "center_offset": list(self.center_offset),
            "yaw_stiffness": self.yaw_stiffness,
            "yaw_damping": self.yaw_damping,
        }


#: Plywood density [kg/m³] (poplar/birch plywood is 450–700; light grade).
PLYWOOD_DENSITY = 450.0
#: Steel density [kg/m³] for the lumped weights.
STEEL_DENSITY = 7850.0

_BOARD_MASS = PLYWOOD_DENSITY * 1.06 * 0.82 * 0.02  # ≈ 7.8 kg
_HEAVY_MASS = STEEL_DENSITY * 0.18 * 0.155 * 0.05  # ≈ 11 kg (a solid block of that size)

#: The three objects of the thesis (§5.1, §5.2.3).
OBJECTS: dict[str, CarriedObject] = {
    # 3D-printed handle: light plastic, rigid, the hand right at the sensor.
    "handle": CarriedObject("handle"),
    # Wooden board 106 × 82 × 2 cm held by the vacuum cup 0.2 m from its centre on the
    # robot's side; the operator holds the near edge, 0.61 m from the cup (−y: the
    # operator stands in front of the robot). Cup torsion: a soft rubber cup,
    # k_θ = 150 N·m/rad, lightly damped.
    "board": CarriedObject(
        "board",
        mass=_BOARD_MASS,
        size=(1.06, 0.82),
        grasp_offset=(0.0, -0.61),
        center_offset=(0.0, -0.20),
        yaw_stiffness=150.0,
        yaw_damping=8.0,
    ),
    # Lumped weights 18 × 15.5 × 5 cm held at their centre: mass only, no lever arm.
    "heavy": CarriedObject("heavy", mass=_HEAVY_MASS, size=(0.18, 0.155)),
}


def get_object(name: str) -> CarriedObject:
    """The object preset ``name`` (one of :data:`OBJECTS`)."""
    try:
        return OBJECTS[name]
    except KeyError:
        raise ValueError(f"object must be one of {tuple(OBJECTS)}, got {name!r}") from None


@dataclass(frozen=True)
class ForceSensor:
    """The force/torque sensor's planar force channel (module docstring).

    Parameters
    ----------
    noise : white-noise standard deviation per axis [N] (real logs at rest: 0.01–0.05 N).
    offset : standard deviation of the raw per-axis offset [N], drawn per trial.
    tilt : standard deviation of the sensor tilt [rad]: the object's weight leaks
        m·g·tilt into each planar axis.
    rate_hz : sample rate [Hz]; readings are held between samples. None: every tick.
    zero_samples : readings averaged to zero the sensor at the start (≥ 1).
    saturation : |reading| limit per axis [N].
    """

    noise: float = 0.05
    offset: float = 3.0
    tilt: float = 0.02
    rate_hz: float | None = 100.0
    zero_samples: int = 25
    saturation: float = 327.67

    def __post_init__(self) -> None:
        object.__setattr__(self, "noise", _nonneg(self.noise, "ForceSensor.noise"))
        object.__setattr__(self, "offset", _nonneg(self.offset, "ForceSensor.offset"))
        object.__setattr__(self, "tilt", _nonneg(self.tilt, "ForceSensor.tilt"))
        if self.rate_hz is not None:
            object.__setattr__(self, "rate_hz", check_positive_scalar(self.rate_hz, "ForceSensor.rate_hz"))
        object.__setattr__(self, "zero_samples", check_int(self.zero_samples, "ForceSensor.zero_samples", 1))
        object.__setattr__(self, "saturation", check_positive_scalar(self.saturation, "ForceSensor.saturation"))

    def raw_bias(self, obj: CarriedObject, rng: np.random.Generator) -> np.ndarray:
        """A trial's raw bias (2,) [N]: offset plus weight leaking through the tilt."""
        offset = rng.normal(0.0, self.offset, 2)
        tilt = rng.normal(0.0, self.tilt, 2)
        return offset + obj.mass * GRAVITY * np.sin(tilt)

    def zero(self, raw_bias: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The bias estimate from averaging ``zero_samples`` readings at rest (2,) [N]."""
        readings = raw_bias + rng.normal(0.0, self.noise, (self.zero_samples, 2))
        return readings.mean(axis=0)

    def sample_ticks(self, n: int, dt: float) -> np.ndarray:
        """(n,) bool: True at ticks where a new sample arrives (held otherwise)."""
        if self.rate_hz is None:
            return np.ones(n, dtype=bool)
        k = np.arange(n)
        # Sample index of each tick's time; a tick sees a new sample when that index advances.
        idx = np.floor(k * dt * self.rate_hz + 1e-9).astype(np.int64)
        fresh = np.ones(n, dtype=bool)
        fresh[1:] = idx[1:] != idx[:-1]
        return fresh


class YawConstants(NamedTuple):
    """A carried object's yaw constants (:meth:`CarriedObject.yaw_constants`), for :func:`yaw_step` and
    :func:`hand_point`: floats for one object, (B,) arrays for a batch of worlds (coassist.sim.point_mass).

    rhx, rhy : r_h, the hand from the cup [m]; rcx, rcy : r_c, the centre from the cup [m];
    m : [kg]; k_th : [N·m/rad]; c_th : [N·m·s/rad]; I_c : [kg·m²] (1 without yaw, unused)."""

    rhx: Any
    rhy: Any
    rcx: Any
    rcy: Any
    m: Any
    k_th: Any
    c_th: Any
    I_c: Any


def hand_point(board: YawConstants, x, y, vx, vy, th, thd):
    """The hand point's position and velocity on a board turned by θ: (p_x, p_y, ṗ_x, ṗ_y)."""
    return x - th * board.rhy, y + th * board.rhx, vx - thd * board.rhy, vy + thd * board.rhx


def yaw_step(board: YawConstants, th, thd, fhx, fhy, ax_prev, ay_prev, dt: float):
    """One period of the yaw (module docstring: I_c θ̈ + c_θ θ̇ + k_θ θ = r_h × F_h − m r_c × a, semi-implicit
    Euler; F_h = (fhx, fhy), a the previous period's): (θ(k+1), θ̇(k+1), θ̈(k), c_x, c_y), c = −m θ̈ J r_c."""
    m = board.m
    tau = board.rhx * fhy - board.rhy * fhx - m * (board.rcx * ay_prev - board.rcy * ax_prev)
    thdd = (tau - board.k_th * th - board.c_th * thd) / board.I_c
    thd = thd + thdd * dt
    th = th + thd * dt
    return th, thd, thdd, m * thdd * board.rcy, -m * thdd * board.rcx
