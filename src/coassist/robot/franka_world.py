"""A Franka Panda (or FR3) as a :class:`~coassist.runtime.world.World`, through franky.

franky (``franky-control``) talks libfranka's network protocol to the arm's controller
(FCI). This world sends each tick's joint velocity as a franky ``JointVelocityMotion``,
asynchronously: a new motion replaces the running one, and franky's trajectory
generator (Ruckig) ramps to it within the robot's dynamics limits.

**Tested against franky-sim 1.0.4** (a simulator that speaks the same protocol, MuJoCo
behind it) on loopback, with the real franky 2.0.0 client
(``tests/robot/test_franka_world.py``). **Never run on a real arm.** Untried on
hardware: the sign and frame of ``O_F_ext_hat_K`` (below), the timing of the 1 kHz link
under load, the reflex thresholds, and recovery after a reflex.

The loop
--------
``read()`` takes ``robot.state`` (libfranka's last 1 kHz state); ``apply()`` sends the
motion and then waits until the *robot's* clock (``state.time``, 1 ms steps) has moved
on by dt from the state read: the robot paces the loop, so a simulator running slower
than real time slows it too and the admittance stays in the robot's time. Each motion's ``duration``
(``hold_ms``, default 50 ms) is how long the robot keeps the velocity after reaching it
when no newer motion comes: if this process hangs, the arm brakes to rest on its own.
A stalled loop (a garbage collection, a swapped-out page, a monitor that blocked) shows on
the robot's clock: when two reads with a command between them lie more than
dt + max(dt/2, 2 ms) apart, :attr:`FrankaWorld.last_overrun` says by how much and the loop
flags that tick DEADLINE_MISS; the safety layer then ramps from the joint velocity the arm
measures (it may have braked to rest meanwhile), not from its own last command.

The wrench
----------
Without an external sensor, the wrench is libfranka's estimate ``O_F_ext_hat_K``: the
external wrench acting on the stiffness frame K, in base-frame axes, from the joint
torque sensors. libfranka's sign is the robot's ("forces applied by the robot to the
environment are positive, while forces applied by the environment on the robot are
negative", franky's and libfranka's documentation of the field): its negative is the wrench
the environment (the hand) applies, so a hand pushing the tool along +x_base reads +f_x,
coassist's sign (:mod:`coassist.runtime.world`), with ``sensor_rotation`` = I. (Taken
unnegated, the arm moved against the push, into the person.) An external F/T sensor is any object with
``read() -> (wrench (6,), sensor_rotation (3, 3), seq)`` in coassist's convention
(``ft_sensor=``). franky-sim 1.0.4 reports ``O_F_ext_hat_K`` = 0 always, so the tests
use the sensor path.

Stops
-----
A reflex (the robot's own force or speed limits) or a user stop makes franky raise
``franky.ControlException`` on the next motion: the world reports
``RobotState.protective_stop`` (``emergency_stop`` for the user stop button), keeps no
motion running, and :attr:`FrankaWorld.stop_detail` says what happened and what to do
next. A lost link (a ``franky.NetworkException``, or no new robot state for
``link_timeout`` s) raises :class:`FrankaLinkError`, a ``ConnectionError``: the loop
ends with ``"link_lost"``. An external F/T sensor whose ``read()`` raises (a read
timeout) gives a NaN wrench for that tick (``sensor_errors`` counts them): the tick flags
NONFINITE_WRENCH and brakes, and the safety layer stops the arm if it lasts; any other
exception of the world ends the run in a controlled stop with its trial kept
(:mod:`coassist.runtime.loop`).
"""

from __future__ import annotations

import logging
import math
import re
import time
from typing import Any

import numpy as np

from coassist._checks import is_integer, is_real_number
from coassist.robot.arms import NullSpacePosture, arm_kinematics, check_model_matches, get_arm
from coassist.robot.worlds import WORLDS, WorldRequest
from coassist.runtime.world import MAX_LINK_TIMEOUT, Command, RobotLinkError, RobotState
from coassist.spatial import rotation_vector

__all__ = ["FRANKA_ARMS", "FrankaLinkError", "FrankaWorld", "build_world", "pose_from_franka", "reported_arm"]

#: The registered arms (coassist.robot.arms.ARMS) a FrankaWorld drives.
FRANKA_ARMS = WORLDS["franka"].arms  # the arms its registry entry names

log = logging.getLogger(__name__)

