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

    def __call__(self, u_h: np.ndarray, acc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Δp, Δṗ): the hand point less the tip's, position [m] and velocity [m/s], after this tick's update."""
        board = self.board
        if not self.active or board is None:
            return np.zeros(2), np.zeros(2)
        # the plant's own step (coassist.sim.point_mass steps the simulated board with it)
        self.theta, self.rate, _, _, _ = yaw_step(
            board, self.theta, self.rate, float(u_h[0]), float(u_h[1]), float(acc[0]), float(acc[1]), self.dt
        )
        turn = np.array([-board.rhy, board.rhx])
        return self.theta * turn, self.rate * turn
