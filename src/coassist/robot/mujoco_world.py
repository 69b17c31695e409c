"""An arm in MuJoCo (the UR5, the Panda) as a :class:`coassist.runtime.world.World` (``joint_velocity`` commands).

The physics is :func:`coassist.robot.arm_mjcf.build_arm_model`: the arm of
example-robot-data (:data:`coassist.robot.arms.ARMS`, ``robot=``) with a force/torque
sensor at the flange and the carried object below it; the MuJoCo world frame is the
arm's base frame. Frames, units and signs are those of :mod:`coassist.runtime.world`.
:class:`MujocoUR5World` is the UR5 (the default ``robot``); the servo, the sensor and the
operator below are the same for every arm, with the arm's own joint count, torque and
speed limits (its URDF's) and start seed (its ``home``). A redundant arm (the Panda's
7 joints) resolves eq. 3.6 with the start posture held in the null space
(:meth:`MujocoArmWorld.kinematics`, :class:`coassist.robot.arms.NullSpacePosture`).

One :meth:`MujocoArmWorld.apply` is one control period: the operator (a
:class:`~coassist.runtime.world.HandOperator`) is asked once, at the start of the
period, for its wrench given the handle's pose and twist; that wrench (base frame, at
the handle point) is applied for the whole period; the physics then runs
``control_dt / physics_dt`` steps. Each physics step the joint servo (a UR's
``speedJ``) moves its reference joint velocity toward the command with a first-order
lag of ``servo_time_constant`` and tracks it by computed torque (the arm's inertia,
gravity and Coriolis terms, and a critically damped position/velocity loop at
``servo_bandwidth``; :mod:`coassist.robot.ur5_mjcf`), clipped to the arm's joint
torques. So the joints follow the command with that lag and the hand does not
back-drive them (a 10 N push held 1 s deflects the UR5 by 0.04–0.21 mrad, the Panda with
the handle by 1.6 mrad; the Panda with the heavy block, at 0.95 × its wrist torque, by 36
mrad under a sideways push), as on the real geared arm. An arm whose joint torques cannot hold the
tool at its start (the Panda under the 8 kg board) is refused when the world is built.

Timing within a period: the operator sees the state at the start of the period; the
sensor's samples are taken at their own instants (the physics step in which a sample
time falls; MuJoCo's force sensor reflects that step's start state, 1 physics step old).

The force/torque sensor (:class:`FTSensorModel`) samples MuJoCo's force and torque
sensors at ``rate_hz`` (100 Hz, a Robotiq FT300), adds a constant bias and white noise
drawn from the trial's sensor stream (:func:`coassist.scenario.seeds.trial_rngs`), and clips to its range; a sample is held
until the next one and ``RobotState.wrench_seq`` counts them. The reading has the sign
of the force the tool applies to the sensor (at rest: the tool's weight, m Rᵀ g with
g = (0, 0, −9.81)), in the sensor frame (the flange frame, ``tool0`` on the UR5), its torque about the
TCP, as a UR controller reports its TCP force (the sensor's own torque less r × f, r the TCP from the
sensor, :attr:`MujocoArmWorld.tcp_lever`: a push at the TCP has no torque there; noise and bias on the
sensor's own channels, the range on the reading's); :meth:`MujocoArmWorld.tool_mass_and_com` gives the
centre of mass from the TCP to match. (About the flange, a full-pose drive turned the tool 4.3° under
a pure 10 N push at the handle, which a UR's TCP force leaves untouched.)

Determinism: the physics is deterministic and the only randomness is the sensor noise,
so the same seed and the same commands give bit-identical states.

:class:`MujocoArmGroup` steps the worlds of a lockstep group (:func:`coassist.robot.drive.drive_lockstep`)
in one MuJoCo model: the same states, bit for bit, for a fraction of the physics' Python.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from coassist._checks import check_optional_int
from coassist.errors import CoassistError
from coassist.robot.arm_mjcf import TOOLS, build_arm_model, build_arm_spec, urdf_joint_limits
from coassist.robot.arms import NullSpacePosture, arm_kinematics, get_arm
from coassist.robot.ur5_mjcf import Q_SEED
from coassist.robot.worlds import WorldRequest
from coassist.runtime.world import Command, HandOperator, RobotState
from coassist.scenario.seeds import trial_rngs
from coassist.spatial import rotation_vector, rotation_vector_unchecked  # rotation_vector: re-exported

__all__ = [
    "DEFAULT_START",
    "ConstraintInGroup",
    "FTSensorModel",
    "MujocoArmGroup",
    "MujocoArmWorld",
    "MujocoUR5World",
    "TOOL_DOWN",
    "build_world",
    "rotation_vector",
    "tool_down_ik",
]

#: The default start TCP position [m] (base frame): the tasks' START at 0.2 m height.
DEFAULT_START = (-0.10, -0.615, 0.20)
#: The start orientation of the tool (tool0 axes in the base frame): pointing straight
#: down, tool x along base x (so tool y = −base y).
TOOL_DOWN = np.diag([1.0, -1.0, -1.0])

#: [rad] the joint servo's largest position error; beyond it (torque limits, a hard
#: push) the reference is pulled back once per period so it does not wind up.
MAX_TRACKING_ERROR = 0.05
#: MuJoCo's force/torque sensors report the wrench the parent (the wrist) exerts on the
#: subtree below the site; coassist's sensor reports the one the tool exerts on the
#: sensor: the opposite (verified in tests/robot/test_mujoco_world.py).
_MUJOCO_TO_COASSIST = -1.0


def _sample_number(steps: int, physics_dt: float, rate_hz: float) -> int:
    """The sensor's sample in which physics step ``steps`` falls: a new one is taken where it changes."""
    return math.floor(steps * physics_dt * rate_hz + 1e-9)