_INSTALL_HINT = "the Franka world needs franky: pip install 'coassist[franka]'"

#: What to do after the robot stopped with a reflex (libfranka's error list goes first).
REFLEX_NEXT = (
    "check the workspace and the person, then clear the error (Franka Desk, or franky's "
    "robot.recover_from_errors()) and rerun"
)
USER_STOP_NEXT = "release the user stop button, make the workspace safe, unlock the joints in Desk, then rerun"


#: [s] the least a period may run over before :attr:`FrankaWorld.last_overrun` reports it (the robot's
#: clock ticks in whole ms; a loop on time reads it exactly dt apart on franky-sim, 249 of 249 periods).
OVERRUN_TOLERANCE_MIN = 0.002


class FrankaLinkError(RobotLinkError):
    """The link to the Franka controller failed (a :class:`~coassist.runtime.world.RobotLinkError`:
    the loop ends with ``link_lost``)."""


def pose_from_franka(T: Any) -> np.ndarray:
    """(6,) ``[x, y, z, rx, ry, rz]`` of a transform: franky's ``Affine`` (``.matrix``, 4 × 4) or a 4 × 4 array.
    A rotation with a non-finite entry gives a NaN orientation (a glitched state: the tick flags it and brakes;
    it was a ValueError out of the world's read, which ended the run)."""
    M = np.asarray(getattr(T, "matrix", T), dtype=float)
    if M.shape != (4, 4):
        raise ValueError(f"a transform is a 4 x 4 matrix, got shape {M.shape}")
    rv = rotation_vector(M[:3, :3]) if np.isfinite(M[:3, :3]).all() else np.full(3, np.nan)
    return np.concatenate((M[:3, 3], rv))


def reported_arm(robot: Any) -> tuple[str, str] | None:
    """(arm, name): which of :data:`FRANKA_ARMS` the connected robot says it is, from the robot
    name of the model URDF it serves (franky's ``Robot.model_urdf``, libfranka's
    ``getRobotModel``: ``<robot name="fr3">``; a Panda's is ``panda`` or ``fer``), or None
    when the robot serves none (older system images): then only the start-up joint-range
    check tells the arms apart. A name that is neither raises ValueError."""
    try:
        urdf = robot.model_urdf
    except Exception:  # noqa: BLE001 - not served (older firmware), or not a franky.Robot
        return None
    if not isinstance(urdf, str):
        return None
    m = re.search(r"<robot\b[^>]*\bname\s*=\s*[\"']([^\"']*)[\"']", urdf)
    if m is None:
        return None
    name = m.group(1)
    low = name.lower()
    if "fr3" in low:
        return "fr3", name
    if "panda" in low or low == "fer" or low.startswith("fer_"):
        return "panda", name
    raise ValueError(
        f"the connected Franka reports the model {name!r}, which is neither a Panda nor an FR3 "
        f"({', '.join(FRANKA_ARMS)}); coassist has no kinematics for it"
    )


def _franky():
    try:
        import franky
    except ImportError as exc:
        raise ImportError(f"{_INSTALL_HINT} ({exc})") from exc
    return franky


