"""The world a person plays in: the point-mass robot of the simulator, paced to the wall clock.

An ``effort`` world (:mod:`coassist.runtime.world`): the robot is the thesis' ideal
admittance, rendered physically in the x-y plane::

    M a + D v = u_h + u_r                                             (eq. 3.1, K = 0)
    z(k+1) = A_d z(k) + B_d (u_h(k) + u_r(k)),   z = [x, y, ẋ, ẏ]        (eq. 3.5, exact ZOH)

axis by axis (M and D diagonal), with the one plant step of every point-mass world
(:func:`coassist.model.plant.plant_step`, the simulator's too).

u_r is the tick's effort command, u_h the hand's force (:class:`~coassist.play.hand.BrowserHand`,
evaluated once per period at the start of the period). The force sensor is ideal and
samples every period: the reading at tick k+1 is u_h(k). Unlike
:class:`coassist.sim.point_mass.PointMassWorld` there is no simulated operator, object or
sensor noise: the person is the operator.

Pacing: with ``paced`` (the default) :meth:`apply` first waits for the period's
wall-clock deadline t₀ + (k+1)·dt, then samples the hand and integrates, and returns at
once: the loop runs at 1/dt (125 Hz) in real time, the hand is sampled as late as
possible and the new state reaches the page without waiting another period. When the
tick's work (read → command, and the monitor) ended after that deadline,
:attr:`last_overrun` holds the excess [s] and the loop flags ``Fault.DEADLINE_MISS``; a
period late by more than one whole period re-anchors the schedule instead of racing to
catch up.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from coassist.model.impedance import ImpedanceModel
from coassist.model.plant import PointMassPlant, plant_step
from coassist.runtime.world import Command, RobotState

__all__ = ["PlayWorld"]

_NO_JOINTS = np.zeros(0)
_NO_JOINTS.setflags(write=False)


class PlayWorld:
    """The 2-D admittance robot driven by a hand (module docstring).

    Parameters
    ----------
    model : the controller's impedance model (2 DOFs, x-y, diagonal M and D, K = 0; its dt is the period).
    hand : anything with ``force_xy(x, y, vx, vy) -> (fx, fy)`` [N].
    start : (2,) the tool's start position [m].
    paced : wait for the wall clock in :meth:`apply` (real time for a person).
    clock, sleep : the wall clock [s] and how to wait (tests may replace them).

    Attributes (read by the server after each period; plain floats)
    ----------
    x, y, vx, vy : the tool's state [m, m/s].  fh : (2,) the hand force of the last period [N].
    overruns : periods whose work ended after their deadline.
    """

    command_space = "effort"
    n_joints = 0

    def __init__(
        self,
        model: ImpedanceModel,
        hand,
        start,
        *,
        paced: bool = True,
        clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if model.n_dof != 2:
            raise ValueError(f"the play world is the x-y plane: the controller must have 2 DOFs, got {model.n_dof}")
        s = np.asarray(start, dtype=float)
        if s.shape != (2,) or not np.isfinite(s).all():
            raise ValueError(f"start must be 2 finite numbers [m], got {start!r}")
        if np.any(np.asarray(model.K) != 0.0):
            raise ValueError(
                "the play world renders the free plant M a + D v = u (K = 0): the controller's model has K != 0"
            )
        self.dt = float(model.dt)
        self.realtime = bool(paced)
        #: The plant M a + D v = u, per axis: the point-mass simulator's step (coassist.model.plant).
        self.plant = PointMassPlant.free(model)
        self.hand = hand
        self._clock, self._sleep = clock, sleep
        self.x, self.y = float(s[0]), float(s[1])
        self.vx = self.vy = 0.0
        self.fh = (0.0, 0.0)  # the hand force of the last period: what the sensor reads now
        self.k = 0  # periods applied (also the sensor's sample number)
        self._stopped = False
        self._t0: float | None = None
        self.last_overrun = 0.0
        self.overruns = 0

    def read(self) -> RobotState:
        if self._t0 is None:
            self._t0 = self._clock()  # the schedule starts at the first read
        return RobotState(
            t=self.k * self.dt,
            q=_NO_JOINTS,
            qd=_NO_JOINTS,
            tool_pose=np.array((self.x, self.y, 0.0, 0.0, 0.0, 0.0)),
            tool_twist=np.array((self.vx, self.vy, 0.0, 0.0, 0.0, 0.0)),
            wrench=np.array((self.fh[0], self.fh[1], 0.0, 0.0, 0.0, 0.0)),
            wrench_seq=self.k,
        )

    def hand_force(self) -> tuple[float, float]:
        """u_h(k) [N] applied during the last period (the loop logs it as effort_h)."""
        return self.fh

    def apply(self, command: Command) -> None:
        """One period: wait for the clock, then the hand's force, the plant under u_h + u_r, the sensor."""
        if self.realtime:
            self._wait()
        x, y, vx, vy = self.x, self.y, self.vx, self.vy
        fhx, fhy = self.hand.force_xy(x, y, vx, vy)
        if not (math.isfinite(fhx) and math.isfinite(fhy)):  # a broken hand lets go
            fhx = fhy = 0.0
        effort = command.effort
        urx = ury = 0.0
        if not (command.stop or self._stopped) and effort is not None:
            urx, ury = float(effort[0]), float(effort[1])
            if not (math.isfinite(urx) and math.isfinite(ury)):
                urx = ury = 0.0
        self.fh = (fhx, fhy)
        if command.stop or self._stopped:
            self._stopped = True  # a stopped robot brakes and holds, whatever the hand does
            self.vx = self.vy = 0.0
        else:
            p = self.plant
            self.x, self.vx = plant_step(x, vx, fhx + urx, p.a_xv[0], p.a_vv[0], p.b_x[0], p.b_v[0])
            self.y, self.vy = plant_step(y, vy, fhy + ury, p.a_xv[1], p.a_vv[1], p.b_x[1], p.b_v[1])
        self.k += 1

    def _wait(self) -> None:
        if self._t0 is None:
            self._t0 = self._clock()
        deadline = self._t0 + (self.k + 1) * self.dt
        now = self._clock()
        late = now - deadline
        self.last_overrun = max(0.0, late)
        if late > 0.0:
            self.overruns += 1
            if late > self.dt:  # re-anchor: never race to catch up
                self._t0 = now - (self.k + 1) * self.dt
            return
        self._sleep(deadline - now)

    def stop(self) -> None:
        self._stopped = True
        self.vx = self.vy = 0.0

    def close(self) -> None:
        pass