@dataclass(frozen=True)
class FTSensorModel:
    """The force/torque sensor (module docstring).

    noise_force, noise_torque : white-noise standard deviations [N], [N·m] (≥ 0).
    rate_hz : sample rate [Hz] (readings held between samples); None: a new sample at
        the end of every control period.
    force_range, torque_range : |reading| limits per channel [N], [N·m].
    bias : (6,) constant offset added to every reading [N, N·m].
    """

    noise_force: float = 0.05
    noise_torque: float = 0.002
    rate_hz: float | None = 100.0
    force_range: float = 300.0
    torque_range: float = 30.0
    bias: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("noise_force", "noise_torque"):
            v = _number(getattr(self, name), f"FTSensorModel.{name}")
            if v < 0.0:
                raise ValueError(f"FTSensorModel.{name} must be >= 0, got {v!r}")
            object.__setattr__(self, name, v)
        for name in ("force_range", "torque_range"):
            v = _number(getattr(self, name), f"FTSensorModel.{name}")
            if v <= 0.0:
                raise ValueError(f"FTSensorModel.{name} must be > 0, got {v!r}")
            object.__setattr__(self, name, v)
        if self.rate_hz is not None:
            v = _number(self.rate_hz, "FTSensorModel.rate_hz")
            if v <= 0.0:
                raise ValueError(f"FTSensorModel.rate_hz must be > 0 or None, got {v!r}")
            object.__setattr__(self, "rate_hz", v)
        bias = np.asarray(self.bias, dtype=float)
        if bias.shape != (6,) or not np.isfinite(bias).all():
            raise ValueError(f"FTSensorModel.bias must be 6 finite numbers [N, N·m], got {self.bias!r}")
        object.__setattr__(self, "bias", tuple(float(b) for b in bias))


def _number(value, name: str) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def tool_down_ik(model: mujoco.MjModel, position, q_seed=None, *, site: str = "tcp") -> np.ndarray:
    """Joint angles that put ``site`` at ``position`` (base frame) with the tool down (:data:`TOOL_DOWN`).

    Damped least squares on MuJoCo's site Jacobian (mj_jacSite), from ``q_seed``
    (default :data:`~coassist.robot.ur5_mjcf.Q_SEED`: elbow up, wrist down), steps
    capped at 0.5 rad. Raises ValueError (naming ``start``) when it does not converge
    to 1e-6 m / 1e-6 or leaves the joint ranges.
    """
    p = np.asarray(position, dtype=float)
    q = (Q_SEED if q_seed is None else np.asarray(q_seed, dtype=float)).copy()
    sid = model.site(site).id
    d = mujoco.MjData(model)
    jp, jr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    for _ in range(200):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        Re = TOOL_DOWN @ d.site_xmat[sid].reshape(3, 3).T
        e = np.concatenate(
            [p - d.site_xpos[sid], 0.5 * np.array([Re[2, 1] - Re[1, 2], Re[0, 2] - Re[2, 0], Re[1, 0] - Re[0, 1]])]
        )
        if float(np.linalg.norm(e)) < 1e-12:
            break
        mujoco.mj_jacSite(model, d, jp, jr, sid)
        J = np.vstack([jp, jr])
        dq = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), e)
        n = float(np.linalg.norm(dq))
        if n > 0.5:
            dq *= 0.5 / n
        q += dq
    d.qpos[:] = q
    mujoco.mj_kinematics(model, d)
    pos_err = float(np.linalg.norm(p - d.site_xpos[sid]))
    rot_err = float(np.linalg.norm(d.site_xmat[sid].reshape(3, 3) - TOOL_DOWN))
    lo, hi = model.jnt_range[:, 0], model.jnt_range[:, 1]
    if pos_err > 1e-6 or rot_err > 1e-6 or np.any(q < lo) or np.any(q > hi):
        raise ValueError(
            f"start {p.tolist()} is not reachable with the tool pointing down from the seed "
            f"(IK error {pos_err:.3g} m, {rot_err:.3g} in rotation)"
        )
    return q


