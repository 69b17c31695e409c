"""The point-mass world: the thesis' robot as an ideal admittance, with object, sensor and operator.

One period k → k+1 of :meth:`PointMassWorld.apply`, given the robot's effort u_r(k):

1. the operator's arm gives the hand force u_h(k) at the hand point (eq. 4.1 with delay,
   adaptation and noise, :class:`~coassist.scenario.operator.OperatorArm`); on the board
   the hand point turns with the board's yaw θ: p = x + θ J r_h (J r = (−r_y, r_x));
2. the board yaws (:mod:`coassist.scenario.objects`)::

       I_c θ̈ + c_θ θ̇ + k_θ θ = r_h × u_h − m r_c × a(k−1)

   (semi-implicit Euler), and the object's reaction on the tip is c = −m θ̈ J r_c;
3. the plant (M + m) a + D v = u_h + u_r + n_s + b_res + c (the object's mass m adds to the
   rendered inertia; the measured noise n_s and the residual bias b_res drive the
   admittance, which moves on what the sensor says) is held exactly over dt
   (:func:`coassist.model.plant.plant_step`, the one plant step of every point-mass world);
4. the sensor's next reading, at its own sample ticks (held between them), is
   u_h − m a + c + n_s + b_res, a = (v(k+1) − v(k))/dt, clipped to its saturation.

:class:`PointMassWorldBatch` is its array twin: the same period for B worlds at once, row
for row the same floats (the same helpers below for every formula both write, elementwise
on floats or arrays), for the point-mass array path (:mod:`coassist.sim.array_runner`).

Determinism: every random draw comes from Generators of the trial seed
(:mod:`coassist.scenario.seeds`: the trial's streams), drawn in the constructor in a fixed
order; the same seed gives the same world bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from coassist._rows import RowConstants
from coassist.model.impedance import ImpedanceModel
from coassist.model.plant import PointMassPlant, plant_step
from coassist.runtime.world import Command, RobotState
from coassist.scenario.objects import CarriedObject, ForceSensor, YawConstants, hand_point, yaw_step
from coassist.scenario.operator import OperatorArm, OperatorProfile, intent_trajectory, motor_noise
from coassist.scenario.seeds import trial_rngs
from coassist.scenario.tasks import Task

__all__ = ["PointMassWorld", "PointMassWorldBatch"]


def _net_force(fh, u, noise, bias, c):
    """What the plant integrates on one axis (step 3): u_h + u_r + n_s + b_res + c [N]."""
    return fh + u + noise + bias + c


def _sensed_force(fh, m, a, c, noise, bias):
    """The sensor's reading on one axis before clipping (step 4): u_h − m a + c + n_s + b_res [N]."""
    return fh - m * a + c + noise + bias


