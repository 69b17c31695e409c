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

from coassist.scenario.objects import OBJECTS, yaw_step

__all__ = ["HandForce", "HandPoint"]


class HandForce:
    """u_h = w + m·â of one trial (module docstring): :meth:`__call__` (arrays) or :meth:`step` (components) once
    per tick, in order."""

    def __init__(self, dt: float, accel_time: float, obj: str) -> None:
        known = OBJECTS.get(obj)
        self.dt = float(dt)
        self.mass = float(known.mass) if known is not None else 0.0
        self.gain = 1.0 - math.exp(-self.dt / accel_time) if accel_time > 0 else 1.0
        # the state as Python floats: a tick's arithmetic on two components is cheaper without numpy
        self._ax = self._ay = 0.0
        self._v_prev: tuple[float, float] | None = None

    @property
    def acceleration(self) -> tuple[float, float]:
        """â's components [m/s²] after the last tick."""
        return self._ax, self._ay

    def step(self, vx: float, vy: float, wx: float, wy: float) -> tuple[float, float]:
        """u_h's components [N] from the tool's velocity [m/s] and the sensor's force [N], as :meth:`__call__`."""
        if self._v_prev is not None:
            g, dt = self.gain, self.dt
            self._ax += g * ((vx - self._v_prev[0]) / dt - self._ax)
            self._ay += g * ((vy - self._v_prev[1]) / dt - self._ay)
        self._v_prev = (vx, vy)
        return wx + self.mass * self._ax, wy + self.mass * self._ay

    def __call__(self, v: np.ndarray, w: np.ndarray) -> np.ndarray:
        vx, vy = v.tolist()
        wx, wy = w.tolist()
        return np.array(self.step(vx, vy, wx, wy))


class HandPoint:
    """Where the hand is on an object that yaws on its mount: p_hand = p + θ J r_h, ṗ_hand = ṗ + θ̇ J r_h.

    The arm measures the tip; on an object held off-centre on a compliant mount (the board:
    :class:`~coassist.scenario.objects.CarriedObject` with a yaw mode) the hand point turns with the
    object's yaw θ, which no sensor reads. θ is observed from the hand force and the tip's acceleration
    through the object's own yaw equation (coassist.scenario.objects)::

        I_c θ̈ + c_θ θ̇ + k_θ θ = r_h × u_h − m r_c × â     (semi-implicit Euler, one step per tick)

    J r = (−r_y, r_x). Without a yaw mode (or an object coassist does not know) the offset is 0. Seen by
    the present estimate, the mount's compliance is a spring in series with the person's arm: on the
    board, r_h = 0.61 m and k_θ = 150 N·m/rad make a lateral 1/(|r_h|²/k_θ) ≈ 400 N/m, stiffer than
    nothing but softer than most arms, so ignoring it puts the estimate far short of the intent."""

    def __init__(self, dt: float, obj: str) -> None:
        known = OBJECTS.get(obj)
        self.dt = float(dt)
        self.active = known is not None and known.has_yaw
        self.board = known.yaw_constants() if known is not None else None
        self.theta = 0.0
        self.rate = 0.0

    def step(self, ux: float, uy: float, ax: float, ay: float) -> tuple[float, float, float, float]:
        """(Δx, Δy, Δẋ, Δẏ): the hand point less the tip's, position [m] and velocity [m/s], after this tick's update
        from the hand force u_h [N] and the tip's acceleration â [m/s²] (components; once per tick, in order)."""
        board = self.board
        if not self.active or board is None:
            return 0.0, 0.0, 0.0, 0.0
        # the plant's own step (coassist.sim.point_mass steps the simulated board with it)
        self.theta, self.rate, _, _, _ = yaw_step(board, self.theta, self.rate, ux, uy, ax, ay, self.dt)
        return self.theta * -board.rhy, self.theta * board.rhx, self.rate * -board.rhy, self.rate * board.rhx

    def __call__(self, u_h: np.ndarray, acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Δp, Δṗ): :meth:`step` on arrays, (2,) each."""
        dx, dy, dvx, dvy = self.step(float(u_h[0]), float(u_h[1]), float(acc[0]), float(acc[1]))
        return np.array((dx, dy)), np.array((dvx, dvy))
