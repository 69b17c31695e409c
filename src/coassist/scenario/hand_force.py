"""The hand's own force at the handle, from the sensor's reading and the tool's velocity.

The sensor between the handle and the carried object reads the hand's force less what
accelerates the object: u_h = w + m·â, with â the tool's acceleration from successive velocities
low-passed over ``accel_time`` (a first-order filter, â += g·((v − v_prev)/dt − â),
g = 1 − exp(−dt/accel_time); g = 1 without a filter). Shapes (2,) [N], [m/s], [m/s²]; m [kg] the
carried object's mass (0 where the object is unknown). Used by the present estimates of
:mod:`coassist.scenario.path_hypotheses` and :mod:`coassist.scenario.person_intent`.
"""

from __future__ import annotations

import math

import numpy as np

from coassist.scenario.objects import OBJECTS

__all__ = ["HandForce"]


class HandForce:
    """u_h = w + m·â of one trial (module docstring); :meth:`__call__` once per tick, in order."""

    def __init__(self, dt: float, accel_time: float, obj: str) -> None:
        known = OBJECTS.get(obj)
        self.dt = float(dt)
        self.mass = float(known.mass) if known is not None else 0.0
        self.gain = 1.0 - math.exp(-self.dt / accel_time) if accel_time > 0 else 1.0
        self.acc = np.zeros(2)
        self._v_prev: np.ndarray | None = None

    def __call__(self, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        if self._v_prev is not None:
            self.acc += self.gain * ((v - self._v_prev) / self.dt - self.acc)
        self._v_prev = v.copy()
        return w + self.mass * self.acc