class PointMassWorld:
    """The 2-D point-mass world (module docstring): the thesis' robot as an ideal admittance.

    An ``effort`` world (:mod:`coassist.runtime.world`): it renders the impedance model
    physically, so the tick sends it the robot's effort u_r. It owns time (tick k), the
    operator's arm (called inside :meth:`apply`), the board's yaw and the force sensor.

    Parameters
    ----------
    task : the task (the start, and the operator's intent around its obstacle).
    operator : the operator's profile.
    obj : the object between hand and sensor.
    model : the controller's impedance model (2 DOFs, diagonal M and D; its dt is the period).
    seed : the trial's seed: every random draw (intent, motor noise, sensor) derives from it.
    n_max : ticks the run may last (the noise is drawn for them).
    n_grid : ticks of the intent's grid (≥ n_max + the intent horizon).
    sensor : the force sensor.
    """

    command_space = "effort"
    n_joints = 0
    realtime = False

    def __init__(
        self,
        task: Task,
        operator: OperatorProfile,
        obj: CarriedObject,
        model: ImpedanceModel,
        seed: int,
        n_max: int,
        n_grid: int,
        sensor: ForceSensor,
    ) -> None:
        dt = float(model.dt)
        self.dt = dt
        rng_intent, rng_motor, rng_sensor = trial_rngs(seed, 3)
        self.intent = intent_trajectory(task, operator, rng_intent, n_grid, dt)
        noise_h = motor_noise(operator, rng_motor, n_max, dt)
        self.raw_bias = sensor.raw_bias(obj, rng_sensor)
        residual = self.raw_bias - sensor.zero(self.raw_bias, rng_sensor)  # what zeroing leaves behind
        self.residual = residual
        noise_s = rng_sensor.normal(0.0, sensor.noise, (n_max + 1, 2))
        self._fresh = sensor.sample_ticks(n_max + 1, dt).tolist()
        self._sat = sensor.saturation
        #: The plant (M + m) a + D v = f, per axis (coassist.model.plant).
        self.plant = PointMassPlant.free(model, obj.mass)
        self._yaw = obj.has_yaw
        self._board = obj.yaw_constants()
        #: The operator's arm (called once per period by :meth:`apply`).
        self.arm = OperatorArm(operator, self.intent.positions, dt, noise_h)
        sat = self._sat
        self._nsx, self._nsy = noise_s[:, 0].tolist(), noise_s[:, 1].tolist()
        self._bres = (float(residual[0]), float(residual[1]))
        x0 = task.start
        self.x, self.y = float(x0[0]), float(x0[1])
        self.vx = self.vy = 0.0
        self._th = self._thd = self._thdd = 0.0
        self._ax_prev = self._ay_prev = 0.0
        self.wx = float(np.clip(residual[0] + noise_s[0, 0], -sat, sat))
        self.wy = float(np.clip(residual[1] + noise_s[0, 1], -sat, sat))
        self._seq = 0
        self.k = 0
        self._fh = (0.0, 0.0)
        self._stopped = False

    @property
    def stopped(self) -> bool:
        """The robot has been stopped (it brakes and holds from then on)."""
        return self._stopped

    def read(self) -> RobotState:
        return RobotState(
            t=self.k * self.dt,
            q=_NO_JOINTS,
            qd=_NO_JOINTS,
            tool_pose=np.array((self.x, self.y, 0.0, 0.0, 0.0, 0.0)),
            tool_twist=np.array((self.vx, self.vy, 0.0, 0.0, 0.0, 0.0)),
            wrench=np.array((self.wx, self.wy, 0.0, 0.0, 0.0, 0.0)),
            sensor_rotation=SENSOR_ROTATION,
            wrench_seq=self._seq,
        )

    def hand_force(self) -> tuple[float, float]:
        """The operator's force u_h(k) [N] applied during the last period."""
        return self._fh

    def apply(self, command: Command) -> None:
        """One period (module docstring): the operator's arm, the board, the plant under u_h + u_r, the sensor."""
        k = self.k
        dt = self.dt
        effort = command.effort
        if command.stop or self._stopped or effort is None:
            urx = ury = 0.0
        else:
            urx, ury = float(effort[0]), float(effort[1])
            if not (math.isfinite(urx) and math.isfinite(ury)):  # never integrate garbage
                urx = ury = 0.0
        x, y, vx, vy = self.x, self.y, self.vx, self.vy
        th, thd = self._th, self._thd
        board = self._board
        # 1. the operator (the hand point moves with the board's yaw)
        if self._yaw:
            px, py, pvx, pvy = hand_point(board, x, y, vx, vy, th, thd)
        else:
            px, py, pvx, pvy = x, y, vx, vy
        fhx, fhy = self.arm.force(k, px, py, pvx, pvy)
        self._fh = (fhx, fhy)
        # 2. the board
        m = board.m
        nsx, nsy = self._nsx[k + 1], self._nsy[k + 1]
        bres_x, bres_y = self._bres
        cx = cy = 0.0
        if self._yaw:
            th, thd, thdd, cx, cy = yaw_step(board, th, thd, fhx, fhy, self._ax_prev, self._ay_prev, dt)
            self._thdd, self._thd, self._th = thdd, thd, th
        # 3. the plant
        fx = _net_force(fhx, urx, nsx, bres_x, cx)
        fy = _net_force(fhy, ury, nsy, bres_y, cy)
        if command.stop or self._stopped:
            # a stopped robot brakes: the tool holds where it is, whatever the hand does
            self._stopped = True
            vx_new = vy_new = 0.0
            x_new, y_new = x, y
        else:
            plant = self.plant
            x_new, vx_new = plant_step(x, vx, fx, plant.a_xv[0], plant.a_vv[0], plant.b_x[0], plant.b_v[0])
            y_new, vy_new = plant_step(y, vy, fy, plant.a_xv[1], plant.a_vv[1], plant.b_x[1], plant.b_v[1])
        inv_dt = 1.0 / dt
        self._ax_prev = (vx_new - vx) * inv_dt
        self._ay_prev = (vy_new - vy) * inv_dt
        # 4. the sensor
        if self._fresh[k + 1]:
            sat = self._sat
            sx = _sensed_force(fhx, m, self._ax_prev, cx, nsx, bres_x)
            sy = _sensed_force(fhy, m, self._ay_prev, cy, nsy, bres_y)
            self.wx = sat if sx > sat else (-sat if sx < -sat else sx)
            self.wy = sat if sy > sat else (-sat if sy < -sat else sy)
            self._seq += 1
        self.x, self.y, self.vx, self.vy = x_new, y_new, vx_new, vy_new
        self.k = k + 1

    def stop(self) -> None:
        self._stopped = True
        self.vx = self.vy = 0.0

    def close(self) -> None:
        pass


