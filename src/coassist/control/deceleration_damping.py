"""Deceleration-gated damping: extra damping while the tool slows down (issue 34, item 3).

Where a person turns, the tool has to slow down along its old direction. An assistive
robot that pushes along a prediction keeps pushing through that turn, and the tool
overshoots. This law adds damping only while the tool decelerates, so it brakes the
overshoot without taxing the steady motion the person wants help with::

    d(k)   = −(â · v) / ‖v‖                       deceleration along the motion [m/s²] (0 at rest)
    g(k)   = clip(d(k) / a_ref, 0, 1)              the gate: 0 while speeding up or cruising
    u_r'   = u_r − g(k) · D_g · v                  [N]

â is the tool's acceleration, (v(k) − v(k−1))/dt low-pass filtered with time constant τ_a
(one pole, exact for a sampled first-order filter). D_g is the extra damping at full gate
[N·s/m]; a_ref the deceleration [m/s²] at which the gate is fully open. The extra force
only ever opposes the velocity, so it takes energy out of the loop: it cannot make a
stable loop unstable, and it costs the person force only while the tool slows down.

:func:`deceleration_damping` is the pure law (arrays in, arrays out);
:class:`DecelerationDamping` wraps any controller's ``step`` with it and keeps â between
ticks (``reset`` starts a run).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_real
from coassist.control.controllers import ControlStep, saturate
from coassist.interfaces import ZERO_EFFORT_FAULTS, Fault

__all__ = ["DampingParameters", "DecelerationDamping", "deceleration_damping"]


@dataclass(frozen=True)
class DampingParameters:
    """gain D_g [N·s/m] ≥ 0; decel_ref a_ref [m/s²] > 0; accel_time τ_a [s] ≥ 0 (0: no filter)."""

    gain: float = 40.0
    decel_ref: float = 0.3
    accel_time: float = 0.02

    def __post_init__(self) -> None:
        object.__setattr__(self, "gain", check_real(self.gain, "DampingParameters.gain", 0.0))
        object.__setattr__(
            self, "decel_ref", check_real(self.decel_ref, "DampingParameters.decel_ref", 0.0, open_lo=True)
        )
        object.__setattr__(self, "accel_time", check_real(self.accel_time, "DampingParameters.accel_time", 0.0))


def deceleration_damping(v: ArrayLike, a: ArrayLike, params: DampingParameters) -> np.ndarray:
    """The extra effort −g·D_g·v [N] (module docstring) for velocity v and acceleration estimate a,
    shapes (n,) or (B, n); zero where the tool is at rest or not slowing down."""
    v = np.asarray(v, dtype=float)
    a = np.asarray(a, dtype=float)
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    along = np.sum(a * v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        decel = np.where(speed > 0.0, -along / np.where(speed > 0.0, speed, 1.0), 0.0)
    gate = np.clip(decel / params.decel_ref, 0.0, 1.0)
    return -gate * params.gain * v


class DecelerationDamping:
    """A controller whose effort gets :func:`deceleration_damping` added (module docstring).

    Parameters
    ----------
    controller : any controller with ``step(z, ref_h, ref_r, wrench) -> ControlStep`` on z = [Δx; v].
    params : the law's constants.

    A tick the inner controller refused (a zero-effort fault) stays refused: nothing is added.
    The sum is saturated to the inner controller's effort limit again, keeping its direction (the
    limit is the robot's; ``SATURATED`` is flagged).
    """

    def __init__(self, controller, params: DampingParameters | None = None) -> None:
        self.controller = controller
        self.params = DampingParameters() if params is None else params
        self.name = f"{controller.name}+decel-damping"
        self.model = controller.model
        self.horizon = controller.horizon
        self.effort_limit = getattr(controller, "effort_limit", None)
        self.n = int(self.model.n_dof)
        self.dt = float(self.model.dt)
        tau = self.params.accel_time
        self._gain = 1.0 - math.exp(-self.dt / tau) if tau > 0.0 else 1.0
        self.reset()

    def reset(self) -> None:
        self._v_prev: np.ndarray | None = None
        self._a = np.zeros(self.n)
        if callable(getattr(self.controller, "reset", None)):
            self.controller.reset()

    @property
    def alpha(self) -> float | None:
        return getattr(self.controller, "alpha", None)

    def step(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike, wrench: ArrayLike) -> ControlStep:
        out = self.controller.step(z, ref_h, ref_r, wrench)
        z = np.asarray(z)
        if z.shape != (2 * self.n,) or z.dtype.kind not in "iuf":
            return out  # no state of n DOFs (the inner guard has flagged it): neither read nor filtered
        v = z[self.n :].astype(float)
        if not np.isfinite(v).all():
            return out  # the inner guard has flagged it; the filter keeps its last good state
        if self._v_prev is not None:
            self._a += self._gain * ((v - self._v_prev) / self.dt - self._a)
        self._v_prev = v.copy()
        if out.fault & ZERO_EFFORT_FAULTS:
            return out
        u = out.u_r + deceleration_damping(v, self._a, self.params)
        if self.effort_limit is None:
            return ControlStep(u, out.u_h_model, out.fault)
        u, clipped = saturate(u, np.broadcast_to(np.asarray(self.effort_limit, dtype=float), u.shape))
        return ControlStep(u, out.u_h_model, out.fault | Fault.SATURATED if clipped else out.fault)