class MujocoArmWorld:
    """An arm in MuJoCo (module docstring); implements :class:`~coassist.runtime.world.World`.

    Parameters
    ----------
    tool : the carried object, one of ``("handle", "board", "heavy")``.
    robot : the arm, a key of :data:`coassist.robot.arms.ARMS` with a MuJoCo model
        ("ur5", "panda").
    control_dt : the control period [s] (0.008 at 125 Hz, 0.002 at 500 Hz); a positive
        multiple of ``physics_dt``.
    physics_dt : the MuJoCo step [s]; None: 0.002 s, or the largest divisor of
        control_dt under it.
    start : (3,) the start TCP position [m] in the base frame; the tool points straight
        down (:data:`TOOL_DOWN`). The joints come from a damped-least-squares IK from
        ``q_seed`` (default: the arm's ``home``; the UR5's elbow up, wrist down,
        :data:`~coassist.robot.ur5_mjcf.Q_SEED`).
    servo_time_constant : [s] first-order lag of the joint velocity behind the command.
    sensor : the :class:`FTSensorModel` (default: 0.05 N noise at 100 Hz, no bias).
    operator : the :class:`~coassist.runtime.world.HandOperator`, or None (no hand).
    seed : the trial's seed: the sensor noise is its sensor stream (:func:`coassist.scenario.seeds.trial_rngs`'s
        third); None: unseeded.
    tcp_offset : (3,) the TCP in the tool0 frame [m]; None: the tool's default (the
        handle point for the handle and the heavy block, the vacuum cup for the board).
    gravity : False turns gravity off (tests).
    realtime : pace :meth:`apply` to the wall clock (a viewer).
    view : open MuJoCo's passive viewer (needs a display), synced every period.
    q_seed : (n,) the joint configuration the start IK begins from [rad]; None: the
        arm's ``home``.
    servo_bandwidth : [Hz] the bandwidth of the computed-torque servo's critically damped
        position/velocity loop (ω = 2π·bandwidth: how stiffly each joint tracks its reference).
    posture_gain : k_n [1/s] of the null-space posture of a redundant arm.
    """

    command_space = "joint_velocity"

    def __init__(
        self,
        tool: str = "handle",
        *,
        robot: str = "ur5",
        control_dt: float = 0.008,
        physics_dt: float | None = None,
        start=DEFAULT_START,
        servo_time_constant: float = 0.02,
        sensor: FTSensorModel | None = None,
        operator: HandOperator | None = None,
        seed: int | None = 0,
        tcp_offset=None,
        gravity: bool = True,
        realtime: bool = False,
        view: bool = False,
        q_seed=None,
        servo_bandwidth: float = 25.0,
        posture_gain: float = 1.0,
    ) -> None:
        arm = get_arm(robot)
        n = arm.n_joints
        if tool not in TOOLS:
            raise ValueError(f"tool must be one of {TOOLS}, got {tool!r}")
        control_dt = _number(control_dt, "control_dt")
        if control_dt <= 0.0:
            raise ValueError(f"control_dt must be > 0, got {control_dt!r}")
        if physics_dt is None:
            physics_dt = control_dt / math.ceil(control_dt / 0.002 - 1e-9)
        physics_dt = _number(physics_dt, "physics_dt")
        if not 0.0 < physics_dt <= 0.004:
            raise ValueError(f"physics_dt must be in (0, 0.004] s (the servo's stability), got {physics_dt!r}")
        n_sub = round(control_dt / physics_dt)
        if n_sub < 1 or abs(n_sub * physics_dt - control_dt) > 1e-9 * max(1.0, control_dt):
            raise ValueError(f"control_dt must be a positive multiple of physics_dt={physics_dt}, got {control_dt!r}")
        bandwidth = _number(servo_bandwidth, "servo_bandwidth")
        if not 0.0 < bandwidth <= 0.1 / physics_dt:
            raise ValueError(
                f"servo_bandwidth must be in (0, {0.1 / physics_dt:g}] Hz at physics_dt={physics_dt} "
                f"(the discrete servo's stability), got {servo_bandwidth!r}"
            )
        tau = _number(servo_time_constant, "servo_time_constant")
        if tau <= 0.0:
            raise ValueError(f"servo_time_constant must be > 0, got {servo_time_constant!r}")
        if sensor is None:
            sensor = FTSensorModel()
        elif not isinstance(sensor, FTSensorModel):
            raise ValueError(f"sensor must be an FTSensorModel, got {type(sensor).__name__}")
        if operator is not None and not callable(getattr(operator, "force", None)):
            raise ValueError(f"operator must have a force(t, hand_pose, hand_twist) method, got {operator!r}")
        start_arr = np.asarray(start, dtype=float)
        if start_arr.shape != (3,) or not np.isfinite(start_arr).all():
            raise ValueError(f"start must be 3 finite numbers [m] (base frame), got {start!r}")
        q0 = np.array(arm.home) if q_seed is None else np.asarray(q_seed, dtype=float)
        if q0.shape != (n,) or not np.isfinite(q0).all():
            raise ValueError(f"q_seed must be {n} finite joint angles [rad], got {q_seed!r}")
        seed = check_optional_int(seed, "seed")

        self.tool = tool
        self.robot, self.n_joints = arm.name, n
        self.posture_gain = float(posture_gain)
        self.velocity_limits = urdf_joint_limits(arm.name)[2]
        self.dt = control_dt
        self.physics_dt = physics_dt
        self.n_substeps = int(n_sub)
        self.servo_time_constant = tau
        self.sensor = sensor
        self.operator = operator
        self.realtime = bool(realtime)
        self.servo_bandwidth = bandwidth
        self.model = build_arm_model(
            arm.name,
            tool,
            physics_dt=physics_dt,
            servo_time_constant=tau,
            tcp_offset=tcp_offset,
            gravity=gravity,
        )
        # what the model was built from: worlds built alike can share one model (MujocoArmGroup)
        self._spec_args = (
            arm.name,
            tool,
            physics_dt,
            tau,
            None if tcp_offset is None else tuple(np.asarray(tcp_offset, dtype=float).tolist()),
            bool(gravity),
        )
        self._group: MujocoArmGroup | None = None
        self._applied = False
        self._dofs = slice(0, n)  # this arm's joints among its model's (a group's model holds several arms)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._tcp = m.site("tcp").id
        self._handle = m.site("handle").id
        self._ft = m.site("ft_sensor").id
        self._tool_body = m.body("tool").id
        self._tool0 = m.body(arm.tip_frame).id  # the flange
        self._force_adr = int(m.sensor("ft_force").adr[0])
        self._torque_adr = int(m.sensor("ft_torque").adr[0])
        omega = 2.0 * math.pi * bandwidth
        self._kp = omega * omega
        self._kd = 2.0 * omega
        self._alpha = 1.0 - math.exp(-physics_dt / tau)
        self._sigma = np.array([sensor.noise_force] * 3 + [sensor.noise_torque] * 3)
        self._range = np.array([sensor.force_range] * 3 + [sensor.torque_range] * 3)
        self._bias = np.asarray(sensor.bias, dtype=float)
        # the trial's sensor stream (coassist.scenario.seeds: the third child of the trial's, as the point-mass world's
        # sensor): default_rng(seed) drew the sensor's noise from the task's own stream (SeedSequence([s, 0]))
        self._rng = np.random.default_rng() if seed is None else trial_rngs(seed, 3)[2]

        self.q_start = tool_down_ik(self.model, start_arr, q0)
        # Servo state: the lagged reference velocity and its integral.
        self._v_ref = [0.0] * n  # lists of floats: the servo runs on plain floats
        self._q_ref = self.q_start.tolist()
        self._target = [0.0] * n
        self._u_list = [0.0] * n
        self._hand = np.zeros(6)
        self._hand_list = [0.0] * 6
        self._hand_active = False
        self._u = np.zeros(n)
        self._inv_dt = 1.0 / physics_dt
        #: times the servo's position error reached MAX_TRACKING_ERROR (torque limits, a
        #: hard push) and its reference was pulled back to the arm (no wind-up).
        self.tracking_limit_events = 0
        self._jacp = np.zeros((3, n))
        self._jacr = np.zeros((3, n))
        self._vel6 = np.zeros(6)
        self._steps = 0
        self._sample_index = 0
        self.wrench_seq = 0
        self.protective_stop = False
        self.emergency_stop = False
        #: apply() calls whose joint velocity was missing, of the wrong shape or not finite (zero was used).
        self.invalid_commands = 0
        #: operator wrenches that were not a finite (6,) array (zero was used).
        self.invalid_hand_wrenches = 0
        self._closed = False

        d = self.data
        # Views into mjData (stable for the data's lifetime): no wrapper per access.
        self._ctrl = d.ctrl
        self._bias_force = d.qfrc_bias
        self._qpos = d.qpos
        self._qvel = d.qvel
        self._site_xpos = d.site_xpos
        self._site_xmat = d.site_xmat
        self._xipos = d.xipos
        self._xfrc_tool = d.xfrc_applied[self._tool_body]
        self._sensordata = d.sensordata
        d.qpos[:] = self.q_start
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)
        #: (3,) [m] the TCP from the sensor's origin, in the sensor frame (the tool is rigid: a constant); the
        #: reading's torque is about the TCP, the sensor's own is τ + tcp_lever × f
        self.tcp_lever = d.site_xmat[self._ft].reshape(3, 3).T @ (d.site_xpos[self._tcp] - d.site_xpos[self._ft])
        self.tcp_lever.setflags(write=False)
        # at rest the bias force is gravity's: an arm whose actuators cannot hold the tool falls from the first tick
        # (the Panda under the 8 kg board: its wrist at 1.84 × its 12 N·m; with nobody touching it the sensor read a
        # falling arm as pushes up to 169 N)
        share = np.abs(d.qfrc_bias[:n]) / m.actuator_forcerange[:n, 1]
        if share.max() > 1.0:
            j = int(np.argmax(share))
            raise ValueError(
                f"the {arm.name} cannot hold the {tool}: at its start its joint {j + 1} needs "
                f"{abs(d.qfrc_bias[j]):.1f} N·m against gravity, {share[j]:.2f} × its {m.actuator_forcerange[j, 1]:g} "
                f"N·m; carry another object (tool: one of {', '.join(t for t in TOOLS if t != tool)})"
            )
        self._set_servo(hold=True)
        mujoco.mj_forward(m, d)  # sensors at rest under the holding torques; also mj_step1's state
        self._wrench = self._sample()

        self._wall0: float | None = None
        self._viewer = None
        if view:
            if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
                raise RuntimeError("view=True needs a display (DISPLAY / WAYLAND_DISPLAY is not set)")
            import mujoco.viewer as mj_viewer

            self._viewer = mj_viewer.launch_passive(m, d)

    def reset(self, q) -> None:
        """Put the arm at rest at the joints ``q`` (n,) [rad]: the servo holds there, the sensor samples anew.

        The simulated time, the sensor's noise stream and its sample count go on. Raises
        ValueError unless ``q`` is n finite joint angles inside the joint ranges.
        """
        if self._group is not None:
            raise RuntimeError("MujocoArmWorld.reset on a world stepped in a MujocoArmGroup")
        q = np.asarray(q, dtype=float)
        lo, hi = self.model.jnt_range[:, 0], self.model.jnt_range[:, 1]
        if q.shape != (self.n_joints,) or not np.isfinite(q).all() or np.any(q < lo) or np.any(q > hi):
            raise ValueError(f"q must be {self.n_joints} finite joint angles inside the joint ranges, got {q!r}")
        m, d = self.model, self.data
        self._v_ref = [0.0] * self.n_joints
        self._q_ref = q.tolist()
        self._target = [0.0] * self.n_joints
        d.qpos[:] = q
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        mujoco.mj_forward(m, d)
        self._set_servo(hold=True)
        mujoco.mj_forward(m, d)
        self._wrench = self._sample()
        self.wrench_seq += 1

    # ------------------------------------------------------------------ physics
    def _set_servo(self, hold: bool = False) -> None:
        """The joint torques for the next physics step (needs mj_step1's M and c at the current state).

        Computed torque, h the physics step: the reference moves v⁺ = v_ref + α (target −
        v_ref) (the exact first-order lag over one step), a_ref = (v⁺ − v_ref)/h, and
        τ = M(q) [a_ref + 2ω (v_ref − q̇) + ω² (q_ref − q)] + c(q, q̇), clipped by the
        motors to the torque limits. An undisturbed arm ends the step at q̇ = v⁺ exactly;
        then q_ref += h v⁺ (MuJoCo's semi-implicit position update). Every mode of the
        error is critically damped at ω whatever the arm's inertia (ωh ≤ 0.63 here).
        """
        # Plain floats: six-element numpy operations cost about a microsecond each.
        h, alpha, kd, kp = self.physics_dt, self._alpha, self._kd, self._kp
        v_ref, q_ref, target = self._v_ref, self._q_ref, self._target
        qd, q = self._qvel.tolist(), self._qpos.tolist()
        u = self._u_list
        for i in range(self.n_joints):
            v = v_ref[i]
            dv = 0.0 if hold else alpha * (target[i] - v)
            u[i] = dv / h + kd * (v - qd[i]) + kp * (q_ref[i] - q[i])
            if not hold:
                v += dv
                v_ref[i] = v
                q_ref[i] += h * v
        self._u[:] = u
        ctrl = self._ctrl
        mujoco.mj_mulM(self.model, self.data, ctrl, self._u)
        ctrl += self._bias_force

    def _set_hand(self) -> None:
        """xfrc_applied of the tool body: the hand wrench moved from the handle to the body's COM."""
        fx, fy, fz, tx, ty, tz = self._hand_list
        hx, hy, hz = self._site_xpos[self._handle].tolist()
        cx, cy, cz = self._xipos[self._tool_body].tolist()
        rx, ry, rz = hx - cx, hy - cy, hz - cz
        # r × f by hand: np.cross costs tens of µs on 3-vectors.
        self._xfrc_tool[:] = (fx, fy, fz, tx + ry * fz - rz * fy, ty + rz * fx - rx * fz, tz + rx * fy - ry * fx)

    def _sample(self) -> np.ndarray:
        """A new sensor sample from MuJoCo's sensors (sign, bias, noise, saturation)."""
        raw = np.concatenate(
            (
                self._sensordata[self._force_adr : self._force_adr + 3],
                self._sensordata[self._torque_adr : self._torque_adr + 3],
            )
        )
        raw *= _MUJOCO_TO_COASSIST
        raw += self._bias
        noise = self._rng.standard_normal(6)
        noise *= self._sigma
        raw += noise
        # the sensor's reading, its torque about the TCP (module docstring)
        raw[3:] -= np.cross(self.tcp_lever, raw[:3])
        np.minimum(raw, self._range, out=raw)
        return np.maximum(raw, -self._range, out=raw)

    def _substep(self) -> None:
        m, d = self.model, self.data
        if self._hand_active:
            self._set_hand()
        self._set_servo()
        mujoco.mj_step2(m, d)
        mujoco.mj_step1(m, d)
        self._steps += 1
        if self.sensor.rate_hz is not None:
            idx = _sample_number(self._steps, self.physics_dt, self.sensor.rate_hz)
            if idx != self._sample_index:
                self._sample_index = idx
                self._wrench = self._sample()
                self.wrench_seq += 1

    # ------------------------------------------------------------------ World protocol
    @property
    def t(self) -> float:
        """The simulated time [s]."""
        return self._steps * self.physics_dt

    def read(self) -> RobotState:
        return RobotState(
            t=self.t,
            q=self._qpos.copy(),
            qd=self._qvel.copy(),
            tool_pose=self._site_pose(self._tcp),
            tool_twist=self._site_twist(self._tcp),
            wrench=self._wrench.copy(),
            sensor_rotation=self._site_xmat[self._ft].reshape(3, 3).copy(),
            wrench_seq=self.wrench_seq,
            protective_stop=self.protective_stop,
            emergency_stop=self.emergency_stop,
        )

    def apply(self, command: Command) -> None:
        if self._closed:
            raise RuntimeError(f"{type(self).__name__}.apply after close()")
        self._target = self._command_target(command).tolist()
        self._hand = self._hand_wrench()
        q = self._qpos.tolist()
        if any(abs(r - x) > MAX_TRACKING_ERROR for r, x in zip(self._q_ref, q)):
            self.tracking_limit_events += 1
            self._q_ref = [x + min(max(r - x, -MAX_TRACKING_ERROR), MAX_TRACKING_ERROR) for r, x in zip(self._q_ref, q)]
        self._hand_list = self._hand.tolist()
        self._hand_active = any(self._hand_list)
        if not self._hand_active:
            self._xfrc_tool[:] = 0.0
        if self._group is not None:  # the group steps the physics once every member has applied
            self._applied = True
            return
        for _ in range(self.n_substeps):
            self._substep()
        if self.sensor.rate_hz is None:
            self._wrench = self._sample()
            self.wrench_seq += 1
        if self._viewer is not None and self._viewer.is_running():
            self._viewer.sync()
        if self.realtime:
            now = time.perf_counter()
            if self._wall0 is None:
                self._wall0 = now - self.t
            lag = self._wall0 + self.t - now
            if lag > 0.0:
                time.sleep(lag)
            elif lag < -0.1:  # fell behind (a pause, a slow caller): re-anchor, no catching up
                self._wall0 = now - self.t

    def stop(self, max_time: float = 2.0) -> None:
        """Command zero joint velocity until |q̇| < 1e-3 rad/s (at most ``max_time`` s). In a
        :class:`MujocoArmGroup` nothing: the group holds an arm whose run ended (its run is over)."""
        if self._closed or self._group is not None:
            return
        for _ in range(max(1, math.ceil(max_time / self.dt))):
            self.apply(Command(stop=True))
            if np.max(np.abs(self._qvel)) < 1e-3 and max(abs(v) for v in self._v_ref) < 1e-3:
                break

    def close(self) -> None:
        if self._closed:
            return
        self.stop()
        self._closed = True
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    # ------------------------------------------------------------------ extras
    def trigger_protective_stop(self) -> None:
        """Simulate the controller's protective stop: the flag is set and the arm brakes to rest."""
        self.protective_stop = True

    def _command_target(self, command: Command) -> np.ndarray:
        """The servo's target joint velocity: command.qd clipped to the joint speed limits,
        zero when stopping; a missing, mis-shaped or non-finite qd is counted and read as zero."""
        n = self.n_joints
        if self.protective_stop or self.emergency_stop or getattr(command, "stop", False):
            return np.zeros(n)
        qd = getattr(command, "qd", None)
        try:
            arr = np.asarray(qd, dtype=float)
            ok = qd is not None and arr.shape == (n,) and math.isfinite(float(np.add.reduce(arr)))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            self.invalid_commands += 1
            return np.zeros(n)
        out = np.maximum(arr, -self.velocity_limits)
        return np.minimum(out, self.velocity_limits, out=out)

    def _hand_wrench(self) -> np.ndarray:
        if self.operator is None:
            return np.zeros(6)
        pose, twist = self.hand_pose()
        try:
            w = np.array(self.operator.force(self.t, pose, twist), dtype=float)
            ok = w.shape == (6,) and math.isfinite(float(np.add.reduce(w)))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            self.invalid_hand_wrenches += 1
            return np.zeros(6)
        return w

    def _site_pose(self, site: int) -> np.ndarray:
        return np.concatenate((self._site_xpos[site], rotation_vector_unchecked(self._site_xmat[site].reshape(3, 3))))

    def _site_twist(self, site: int) -> np.ndarray:
        mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_SITE, site, self._vel6, 0)
        return np.concatenate((self._vel6[3:], self._vel6[:3]))  # MuJoCo [ω; v] → [v; ω]

    def hand_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The handle's pose (6,) and twist (6,) in the base frame (what the operator is given)."""
        return self._site_pose(self._handle), self._site_twist(self._handle)

    @property
    def hand_wrench(self) -> np.ndarray:
        """The wrench the hand applies in the current period (base frame, at the handle)."""
        return self._hand.copy()

    @property
    def noise_free_sensor(self) -> bool:
        """The sensor model has no noise (``noise_force`` = ``noise_torque`` = 0): it repeats exactly on a constant push."""
        return not (self.sensor.noise_force or self.sensor.noise_torque)

    def tool_mass_and_com(self) -> tuple[float, np.ndarray]:
        """Mass [kg] of everything below the sensor and its centre of mass (3,) from the TCP, in the sensor frame
        [m]: the point the reading's torque is about (module docstring)."""
        d = self.data
        R = d.site_xmat[self._ft].reshape(3, 3)
        com = R.T @ (d.subtree_com[self._tool0] - d.site_xpos[self._tcp])
        return float(self.model.body_subtreemass[self._tool0]), com

    def flange_to_tcp(self) -> np.ndarray:
        """(6,) the TCP pose in the flange frame ``[x, y, z, rx, ry, rz]`` [m, rad] (the kinematics' TCP offset)."""
        d = self.data
        R0 = d.xmat[self._tool0].reshape(3, 3)
        rel = R0.T @ (d.site_xpos[self._tcp] - d.xpos[self._tool0])
        Rrel = R0.T @ d.site_xmat[self._tcp].reshape(3, 3)
        return np.concatenate([rel, rotation_vector(Rrel)])

    def kinematics(self):
        """The arm's kinematics with this world's TCP (eq. 3.6 of the tick): an
        :class:`~coassist.robot.kinematics.ArmKinematics`, or on a redundant arm a
        :class:`~coassist.robot.arms.NullSpacePosture` holding the start posture."""
        kin = arm_kinematics(self.robot, self.flange_to_tcp())
        if self.n_joints > 6:
            return NullSpacePosture(kin, self.q_start, gain=self.posture_gain)
        return kin

    def tcp_jacobian(self) -> np.ndarray:
        """(6, n) TCP Jacobian [linear; angular] in the base frame at the current joints."""
        mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, self._tcp)
        if self._group is None:
            return np.vstack([self._jacp, self._jacr])
        cols = self._dofs  # this arm's columns of the group's model
        return np.vstack([self._jacp[:, cols], self._jacr[:, cols]])

    def __enter__(self) -> MujocoArmWorld:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class ConstraintInGroup(CoassistError, RuntimeError):
    """A constraint (a joint at its limit) became active in a :class:`MujocoArmGroup`'s model: MuJoCo's
    solver then runs over every arm, and the arms' states are no longer their own worlds' bit for bit."""