_NO_JOINTS = np.zeros(0)
_NO_JOINTS.setflags(write=False)
#: The point-mass sensor's orientation: its frame is the base frame (one read-only array, not one per tick).
SENSOR_ROTATION = np.eye(3)
SENSOR_ROTATION.setflags(write=False)


class PointMassWorldBatch:
    """:meth:`PointMassWorld.apply` for B worlds at once, row for row the same floats: its array twin.

    Holds the B worlds' state as arrays: :attr:`position` and :attr:`velocity` (B, 2) [m,
    m/s], the sensor's latest reading :attr:`wrench` (B, 2) [N] and sample counter
    :attr:`wrench_seq` (B,). :meth:`apply` advances the rows given by one period, as each
    world's ``apply`` with an effort command would (never stopped: a run that stops leaves
    the array path before). The worlds themselves are left as they were.

    Parameters
    ----------
    worlds : B :class:`PointMassWorld` at tick 0, not stopped (:meth:`accepts`), one period dt.
    """

    @staticmethod
    def accepts(world: object) -> bool:
        """Whether ``world`` can join a batch: a :class:`PointMassWorld` at tick 0, not stopped, whose arm's type has
        an array twin (a ``batch`` of its arms: the simulated operator's, :meth:`OperatorArm.batch`, or a person's
        twin's, :meth:`coassist.sim.person_twin.TwinArm.batch`)."""
        return (
            type(world) is PointMassWorld
            and world.k == 0
            and not world.stopped
            and callable(getattr(type(world.arm), "batch", None))
        )

    def __init__(self, worlds: Sequence[PointMassWorld]) -> None:
        for i, w in enumerate(worlds):
            if not self.accepts(w):
                raise ValueError(f"worlds[{i}] is not a PointMassWorld at tick 0 (PointMassWorldBatch.accepts)")
        if not worlds:
            raise ValueError("a PointMassWorldBatch needs at least one world")
        self.dt = dt = float(worlds[0].dt)
        if any(float(w.dt) != dt for w in worlds):
            raise ValueError("the worlds of a PointMassWorldBatch must share one period dt")
        self.sensor_rotation = SENSOR_ROTATION

        def f(seq) -> np.ndarray:
            return np.array(seq, dtype=float)

        self.position = f([[w.x, w.y] for w in worlds])
        self.velocity = f([[w.vx, w.vy] for w in worlds])
        self.wrench = f([[w.wx, w.wy] for w in worlds])
        self.wrench_seq = np.array([w._seq for w in worlds], dtype=np.int64)
        self._inv_dt = 1.0 / dt
        plants = [w.plant for w in worlds]
        self._a_xv, self._a_vv = f([p.a_xv for p in plants]), f([p.a_vv for p in plants])
        self._b_x, self._b_v = f([p.b_x for p in plants]), f([p.b_v for p in plants])
        self._board = YawConstants(*(f(column) for column in zip(*(w._board for w in worlds))))
        self._yaw = np.array([bool(w._yaw) for w in worlds])
        self._any_yaw = bool(self._yaw.any())
        self._th = f([w._th for w in worlds])
        self._thd = f([w._thd for w in worlds])
        self._a_prev = f([[w._ax_prev, w._ay_prev] for w in worlds])
        self._sat = f([w._sat for w in worlds])
        self._bres = f([w._bres for w in worlds])
        N = max(len(w._fresh) for w in worlds)
        self._fresh = np.zeros((len(worlds), N), dtype=bool)
        self._noise = np.zeros((len(worlds), N, 2))
        for b, w in enumerate(worlds):
            self._fresh[b, : len(w._fresh)] = w._fresh
            self._noise[b, : len(w._nsx), 0] = w._nsx
            self._noise[b, : len(w._nsy), 1] = w._nsy
        kinds = {type(w.arm) for w in worlds}
        if len(kinds) != 1:  # one array twin steps every row's arm
            names = ", ".join(sorted(k.__name__ for k in kinds))
            raise ValueError(f"the worlds of a PointMassWorldBatch must share one kind of arm, got {names}")
        self.arms = kinds.pop().batch([w.arm for w in worlds])
        # the per-world constants, gathered once per set of rows still going (the board's
        # columns last: read only where some world yaws)
        self._constants = RowConstants(
            (self._yaw, self._bres, self._a_xv, self._a_vv, self._b_x, self._b_v, self._sat, *self._board)
        )
        self._taken: tuple[np.ndarray, ...] = ()
        self._columns = self._board
        self._all_yaw = False

    def apply(self, k: int, rows: np.ndarray, effort: np.ndarray) -> np.ndarray:
        """Period k of the worlds ``rows`` (indices) under the efforts u_r (len(rows), 2) [N]; their
        hand forces u_h(k) (len(rows), 2) [N] (each world's ``hand_force()`` after its ``apply``)."""
        dt = self.dt
        x, v = self.position[rows], self.velocity[rows]
        th, thd = self._th[rows], self._thd[rows]
        taken = self._constants.take(rows)
        yaw, bias, a_xv, a_vv, b_x, b_v, sat_rows = taken[:7]
        if taken is not self._taken:  # a new set of rows: its board columns as one YawConstants
            self._taken, self._columns, self._all_yaw = taken, YawConstants(*taken[7:]), bool(yaw.all())
        columns = self._columns
        all_yaw = self._all_yaw  # every row yaws (a board cell): np.where would pick the yawing values
        # the board's columns only where some run yaws (without yaw only its mass is read)
        board = columns if self._any_yaw else None
        # 1. the operator (the hand point moves with the board's yaw)
        if board is not None:
            px, py, pvx, pvy = hand_point(board, x[:, 0], x[:, 1], v[:, 0], v[:, 1], th, thd)
            p, pv = np.stack([px, py], axis=1), np.stack([pvx, pvy], axis=1)
            if not all_yaw:
                p, pv = np.where(yaw[:, None], p, x), np.where(yaw[:, None], pv, v)
        else:
            p, pv = x, v
        fh = self.arms.force(k, rows, p, pv)
        # 2. the board
        m = columns.m
        noise = self._noise[rows, k + 1]
        c = np.zeros_like(x)
        if board is not None and yaw.any():
            a_prev = self._a_prev[rows]
            th_new, thd_new, thdd, cx, cy = yaw_step(board, th, thd, fh[:, 0], fh[:, 1], a_prev[:, 0], a_prev[:, 1], dt)
            c = np.stack([cx, cy], axis=1)
            if not all_yaw:
                thd_new, th_new, c = (
                    np.where(yaw, thd_new, thd),
                    np.where(yaw, th_new, th),
                    np.where(yaw[:, None], c, 0.0),
                )
            self._thd[rows] = thd_new
            self._th[rows] = th_new
        # 3. the plant
        f = _net_force(fh, effort, noise, bias, c)
        x_new, v_new = plant_step(x, v, f, a_xv, a_vv, b_x, b_v)
        a = (v_new - v) * self._inv_dt
        self._a_prev[rows] = a
        # 4. the sensor, for the rows with a new sample
        fresh = self._fresh[rows, k + 1]
        if fresh.all():  # every row samples (the sensors share their sample ticks): no row to pick
            s = _sensed_force(fh, m[:, None], a, c, noise, bias)
            sat = sat_rows[:, None]
            self.wrench[rows] = np.where(s > sat, sat, np.where(s < -sat, -sat, s))
            self.wrench_seq[rows] += 1
        elif fresh.any():
            at = rows[fresh]
            s = _sensed_force(fh[fresh], m[fresh, None], a[fresh], c[fresh], noise[fresh], bias[fresh])
            sat = sat_rows[fresh][:, None]
            self.wrench[at] = np.where(s > sat, sat, np.where(s < -sat, -sat, s))
            self.wrench_seq[at] += 1
        self.position[rows], self.velocity[rows] = x_new, v_new
        return fh