class FrankaWorld:
    """A Franka arm through franky (module docstring).

    host : the robot's FCI address.  frequency : the control rate [Hz] (≤ 1000).
    robot : a connected ``franky.Robot`` (None: ``franky.Robot(host)``).
    arm : the registered arm, ``"panda"`` or ``"fr3"`` (the same kinematics, each its own
        joint limits: :data:`coassist.robot.arms.ARMS`); the start posture must lie inside
        its joint range, and every command is clipped to its joint speeds.
    ft_sensor : an external F/T sensor (module docstring); None: ``O_F_ext_hat_K``.
    hold_ms : each motion's hold time [ms] (the hang watchdog).
    last_overrun : [s] how far the robot's clock ran past dt between the last two reads
        (0.0 on time; module docstring).
    link_timeout : [s] without a new robot state before the link counts as lost.
    posture_gain : k_n [1/s] of the null-space posture (arms.NullSpacePosture).
    """

    command_space = "joint_velocity"
    realtime = True

    def __init__(
        self,
        host: str,
        *,
        frequency: float = 125.0,
        robot: Any = None,
        arm: str = "panda",
        ft_sensor: Any = None,
        hold_ms: int = 50,
        link_timeout: float = 0.1,
        posture_gain: float = 1.0,
    ) -> None:
        if not isinstance(host, str) or not host:
            raise ValueError(f"host must be the robot's FCI address, got {host!r}")
        if not is_real_number(frequency) or not 0.0 < frequency <= 1000.0:
            raise ValueError(f"frequency must be in (0, 1000] Hz, got {frequency!r}")
        if not is_integer(hold_ms) or not 1 <= hold_ms <= 1000:
            raise ValueError(f"hold_ms must be an int in [1, 1000] ms, got {hold_ms!r}")
        if not is_real_number(link_timeout) or not 0 < link_timeout <= MAX_LINK_TIMEOUT:
            raise ValueError(
                f"link_timeout must be a number of seconds in (0, {MAX_LINK_TIMEOUT:g}] (a stopped robot clock "
                f"is a lost link), got {link_timeout!r}"
            )
        if not is_real_number(posture_gain) or not math.isfinite(posture_gain) or posture_gain < 0:
            raise ValueError(f"posture_gain must be a finite number >= 0 (1/s), got {posture_gain!r}")
        if arm not in FRANKA_ARMS:
            raise ValueError(f"arm must be one of {FRANKA_ARMS}, got {arm!r}")
        if ft_sensor is not None and not callable(getattr(ft_sensor, "read", None)):
            raise ValueError("ft_sensor must have a read() -> (wrench, sensor_rotation, seq) method")
        self._fr = _franky()
        self.host, self.dt = host, 1.0 / float(frequency)
        self.arm = get_arm(arm)
        self.n_joints = self.arm.n_joints
        self.ft_sensor, self.hold_ms, self.link_timeout = ft_sensor, hold_ms, float(link_timeout)
        self.stop_detail: str | None = None
        self.commands_sent = 0
        self.sensor_errors = 0
        self.last_sensor_error: str | None = None
        self._closed = False
        self._moving = False
        self._seq = 0
        self._sensor_seq = 0
        self.last_overrun = 0.0
        self._overrun_tolerance = max(0.5 * self.dt, OVERRUN_TOLERANCE_MIN)
        self._applied = False
        self._read_t = 0.0
        self._last_t = -math.inf
        self._last_new = time.monotonic()
        if robot is None:
            try:  # never bound to a local: a refused robot must not outlive this call in a traceback's frame
                self.robot = self._fr.Robot(host, realtime_config=self._fr.RealtimeConfig.Ignore)
            except Exception as exc:  # franky.NetworkException, IncompatibleVersionException
                raise FrankaLinkError(
                    f"could not connect to the Franka at {host}: {exc}; check the address, "
                    "that FCI is activated in Desk and the joints are unlocked"
                ) from exc
        else:
            self.robot = robot
        try:
            self._check_arm(host, arm, posture_gain)
        except BaseException:
            # franky's Robot holds the FCI connection (one client at a time) until it is collected
            self.robot = None
            raise

    def _check_arm(self, host: str, arm: str, posture_gain: float) -> None:
        """At connect: the arm the robot reports is ``arm``, the model's TCP is where the robot
        says, and the joints lie inside the arm's range (module docstring)."""
        reported = reported_arm(self.robot)
        if reported is not None and reported[0] != arm:
            model, name = reported
            label = {"fr3": "Franka Research 3", "panda": "Panda"}[model]
            raise ValueError(
                f"the Franka at {host} is a {label} (the model it reports is {name!r}), not a {arm}: "
                f"pass --robot {model}"
            )
        state = self._state()
        # the TCP is libfranka's end effector: flange -> EE as set in Desk (F_T_EE)
        F_T_EE = pose_from_franka(state.F_T_EE)
        self._kin = arm_kinematics(self.arm.name, F_T_EE)
        q0 = np.asarray(state.q, dtype=float)
        check_model_matches(self._kin, q0, pose_from_franka(state.O_T_EE), what=f"the Franka at {host}")
        lim = self._kin.joint_position_limit
        outside = np.flatnonzero((q0 < lim[:, 0]) | (q0 > lim[:, 1]))
        if outside.size:  # an FR3 told it is a Panda, or the other way round
            i = int(outside[0])
            raise ValueError(
                f"the Franka at {host} has joint {i + 1} at {q0[i]:.4f} rad, outside the {self.arm.name}'s "
                f"range [{lim[i, 0]}, {lim[i, 1]}]; is --robot the arm it is ({', '.join(FRANKA_ARMS)})?"
            )
        self._vmax = np.array(self.arm.joint_velocity_limit, dtype=float)
        self.tcp_offset_pose = F_T_EE
        self.posture_gain = posture_gain
        self._q0 = q0.copy()

    # ------------------------------------------------------------------ kinematics
    def kinematics(self) -> NullSpacePosture:
        """The arm's kinematics with the start posture held in the null space (eq. 3.6, 7 joints)."""
        return NullSpacePosture(self._kin, self._q0, gain=self.posture_gain)

    def tool_mass_and_com(self) -> tuple[float, np.ndarray]:
        """(0.0, zeros): no payload is removed here (libfranka's estimate already leaves out the
        load configured in Desk; an external sensor is zeroed with the tool on it)."""
        return 0.0, np.zeros(3)

    @property
    def noise_free_sensor(self) -> bool:
        """An external sensor that declares no noise (``noise_force`` and ``noise_torque`` both 0, a
        test's simulated one): its reading repeats exactly on a constant push."""
        sensor = self.ft_sensor
        return sensor is not None and not (getattr(sensor, "noise_force", 1.0) or getattr(sensor, "noise_torque", 1.0))

    # ------------------------------------------------------------------ World
    def _state(self) -> Any:
        try:
            return self.robot.state
        except Exception as exc:  # franky.NetworkException and friends
            raise FrankaLinkError(f"reading the Franka's state failed: {exc}") from exc

    def read(self) -> RobotState:
        """The robot's latest state (module docstring); FrankaLinkError when it stopped coming."""
        if self._closed:
            raise FrankaLinkError(f"read on a closed FrankaWorld ({self.host}); build a new one")
        s = self._state()
        t = float(s.time.to_sec())
        now = time.monotonic()
        advanced = t > self._last_t
        if advanced:
            self._last_t, self._last_new = t, now
        elif now - self._last_new > self.link_timeout:
            raise FrankaLinkError(f"no new state from the Franka at {self.host} for {now - self._last_new:.3f} s")
        else:  # a repeated or earlier robot clock: the state's time still only goes forward (the loop's protocol)
            # 1 µs on, or one ulp where the clock is so large that 1 µs rounds away
            t = max(self._last_t + 1e-6, math.nextafter(self._last_t, math.inf)) if math.isfinite(self._last_t) else t
            self._last_t = t
        if self._applied:  # the robot's clock since the last read: a stalled loop shows here, wherever it stalled
            excess = t - self._read_t - self.dt
            self.last_overrun = excess if excess > self._overrun_tolerance else 0.0
            self._applied = False
        self._read_t = t
        q = np.asarray(s.q, dtype=float)
        qd = np.asarray(s.dq, dtype=float)
        pose = pose_from_franka(s.O_T_EE)
        try:
            J = self._kin.jacobian(q)
            twist = J @ qd
        except ValueError:  # a non-finite q: the tick flags it and brakes
            twist = np.full(6, np.nan)
        if self.ft_sensor is None:
            # libfranka's sign is the robot's on the environment: the hand's is its negative (module docstring)
            wrench, R = -np.asarray(s.O_F_ext_hat_K, dtype=float), np.eye(3)
            if advanced:  # a new sample only with a new state: a stuck robot's wrench reads as stale
                self._seq += 1
            seq = self._seq
        else:
            wrench, R, seq = self._read_sensor()
        mode = s.robot_mode
        user_stop = mode == self._fr.RobotMode.UserStopped
        errors = s.current_errors
        # franky's Errors: 41 flags, libfranka's error list (a reflex sets one; its bool is always True)
        reflex = (
            mode == self._fr.RobotMode.Reflex
            or any(errors.__getstate__())
            or (self.stop_detail is not None and not user_stop)
        )
        if reflex and self.stop_detail is None:
            self.stop_detail = f"the Franka stopped with a reflex ({errors!r}): {REFLEX_NEXT}"
        if user_stop and self.stop_detail is None:
            self.stop_detail = f"the Franka's user stop is pressed: {USER_STOP_NEXT}"
        return RobotState(
            t=t,
            q=q,
            qd=qd,
            tool_pose=pose,
            tool_twist=twist,
            wrench=wrench,
            sensor_rotation=R,
            wrench_seq=int(seq),
            protective_stop=bool(reflex),
            emergency_stop=bool(user_stop),
        )

    def _read_sensor(self) -> tuple[np.ndarray, np.ndarray, int]:
        """The external F/T sensor's (wrench, R, seq); a sensor that raises (a read timeout, a
        dropped socket) or answers garbage gives a NaN wrench for this tick: the tick flags it and
        brakes, and the safety layer stops the arm if it lasts (``sensor_errors`` counts them)."""
        try:
            wrench, R, seq = self.ft_sensor.read()
            # copies of our own: the tick may flag them in place
            out = np.array(wrench, dtype=float), np.array(R, dtype=float), int(seq)
            self._sensor_seq = out[2]
            return out
        except Exception as exc:  # noqa: BLE001 - whatever the driver raises, the loop goes on safely
            self.sensor_errors += 1
            self.last_sensor_error = f"{type(exc).__name__}: {exc}"
            if self.sensor_errors == 1 or self.sensor_errors % 1000 == 0:
                log.warning(
                    "the F/T sensor's read() failed (%s; %d so far): NaN wrench, the arm brakes",
                    self.last_sensor_error,
                    self.sensor_errors,
                )
            return np.full(6, np.nan), np.eye(3), self._sensor_seq

    def apply(self, command: Command) -> None:
        """Send the command's joint velocity as a franky motion, then wait for the period's end."""
        if self._closed:
            raise FrankaLinkError(f"apply on a closed FrankaWorld ({self.host}); build a new one")
        self.last_overrun = 0.0  # reported by read() for the tick it returns (the loop checks it there)
        self._applied = True
        qd = None if command.qd is None else np.asarray(command.qd, dtype=float)
        if (
            command.stop
            or self.stop_detail is not None
            or qd is None
            or qd.shape != (self.n_joints,)
            or not np.isfinite(qd).all()
        ):
            self._send(np.zeros(self.n_joints))
        else:  # the arm's own speeds: a last guard (the safety layer's limits are lower by default)
            self._send(np.clip(qd, -self._vmax, self._vmax))
        self._wait_period()

    def _wait_period(self) -> None:
        """Sleep until the robot's clock has advanced by dt since the last read (its 1 kHz
        clock paces the loop, so a simulator slower than real time slows the loop with it)."""
        target = self._last_t + self.dt - 5e-4  # the robot's clock ticks in whole ms
        give_up = time.monotonic() + self.dt + self.link_timeout
        while True:
            t = float(self._state().time.to_sec())
            if t >= target:
                return
            now = time.monotonic()
            if now > give_up:
                raise FrankaLinkError(f"the Franka at {self.host} sent no new state for {now - self._last_new:.3f} s")
            time.sleep(min(5e-4, max(target - t, 0.0)))

    def _send(self, qd: np.ndarray) -> None:
        if self.stop_detail is not None and not self._moving:
            return  # stopped by the robot: nothing is sent until a person recovers it
        fr = self._fr
        motion = fr.JointVelocityMotion(qd, duration=fr.Duration(self.hold_ms))
        try:
            self.robot.move(motion, asynchronous=True)
            self.commands_sent += 1
            self._moving = bool(np.any(qd != 0.0))
        except fr.ControlException as exc:  # a reflex: the motion before this one failed
            self._moving = False
            self.stop_detail = f"the Franka stopped with a reflex ({exc}): {REFLEX_NEXT}"
        except fr.NetworkException as exc:
            self._moving = False
            raise FrankaLinkError(f"the link to the Franka at {self.host} dropped: {exc}") from exc

    def stop(self) -> None:
        """Bring the arm to rest (a zero-velocity motion, ramped by franky) and wait for it; safe twice."""
        if self._closed:
            return
        try:
            if self._moving:
                self.robot.move(
                    self._fr.JointVelocityMotion(np.zeros(self.n_joints), duration=self._fr.Duration(10)),
                    asynchronous=True,
                )
            self.robot.join_motion(2.0)
        except Exception:  # noqa: BLE001 - a reflex or a dead link: the robot brakes on its own
            pass
        self._moving = False

    def close(self) -> None:
        """Stop, then drop the reference to the robot (franky disconnects when it is collected)."""
        if self._closed:
            return
        self.stop()
        self._closed = True
        # franky's Robot holds the FCI connection until it is collected (one client at a time)
        self.robot = None


def build_world(request: WorldRequest) -> FrankaWorld:
    """The ``franka`` world of :data:`coassist.robot.worlds.WORLDS`: the ``request.robot`` at ``request.host``, at the run's rate."""
    return FrankaWorld(request.host or "", frequency=float(request.rate_hz), arm=request.robot)  # "": named as missing