class MujocoArmGroup:
    """The worlds of a lockstep group stepped in one MuJoCo model (issue 44).

    Each world keeps its own servo state, hand, sensor noise and counters; its model and data become its
    arm's slot of one model holding every member's arm (the spec it was built from, attached once per
    member, all at the base's place: the arm models have no contacts, so the arms never touch). A member's
    :meth:`MujocoArmWorld.apply` asks its hand and sets its servo's target as before, and the physics waits
    for :meth:`step`, called once per control period after every member has applied (``run_loops``'
    ``after_tick``): each physics step is the world's servo on (B, n) arrays (its formula, elementwise in its
    order), one ``mj_mulM`` and one mj_step2/mj_step1 for every arm, then each member's sensor samples.

    Every arm's joints, velocities, controls and samples are its own world's bit for bit
    (``benchmarks/bench_mujoco_arms.py``, ``tests/robot/test_drive_lockstep.py``) while no constraint is
    active: MuJoCo runs its constraint solver over the whole model once any joint of any arm is at its limit
    (none in 1.46 million physics steps of three of the main job's MuJoCo jobs, board cells and the arm's probe
    trials; docs/performance.md). A step with one raises :class:`ConstraintInGroup` (the caller
    runs its worlds again apart). A member that does not apply in a period (its run ended) is held: its target
    zero, its hand let go. Members are built alike (:meth:`key`), none stepped yet.
    """

    def __init__(self, worlds: Sequence[MujocoArmWorld]) -> None:
        worlds = list(worlds)
        if (
            len(worlds) < 2
            or len({MujocoArmGroup.key(w) for w in worlds}) != 1
            or None in map(MujocoArmGroup.key, worlds)
        ):
            raise ValueError("a MujocoArmGroup takes two or more fresh worlds built alike (MujocoArmGroup.key)")
        w0 = worlds[0]
        parent = mujoco.MjSpec()
        parent.option.timestep = w0.model.opt.timestep
        parent.option.gravity = w0.model.opt.gravity.copy()
        parent.option.integrator = w0.model.opt.integrator
        robot, tool, physics_dt, tau, tcp_offset, gravity = w0._spec_args
        for i in range(len(worlds)):
            child = build_arm_spec(
                robot, tool, physics_dt=physics_dt, servo_time_constant=tau, tcp_offset=tcp_offset, gravity=gravity
            )
            parent.attach(child, prefix=f"a{i}/", frame=parent.worldbody.add_frame())
        self.model = m = parent.compile()
        self.data = d = mujoco.MjData(m)
        B, n = len(worlds), w0.n_joints
        if m.nq != B * n or m.nv != B * n or m.nu != B * n:
            raise RuntimeError(f"the group's model has {m.nv} joints, expected {B} × {n}")
        for i, w in enumerate(worlds):
            if m.opt.timestep != w.model.opt.timestep:
                raise RuntimeError("the group's model steps otherwise than its worlds'")
            cols = slice(i * n, (i + 1) * n)
            d.qpos[cols] = w.data.qpos
            d.qvel[cols] = w.data.qvel
            d.ctrl[cols] = w.data.ctrl
        mujoco.mj_forward(m, d)
        tip = get_arm(robot).tip_frame
        for i, w in enumerate(worlds):
            cols = slice(i * n, (i + 1) * n)
            w.model, w.data = m, d
            w._tcp, w._handle, w._ft = (m.site(f"a{i}/{name}").id for name in ("tcp", "handle", "ft_sensor"))
            w._tool_body, w._tool0 = m.body(f"a{i}/tool").id, m.body(f"a{i}/{tip}").id
            w._force_adr = int(m.sensor(f"a{i}/ft_force").adr[0])
            w._torque_adr = int(m.sensor(f"a{i}/ft_torque").adr[0])
            w._ctrl, w._bias_force = d.ctrl[cols], d.qfrc_bias[cols]
            w._qpos, w._qvel = d.qpos[cols], d.qvel[cols]
            w._site_xpos, w._site_xmat, w._xipos = d.site_xpos, d.site_xmat, d.xipos
            w._xfrc_tool = d.xfrc_applied[w._tool_body]
            w._sensordata = d.sensordata
            w._jacp, w._jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            w._dofs = cols
            w._group = self
        self.worlds = worlds
        self.n_substeps, self.h, self.rate = w0.n_substeps, w0.physics_dt, w0.sensor.rate_hz
        self.alpha, self.kd, self.kp = w0._alpha, w0._kd, w0._kp
        self._qpos, self._qvel = d.qpos.reshape(B, n), d.qvel.reshape(B, n)
        self._u = np.zeros(B * n)
        self._steps, self._sample_index = w0._steps, w0._sample_index
        # every member's sensor (MujocoArmWorld._sample) as (B, 6) arrays: where its six readings sit in the
        # group's sensordata, its bias, noise and range
        self._ft_at = np.array(
            [[*range(w._force_adr, w._force_adr + 3), *range(w._torque_adr, w._torque_adr + 3)] for w in worlds]
        )
        self._ft_bias = np.array([w._bias for w in worlds], dtype=float)
        self._tcp_levers = np.array([w.tcp_lever for w in worlds], dtype=float)
        self._ft_sigma = np.array([w._sigma for w in worlds], dtype=float)
        self._ft_range = np.array([w._range for w in worlds], dtype=float)

    @staticmethod
    def key(world: Any) -> tuple | None:
        """What worlds must share to step in one model (their model's spec, their servo, their sensor's rate
        and time), or None for a world that cannot join (another kind, paced to the wall clock, viewed, closed,
        already in a group)."""
        if not isinstance(world, MujocoArmWorld) or world.realtime or world._viewer is not None:
            return None
        if world._closed or world._group is not None:
            return None
        return (
            world._spec_args,  # the model, the servo's lag (its α follows from it and the step)
            world.n_substeps,
            world.servo_bandwidth,  # the servo's gains
            world.sensor.rate_hz,
            world._steps,
            world._sample_index,
        )

    @classmethod
    def form(cls, worlds: Sequence[Any]) -> list[MujocoArmGroup]:
        """The groups of ``worlds`` built alike, two or more each (the others are left as they are)."""
        alike: dict[tuple, list[MujocoArmWorld]] = {}
        for w in worlds:
            k = cls.key(w)
            if k is not None:
                alike.setdefault(k, []).append(w)
        return [cls(members) for members in alike.values() if len(members) > 1]

    def step(self) -> None:
        """One control period of physics for every member (the class docstring)."""
        worlds, n = self.worlds, self.worlds[0].n_joints
        for w in worlds:
            if not w._applied:  # its run ended: hold it where it is
                w._target = [0.0] * n
                w._hand_active = False
                w._xfrc_tool[:] = 0.0
            w._applied = False
        v_ref = np.array([w._v_ref for w in worlds])
        q_ref = np.array([w._q_ref for w in worlds])
        target = np.array([w._target for w in worlds])
        pushed = [w for w in worlds if w._hand_active]
        if pushed:  # MujocoArmWorld._set_hand on every pushed arm: the hand's wrench moved to the tool's COM
            handles = np.array([w._handle for w in pushed])
            tools = np.array([w._tool_body for w in pushed])
            fx, fy, fz, tx, ty, tz = np.array([w._hand_list for w in pushed]).T
            at_com = np.empty((len(pushed), 6))
            at_com[:, 0], at_com[:, 1], at_com[:, 2] = fx, fy, fz
        m, d = self.model, self.data
        u = self._u.reshape(v_ref.shape)
        for _ in range(self.n_substeps):
            if pushed:
                rx, ry, rz = (d.site_xpos[handles] - d.xipos[tools]).T
                at_com[:, 3] = tx + ry * fz - rz * fy  # r × f, in the world's order of operations
                at_com[:, 4] = ty + rz * fx - rx * fz
                at_com[:, 5] = tz + rx * fy - ry * fx
                d.xfrc_applied[tools] = at_com
            # MujocoArmWorld._set_servo on every arm: u = dv/h + kd (v − q̇) + kp (q_ref − q), in its order
            dv = self.alpha * (target - v_ref)
            np.divide(dv, self.h, out=u)
            u += self.kd * (v_ref - self._qvel)
            u += self.kp * (q_ref - self._qpos)
            v_ref += dv
            q_ref += self.h * v_ref
            mujoco.mj_mulM(m, d, d.ctrl, self._u)
            d.ctrl += d.qfrc_bias
            mujoco.mj_step2(m, d)
            mujoco.mj_step1(m, d)
            if d.nefc:
                raise ConstraintInGroup(
                    f"{d.nefc} constraint rows active in a group of {len(worlds)} MuJoCo arms (a joint at its limit)"
                )
            self._steps += 1
            if self.rate is not None:
                idx = _sample_number(self._steps, self.h, self.rate)
                if idx != self._sample_index:
                    self._sample_index = idx
                    self._sample()
        if self.rate is None:
            self._sample()
        # (nothing in the substeps reads a member's clock or sample count: they are set once, here)
        for w, v, q in zip(worlds, v_ref.tolist(), q_ref.tolist()):
            w._v_ref, w._q_ref = v, q
            w._steps = self._steps
            if self.rate is not None:
                w._sample_index = self._sample_index

    def _sample(self) -> None:
        """A new sensor sample for every member: :meth:`MujocoArmWorld._sample` on (B, 6) arrays, elementwise
        in its order, each member's noise from its own generator (its six draws, as its own sample draws them)."""
        raw = self.data.sensordata[self._ft_at]
        raw *= _MUJOCO_TO_COASSIST
        raw += self._ft_bias
        noise = np.empty_like(raw)
        for w, row in zip(self.worlds, noise):
            w._rng.standard_normal(out=row)
        noise *= self._ft_sigma
        raw += noise
        raw[:, 3:] -= np.cross(self._tcp_levers, raw[:, :3])  # each member's torque about its TCP
        np.minimum(raw, self._ft_range, out=raw)
        np.maximum(raw, -self._ft_range, out=raw)
        for w, row in zip(self.worlds, raw):
            w._wrench = row
            w.wrench_seq += 1


class MujocoUR5World(MujocoArmWorld):
    """The MuJoCo UR5 world: :class:`MujocoArmWorld` with its default ``robot="ur5"``
    (the name the UR5 code, the live monitor and the fault tests use)."""


def build_world(request: WorldRequest) -> MujocoArmWorld:
    """The ``mujoco`` world of :data:`coassist.robot.worlds.WORLDS`: ``request.robot`` in MuJoCo with
    the TCP at ``request.start``, paced to the wall clock when ``request.realtime``."""
    return (MujocoUR5World if request.robot == "ur5" else MujocoArmWorld)(
        request.object,
        robot=request.robot,
        control_dt=1.0 / request.rate_hz,
        start=request.start,
        seed=request.seed,
        view=request.view,
        realtime=request.realtime,
    )
