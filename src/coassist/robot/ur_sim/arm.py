"""The simulated UR5 behind the simulator: MuJoCo physics, UR's motion commands and UR's conventions.

The physics is :class:`coassist.robot.mujoco_world.MujocoArmWorld` (the UR5 of example-robot-data
with the tool, its force/torque sensor and its joint servo), stepped one controller period
per :meth:`SimArm.step`. On top of it, what a UR controller does between a URScript motion
command and the joints:

Motion (one *mode* at a time, as the control script runs one motion thread at a time):

- ``speedj(qd, a)``: the joint velocity reference v moves toward qd with the leading joint's
  acceleration a (every joint's change scaled by the same factor, so they arrive together):
  ``v⁺ = v + (qd − v)·min(1, a·dt / max|qd − v|)``.
- ``speedl(xd, a)``: the same ramp on the TCP twist ``xd = [v (m/s); ω (rad/s)]`` (base frame,
  a on the linear part, ω scaled with it), turned into joint velocities with the damped
  pseudo-inverse of the TCP Jacobian (:func:`coassist.spatial.joint_velocity`).
- ``servoj(q, lookahead)``: first-order tracking of the target, ``v = (q_target − q_ref) / lookahead``
  (an approximation of UR's servo: its lookahead filter is this lag, about what the loop feels).
- ``movej(q, v, a)`` / ``movel(pose, v, a)``: a trapezoidal profile of the leading joint (movej)
  or of the TCP's path length (movel: a straight line, the orientation slerped), followed with
  a proportional correction; a blocking command ends when the profile has.
- ``stopj(a)`` / ``stopl(a)``: decelerate to rest (joint leading axis a [rad/s²], or the
  TCP's linear speed at a [m/s²]).
- ``force_mode(frame, selection, wrench, limits)``: the compliant axes of the task frame move
  as a damper, ``v_i = clip((w_i + f_ext,i) / FORCE_MODE_DAMPING, ±limit_i)``, the others hold
  still (UR's force mode approximately: its gains and type 1/3 frames are not modelled).

Every mode's joint velocity reference is clipped to the UR5's joint speed (π rad/s, the
datasheet's 180°/s) with all joints scaled together; a command beyond UR's limits (a speed
above the joint speed, an acceleration above ``MAX_JOINT_ACCELERATION``, a non-finite value)
is clipped and counted in :attr:`SimArm.out_of_limits`.

Conventions (UR's script manual and RTDE guide):

- ``actual_TCP_pose``: the flange (``tool0``) composed with the TCP offset (``set_tcp``; the
  installation's TCP), ``[x, y, z, rx, ry, rz]`` in the base frame, rotation as a rotation
  vector (axis·angle, angle in [0, π]).
- ``actual_TCP_speed``: ``[v, ω]`` of the TCP point in the base frame.
- ``actual_TCP_force``: the external wrench on the tool, force in the base frame's axes [N]
  and torque about the TCP in the base frame's axes [N·m]; a hand pushing the tool along +x
  reads +Fx. It is the flange sensor's reading with the payload's static weight removed
  (``set_payload``: mass and centre of gravity in the flange frame) and the
  ``zero_ftsensor`` offset subtracted (taken in the sensor's frame, so it turns with the
  tool, as a sensor's bias does). The inertial load of an accelerating tool stays in it.
- ``ft_raw_wrench``: the sensor's reading at the TCP in base axes before both.

Stops: a protective or emergency stop brings the joints to rest at
``SAFETY_STOP_DECELERATION`` (a category 2 / 1 stop), whatever the mode was.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from coassist.robot.mujoco_world import FTSensorModel, MujocoArmWorld, tool_down_ik
from coassist.runtime.world import Command, HandOperator
from coassist.spatial import joint_velocity, rotation_matrix, rotation_vector

__all__ = [
    "FORCE_MODE_DAMPING",
    "JOINT_SPEED_LIMIT",
    "MAX_JOINT_ACCELERATION",
    "MAX_TOOL_ACCELERATION",
    "MAX_TOOL_SPEED",
    "SAFETY_STOP_DECELERATION",
    "SimArm",
]

#: [rad/s] the UR5's joint speed, every joint (datasheet: 180°/s).
JOINT_SPEED_LIMIT = math.pi
#: [rad/s²] the largest joint acceleration a command may ask (ur_rtde refuses more: UR_JOINT_ACCELERATION_MAX).
MAX_JOINT_ACCELERATION = 40.0
#: [m/s], [m/s²] the largest tool speed and acceleration a command may ask (ur_rtde's UR_TOOL_* limits).
MAX_TOOL_SPEED = 3.0
MAX_TOOL_ACCELERATION = 150.0
#: [rad/s²] how fast a protective or emergency stop, or a stopped program, brings the joints to rest.
SAFETY_STOP_DECELERATION = 10.0
#: [N·s/m] the damping of the force mode's compliant axes (N·m·s/rad on the rotations).
FORCE_MODE_DAMPING = 100.0
#: [1/s] the proportional correction of movej/movel toward their profile.
_MOVE_GAIN = 10.0
_G = np.array([0.0, 0.0, -9.81])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _trapezoid(distance: float, v: float, a: float, t: float) -> tuple[float, float, float]:
    """(s, ṡ, duration) of a rest-to-rest trapezoid over ``distance`` at time ``t``; s ∈ [0, 1]."""
    if distance <= 0.0:
        return 1.0, 0.0, 0.0
    v = max(v, 1e-9)
    a = max(a, 1e-9)
    t_acc = v / a
    if a * t_acc * t_acc >= distance:  # triangular: never reaches v
        t_acc = math.sqrt(distance / a)
        v = a * t_acc
        t_flat = 0.0
    else:
        t_flat = (distance - a * t_acc * t_acc) / v
    total = 2.0 * t_acc + t_flat
    if t <= 0.0:
        return 0.0, 0.0, total
    if t < t_acc:
        d, sp = 0.5 * a * t * t, a * t
    elif t < t_acc + t_flat:
        d, sp = 0.5 * a * t_acc * t_acc + v * (t - t_acc), v
    elif t < total:
        r = total - t
        d, sp = distance - 0.5 * a * r * r, a * r
    else:
        d, sp = distance, 0.0
    return d / distance, sp / distance, total


class SimArm:
    """The UR5 in MuJoCo, moved by UR's motion commands (module docstring).

    Parameters
    ----------
    dt : the controller period [s] (0.002 e-Series, 0.008 CB3): one :meth:`step`.
    tool : the carried object ("handle", "board", "heavy").
    start : (3,) the TCP's start position [m], the tool pointing down.
    tcp_offset : (6,) the installation's TCP in the flange frame; None: the tool's TCP.
    payload : (mass [kg], cog (3,) [m] in the flange frame); None: the tool's true mass and centre.
    sensor : the flange force/torque sensor's model (noise, rate).
    seed : the sensor noise's seed.
    """

    n_joints = 6

    def __init__(
        self,
        dt: float,
        *,
        tool: str = "handle",
        start: Sequence[float] = (-0.10, -0.615, 0.20),
        tcp_offset: Sequence[float] | None = None,
        payload: tuple[float, Sequence[float]] | None = None,
        sensor: FTSensorModel | None = None,
        seed: int = 0,
    ) -> None:
        self.dt = float(dt)
        self.world = MujocoArmWorld(
            tool,
            robot="ur5",
            control_dt=self.dt,
            start=start,
            sensor=sensor or FTSensorModel(rate_hz=None),
            seed=seed,
        )
        model, data = self.world.model, self.world.data
        self._model, self._data = model, data
        self._flange = model.body("tool0").id
        self._jacp = np.zeros((3, model.nv))
        self._jacr = np.zeros((3, model.nv))
        self._vel6 = np.zeros(6)
        self._scratch = mujoco.MjData(model)  # kinematics at the reference joints (target_TCP_pose)
        mass, com = self.world.tool_mass_and_com()  # the tool below the sensor, in the sensor (flange) frame
        # the world gives its reading's torque and the centre of mass about its TCP; the controller's are the flange's
        self._lever = np.asarray(self.world.tcp_lever, dtype=float)
        com = com + self._lever
        self.tcp_offset = np.asarray(self.world.flange_to_tcp() if tcp_offset is None else tcp_offset, dtype=float)
        if payload is None:
            self.payload_mass, self.payload_cog = float(mass), np.asarray(com, dtype=float)
        else:
            self.payload_mass, self.payload_cog = float(payload[0]), np.asarray(payload[1], dtype=float)
        self.zero_offset = np.zeros(6)  # in the sensor frame [N, N·m about the flange]
        #: commands clipped because they were beyond UR's limits (module docstring)
        self.out_of_limits = 0
        self.mode = "idle"
        self.v_ref = np.zeros(6)  # the joint velocity reference (target_qd)
        self.a_ref = np.zeros(6)
        self.q_ref = self.world.data.qpos.copy()  # target_q
        self._target = np.zeros(6)
        self._accel = 1.0
        self._x_ref = np.zeros(6)  # speedl's twist reference
        self._servo_q = self.q_ref.copy()
        self._lookahead = 0.1
        self._move: dict | None = None
        self._force: dict | None = None
        self._stop_decel = 0.0
        self._stop_linear = False
        self._safety_stop = False
        self.t = 0.0
        self._sample()

    # ------------------------------------------------------------------ the hand
    @property
    def operator(self) -> HandOperator | None:
        """Whoever pushes on the handle (a :class:`~coassist.runtime.world.HandOperator`); None: nobody."""
        return self.world.operator

    @operator.setter
    def operator(self, value: HandOperator | None) -> None:
        self.world.operator = value

    # ------------------------------------------------------------------ commands
    def _limited(self, values: Sequence[float], limit: float, n: int = 6) -> np.ndarray:
        arr = np.asarray(values, dtype=float)[:n]
        if arr.shape != (n,) or not np.isfinite(arr).all():
            self.out_of_limits += 1
            return np.zeros(n)
        peak = float(np.max(np.abs(arr)))
        if peak > limit * (1.0 + 1e-9):
            self.out_of_limits += 1
            arr = arr * (limit / peak)
        return arr

    def _positive_limited(self, a: float, limit: float) -> float:
        """A speed or acceleration argument: ``a`` when in (0, limit], else the limit (counted)."""
        if not math.isfinite(a) or a <= 0.0:
            self.out_of_limits += 1
            return limit
        if a > limit:
            self.out_of_limits += 1
            return limit
        return float(a)

    def speedj(self, qd: Sequence[float], a: float) -> None:
        """Joint speed ``qd`` [rad/s], reached with the leading joint's acceleration ``a`` [rad/s²]."""
        if self._safety_stop:
            return
        self._target = self._limited(qd, JOINT_SPEED_LIMIT)
        self._accel = self._positive_limited(a, MAX_JOINT_ACCELERATION)
        self.mode = "speedj"

    def speedl(self, xd: Sequence[float], a: float) -> None:
        """TCP twist ``xd = [v, ω]`` [m/s, rad/s] (base frame), reached with tool acceleration ``a`` [m/s²]."""
        if self._safety_stop:
            return
        arr = np.asarray(xd, dtype=float)
        if arr.shape != (6,) or not np.isfinite(arr).all():
            self.out_of_limits += 1
            arr = np.zeros(6)
        lin = float(np.linalg.norm(arr[:3]))
        if lin > MAX_TOOL_SPEED:
            self.out_of_limits += 1
            arr = arr * (MAX_TOOL_SPEED / lin)
        if self.mode != "speedl":
            self._x_ref = self.tcp_speed.copy()
        self._target = arr
        self._accel = self._positive_limited(a, MAX_TOOL_ACCELERATION)
        self.mode = "speedl"

    def servoj(self, q: Sequence[float], lookahead: float) -> None:
        """Track the joint position ``q`` [rad] with the lag ``lookahead`` [s]."""
        if self._safety_stop:
            return
        arr = np.asarray(q, dtype=float)
        if arr.shape != (6,) or not np.isfinite(arr).all():
            self.out_of_limits += 1
            return
        if self.mode != "servoj":
            self.q_ref = self._data.qpos.copy()
        self._servo_q = arr
        self._lookahead = max(float(lookahead), self.dt)
        self.mode = "servoj"

    def movej(self, q: Sequence[float], v: float, a: float) -> None:
        """A trapezoidal joint move to ``q`` [rad] at speed ``v`` [rad/s], acceleration ``a`` (leading joint)."""
        if self._safety_stop:
            return
        q1 = np.asarray(q, dtype=float)
        if q1.shape != (6,) or not np.isfinite(q1).all():
            self.out_of_limits += 1
            return
        v = min(self._positive_limited(v, JOINT_SPEED_LIMIT), JOINT_SPEED_LIMIT)
        a = self._positive_limited(a, MAX_JOINT_ACCELERATION)
        q0 = self._data.qpos.copy()
        delta = q1 - q0
        dist = float(np.max(np.abs(delta)))
        self._move = {"kind": "j", "q0": q0, "delta": delta, "dist": dist, "v": v, "a": a, "t": 0.0}
        self.q_ref = q0.copy()
        self.mode = "move"

    def movel(self, pose: Sequence[float], v: float, a: float) -> None:
        """A trapezoidal straight-line TCP move to ``pose`` [m, rotation vector] at ``v`` [m/s], ``a`` [m/s²]."""
        if self._safety_stop:
            return
        p1 = np.asarray(pose, dtype=float)
        if p1.shape != (6,) or not np.isfinite(p1).all():
            self.out_of_limits += 1
            return
        v = min(self._positive_limited(v, MAX_TOOL_SPEED), MAX_TOOL_SPEED)
        a = self._positive_limited(a, MAX_TOOL_ACCELERATION)
        p0 = self.tcp_position.copy()
        R0 = self.tcp_rotation.copy()
        w = rotation_vector(R0.T @ rotation_matrix(p1[3:]))  # the turn, in the start TCP frame
        dp = p1[:3] - p0
        length = float(np.linalg.norm(dp))
        # a pure rotation runs its angle at v rad/s (UR: the orientation at the same speed and acceleration)
        dist = length if length > 1e-9 else float(np.linalg.norm(w))
        self._move = {"kind": "l", "p0": p0, "R0": R0, "dp": dp, "w": w, "dist": dist, "v": v, "a": a, "t": 0.0}
        self.mode = "move"

    def stop(self, a: float, *, linear: bool = False) -> None:
        """Decelerate to rest: joint leading axis ``a`` [rad/s²], or with ``linear`` the TCP at ``a`` [m/s²]."""
        lim = MAX_TOOL_ACCELERATION if linear else MAX_JOINT_ACCELERATION
        self._stop_decel = self._positive_limited(a, lim)
        self._stop_linear = bool(linear)
        self._force = None
        self._move = None
        self.mode = "stop"

    def force_mode(self, frame: Sequence[float], selection: Sequence[int], wrench: Sequence[float], limits) -> None:
        """UR's force mode, approximately (module docstring); the motion it overlays stops."""
        if self._safety_stop:
            return
        f = np.asarray(frame, dtype=float)
        w = np.asarray(wrench, dtype=float)
        lim = np.asarray(limits, dtype=float)
        sel = np.asarray(selection, dtype=float)
        if not all(x.shape == (6,) and np.isfinite(x).all() for x in (f, w, lim, sel)):
            self.out_of_limits += 1
            return
        self._force = {"R": rotation_matrix(f[3:]), "sel": sel != 0, "w": w, "lim": np.abs(lim)}
        self.mode = "force"

    def end_force_mode(self) -> None:
        self._force = None
        if self.mode == "force":
            self.mode = "speedj"
            self._target = np.zeros(6)
            self._accel = MAX_JOINT_ACCELERATION

    def safety_stop(self) -> None:
        """A protective or emergency stop: every motion ends, the joints brake to rest."""
        self._safety_stop = True
        self.stop(SAFETY_STOP_DECELERATION)

    def release(self) -> None:
        """The stop is cleared: commands move the arm again (from rest)."""
        self._safety_stop = False

    def set_tcp(self, pose: Sequence[float]) -> None:
        arr = np.asarray(pose, dtype=float)
        if arr.shape == (6,) and np.isfinite(arr).all():
            self.tcp_offset = arr
            self._sample()

    def set_payload(self, mass: float, cog: Sequence[float] | None) -> None:
        if math.isfinite(mass) and mass >= 0.0:
            self.payload_mass = float(mass)
        if cog is not None:
            c = np.asarray(cog, dtype=float)
            if c.shape == (3,) and np.isfinite(c).all():
                self.payload_cog = c

    def zero_ftsensor(self) -> None:
        """Take the present (payload-compensated) reading as zero from now on (in the sensor's frame)."""
        self.zero_offset = self._compensated_sensor_frame()

    def teleport(self, position) -> None:
        """Put the TCP at ``position`` (3,) [m], the tool pointing down, at rest (a simulator's reset, no motion).

        Raises ValueError when it is out of reach.
        """
        q = tool_down_ik(self._model, np.asarray(position, dtype=float), self.q)
        self.world.reset(q)
        self.mode, self._move, self._force = "idle", None, None
        self.v_ref = np.zeros(6)
        self.a_ref = np.zeros(6)
        self.q_ref = q.copy()
        self._sample()

    @property
    def moving(self) -> bool:
        return bool(np.any(np.abs(self.v_ref) > 1e-9)) or self.mode == "move"

    @property
    def move_done(self) -> bool:
        """A movej/movel profile has ended (the blocking command may signal done)."""
        return self._move is None

    @property
    def at_rest(self) -> bool:
        return not np.any(np.abs(self.v_ref) > 1e-9)

    # ------------------------------------------------------------------ the period
    def _ramp(self, v: np.ndarray, target: np.ndarray, a: float) -> np.ndarray:
        dv = target - v
        peak = float(np.max(np.abs(dv)))
        step = a * self.dt
        if peak <= step:
            return target.copy()
        return v + dv * (step / peak)

    def _tcp_jacobian(self) -> np.ndarray:
        point = self.tcp_position
        mujoco.mj_jac(self._model, self._data, self._jacp, self._jacr, point, self._flange)
        return np.vstack([self._jacp, self._jacr])

    def _reference(self) -> np.ndarray:
        dt, q = self.dt, self._data.qpos
        mode = self.mode
        if mode == "speedj":
            return self._ramp(self.v_ref, self._target, self._accel)
        if mode == "speedl":
            self._x_ref = self._ramp(self._x_ref, self._target, self._accel)
            return joint_velocity(self._tcp_jacobian(), self._x_ref)
        if mode == "servoj":
            return (self._servo_q - self.q_ref) / self._lookahead
        if mode == "move" and self._move is not None:
            m = self._move
            m["t"] += dt
            s, sd, total = _trapezoid(m["dist"], m["v"], m["a"], m["t"])
            if m["kind"] == "j":
                q_goal = m["q0"] + s * m["delta"]
                v = sd * m["delta"] + _MOVE_GAIN * (q_goal - q)
            else:
                p_goal = m["p0"] + s * m["dp"]
                R_goal = m["R0"] @ rotation_matrix(s * m["w"])
                twist = np.concatenate((sd * m["dp"], sd * (m["R0"] @ m["w"])))
                twist[:3] += _MOVE_GAIN * (p_goal - self.tcp_position)
                twist[3:] += _MOVE_GAIN * rotation_vector(R_goal @ self.tcp_rotation.T)  # log(R_goal Rᵀ), base axes
                v = joint_velocity(self._tcp_jacobian(), twist)
            if m["t"] >= total + 0.2 or (m["t"] >= total and float(np.max(np.abs(self._data.qvel))) < 1e-3):
                self._move = None
                self.mode = "idle"
                return np.zeros(6)
            return v
        if mode == "force" and self._force is not None:
            f = self._force
            R = f["R"]
            ext = self.tcp_force
            w_task = np.concatenate((R.T @ (f["w"][:3] + ext[:3]), R.T @ (f["w"][3:] + ext[3:])))
            v_task = np.where(f["sel"], np.clip(w_task / FORCE_MODE_DAMPING, -f["lim"], f["lim"]), 0.0)
            twist = np.concatenate((R @ v_task[:3], R @ v_task[3:]))
            return joint_velocity(self._tcp_jacobian(), twist)
        if mode == "stop":
            if self._stop_linear:
                speed = float(np.linalg.norm(self.tcp_speed[:3]))
                factor = 0.0 if speed <= self._stop_decel * dt else 1.0 - self._stop_decel * dt / speed
                out = self.v_ref * factor
            else:
                out = self._ramp(self.v_ref, np.zeros(6), self._stop_decel)
            if not np.any(np.abs(out) > 1e-9):
                self.mode = "idle"
                return np.zeros(6)
            return out
        return np.zeros(6)

    def step(self) -> None:
        """One controller period: the mode's joint velocity reference, clipped to the joint speed, then the physics."""
        v = np.asarray(self._reference(), dtype=float)
        if not np.isfinite(v).all():
            v = np.zeros(6)
        peak = float(np.max(np.abs(v)))
        if peak > JOINT_SPEED_LIMIT:
            v = v * (JOINT_SPEED_LIMIT / peak)
        self.a_ref = (v - self.v_ref) / self.dt
        self.v_ref = v
        self.q_ref = self.q_ref + v * self.dt if self.mode != "idle" else self._data.qpos.copy()
        self.world.apply(Command(qd=v))
        self.t += self.dt
        self._sample()

    def _sample(self) -> None:
        """Cache what the controller reports this period (module docstring: conventions)."""
        state = self.world.read()
        self.q = np.asarray(state.q, dtype=float)
        self.qd = np.asarray(state.qd, dtype=float)
        d = self._data
        self.flange_position = d.xpos[self._flange].copy()
        self.flange_rotation = d.xmat[self._flange].reshape(3, 3).copy()
        R_off = rotation_matrix(self.tcp_offset[3:])
        self.tcp_position = self.flange_position + self.flange_rotation @ self.tcp_offset[:3]
        self.tcp_rotation = self.flange_rotation @ R_off
        mujoco.mj_objectVelocity(self._model, d, mujoco.mjtObj.mjOBJ_BODY, self._flange, self._vel6, 0)
        omega, v_f = self._vel6[:3].copy(), self._vel6[3:].copy()
        self.tcp_speed = np.concatenate((v_f + _cross(omega, self.tcp_position - self.flange_position), omega))
        self._sensor_wrench = w = np.array(state.wrench, dtype=float)  # sensor (flange) frame, "tool on sensor" sign
        w[3:] += _cross(self._lever, w[:3])  # the flange sensor's own torque (the world's is about its TCP)
        self._sensor_rotation = np.asarray(state.sensor_rotation, dtype=float)
        comp = self._compensated_sensor_frame() - self.zero_offset
        self.tcp_force = self._to_tcp_base(comp)
        self.ft_raw = self._to_tcp_base(self._sensor_wrench)

    def _compensated_sensor_frame(self) -> np.ndarray:
        """The reading minus the payload's static weight, in the sensor frame (torque about the flange)."""
        Rs = self._sensor_rotation
        g_s = Rs.T @ _G  # gravity in the sensor frame
        f_p = self.payload_mass * g_s
        tau_p = _cross(self.payload_cog, f_p)
        w = self._sensor_wrench.copy()
        w[:3] -= f_p
        w[3:] -= tau_p
        return w

    def _to_tcp_base(self, w_sensor: np.ndarray) -> np.ndarray:
        """A sensor-frame wrench (torque about the flange) as force in base axes and torque about the TCP."""
        Rs = self._sensor_rotation
        F = Rs @ w_sensor[:3]
        tau = Rs @ w_sensor[3:] + _cross(self.flange_position - self.tcp_position, F)
        return np.concatenate((F, tau))

    @property
    def tcp_pose(self) -> np.ndarray:
        """(6,) ``actual_TCP_pose``: position [m] and rotation vector [rad], base frame."""
        return np.concatenate((self.tcp_position, rotation_vector(self.tcp_rotation)))

    def target_tcp_pose(self) -> np.ndarray:
        """(6,) ``target_TCP_pose``: the TCP pose at the joint reference ``q_ref``, by the same kinematics."""
        d = self._scratch
        d.qpos[:] = self.q_ref
        mujoco.mj_kinematics(self._model, d)
        p_f = d.xpos[self._flange]
        R_f = d.xmat[self._flange].reshape(3, 3)
        p = p_f + R_f @ self.tcp_offset[:3]
        return np.concatenate((p, rotation_vector(R_f @ rotation_matrix(self.tcp_offset[3:]))))
