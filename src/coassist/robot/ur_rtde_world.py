"""A real UR arm as a :class:`~coassist.runtime.world.World`, through ur-rtde (``speedJ``).

**Nothing in this module has been run against a robot or URSim.** It is written from
the ur-rtde 1.6.5 Python bindings' signatures and docstrings and tested against a fake
(``tests/robot/fake_rtde.py``). Untried on hardware: the call order on a live
controller, the timing of ``initPeriod``/``waitPeriod`` under load, what the watchdog
does when it fires, the sign and frame of ``getActualTCPForce`` (below), the
``getStepTime`` rate detection (``frequency=-1``), and ``close()`` after a protective stop. Try it first in
URSim, then on the arm at low speed with a hand on the emergency stop.

The loop pattern
----------------
ur-rtde's real-time pattern is one period per control tick::

    t0 = rtde_c.initPeriod()          # start of the period (steady clock)
    ... read, compute ...
    rtde_c.speedJ(qd, acceleration, dt)
    rtde_c.kickWatchdog()
    rtde_c.waitPeriod(t0)             # sleep until t0 + dt

The World protocol splits a tick into ``read()`` then ``apply()``, so the period is
opened by the first ``read()`` and then at the end of every ``apply()`` (right after
``waitPeriod``): the loop's computation between ``read`` and ``apply`` falls inside the
period, as in the pattern above, and the tick rate is 1/dt, not 1/(dt + compute). The
control interface therefore sees ``initPeriod, speedJ, kickWatchdog, waitPeriod``
repeating. ``apply`` measures the whole period with the wall clock; when it lasted
longer than ``dt·(1 + overrun_tolerance)``, :attr:`URRTDEWorld.last_overrun` holds the
excess [s] (else 0.0) and the loop flags ``Fault.DEADLINE_MISS``.

Why ``speedJ`` and not ``servoJ``
---------------------------------
The controller's output is a joint velocity (``command_space = "joint_velocity"``).
``speedJ`` takes it directly and ramps to it with a bounded acceleration. ``servoJ``
takes a position and tracks it through a lookahead filter (``lookahead_time`` ≥ 0.03 s
plus gain), which adds about 34 ms of lag to the human-robot loop: the person feels it
as extra inertia, and it erodes the stability margin of the admittance loop.
``acceleration`` (default 1.4 rad/s², leading axis) bounds how fast the arm follows a
change of command; the safety layer limits it too.

Watchdog
--------
``setWatchdog(watchdog_hz)`` is armed once, at the first ``apply()`` (not at connect:
any pause between building the world and starting the loop would trip it), and every
``apply()`` kicks it. If the loop hangs for longer than ``1/watchdog_hz`` (0.1 s at the
default 10 Hz), ur-rtde's control script stops the robot ("shutdown the control", per
its docstring); later commands then fail and ``apply`` raises :class:`RobotLinkError`.
Between runs, close the world, or keep applying ``Command(stop=True)`` (which holds the
arm and kicks the watchdog).

Force zeroing and the wrench
----------------------------
At connect (``zero_sensor=True``) the world calls ``zeroFtSensor()``, which subtracts
the current reading from every later one. Do it with **the tool still and nobody
touching it or the object**: whatever force is there at that moment is taken as zero
for the whole run. The reading is ``getActualTCPForce()``: the external wrench at the
TCP — force in the base frame's axes, torque about the TCP — measured by the tool
flange's sensor on an e-Series and estimated from the joint currents on a CB3 (noisier,
a few N). The controller compensates it for the payload set with ``setPayload``. UR's
script manual describes it as the external wrench on the tool, so a hand pushing the
tool along +x_base reads +f_x: the sign of coassist's convention (runtime.world).
``read()`` rotates it into the TCP frame (the "sensor" frame here):
``f_tcp = Rᵀ f_base``, ``τ_tcp = Rᵀ τ_base`` with ``R`` the TCP orientation, and reports
``R`` as ``sensor_rotation``. This sign reading of UR's docs is unchecked on an arm:
push the tool by hand along +x_base once and check that ``Rᵀ``-rotated back the reading
is positive.

Link loss
---------
A reading that raises, an interface that reports it is disconnected, or a robot
timestamp that has not advanced for ``link_timeout`` seconds (ur-rtde's receive thread
keeps serving its last sample after the link drops) makes ``read()`` raise
:class:`~coassist.runtime.world.RobotLinkError` (a ``ConnectionError``); the loop turns it into a stop.
Protective and emergency stops are not errors: ``read()`` reports them in
:class:`~coassist.runtime.world.RobotState` and :func:`stop_message` says what to do.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from coassist.robot.worlds import WorldRequest
from coassist.runtime.world import Command, RobotLinkError, RobotState
from coassist.spatial import rotation_matrix

__all__ = ["SafetyStatus", "URRTDEWorld", "build_world", "stop_message"]

log = logging.getLogger(__name__)

#: With ``frequency=-1``, a controller step time slower than this rate is not believed.
_MIN_AUTO_FREQUENCY = 100.0
#: The RTDE interface runs at most at the e-Series controller rate.
_MAX_FREQUENCY = 500.0
_INSTALL_HINT = "the real robot needs ur-rtde: pip install 'coassist[robot]'"


class SafetyStatus:
    """Bits of ``getSafetyStatusBits()`` (ur-rtde docstring order, bits 0–10)."""

    NORMAL = 1 << 0
    REDUCED = 1 << 1
    PROTECTIVE_STOPPED = 1 << 2
    RECOVERY = 1 << 3
    SAFEGUARD_STOPPED = 1 << 4
    SYSTEM_EMERGENCY_STOPPED = 1 << 5
    ROBOT_EMERGENCY_STOPPED = 1 << 6
    EMERGENCY_STOPPED = 1 << 7
    VIOLATION = 1 << 8
    FAULT = 1 << 9
    STOPPED_DUE_TO_SAFETY = 1 << 10

    #: Reported as ``RobotState.protective_stop``: the safety system halted the arm and a
    #: person must clear it (a protective or safeguard stop, a violation or a fault).
    PROTECTIVE = PROTECTIVE_STOPPED | SAFEGUARD_STOPPED | VIOLATION | FAULT | STOPPED_DUE_TO_SAFETY
    #: Reported as ``RobotState.emergency_stop``.
    EMERGENCY = SYSTEM_EMERGENCY_STOPPED | ROBOT_EMERGENCY_STOPPED | EMERGENCY_STOPPED


def stop_message(state: RobotState, safety_status_bits: int | None = None) -> str | None:
    """What stopped the robot and what to do next, or None when it is not stopped.

    ``safety_status_bits`` (:attr:`URRTDEWorld.safety_status_bits`) refines the message
    (safeguard stop, violation, fault); without it the two flags of ``state`` decide.
    """
    bits = int(safety_status_bits or 0)
    if state.emergency_stop or bits & SafetyStatus.EMERGENCY:
        return (
            "Emergency stop: the robot's emergency stop circuit is open (a pressed button or "
            "the external e-stop input). Make the workspace safe, release the button, reset "
            "the robot on the teach pendant (power on, release the brakes), then rerun."
        )
    if bits & (SafetyStatus.VIOLATION | SafetyStatus.FAULT):
        return (
            "Safety fault: the robot's safety system reports a violation or a fault and has "
            "stopped the arm. Read the error on the teach pendant, restart the safety system "
            "there (or with the dashboard's restartSafety), power on, then rerun."
        )
    if bits & SafetyStatus.SAFEGUARD_STOPPED:
        return (
            "Safeguard stop: the safeguard stop input is active (a light curtain, a door or a "
            "safety mat). Clear the safeguarded area, reset the safeguard, then rerun."
        )
    if state.protective_stop or bits & SafetyStatus.PROTECTIVE:
        return (
            "Protective stop: the robot's safety system stopped the arm (a force or speed "
            "limit, or a collision). Check the workspace and the person, clear the stop on "
            "the teach pendant (or with the dashboard's unlockProtectiveStop, at least 5 s "
            "after it happened), then rerun."
        )
    return None


def _check_number(value: Any, name: str, *, positive: bool = True, allow_zero: bool = False) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(out) or (positive and (out < 0.0 or (out == 0.0 and not allow_zero))):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return out


def _check_vector(value: Any, name: str, n: int) -> list[float]:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {n} numbers, got {value!r}") from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be {n} finite numbers, got {value!r}")
    return [float(v) for v in arr]


def _default_control_factory(host: str, frequency: float) -> Any:
    try:
        import rtde_control
    except ImportError as exc:
        raise ImportError(f"{_INSTALL_HINT} ({exc})") from exc
    return rtde_control.RTDEControlInterface(host, frequency)


def _default_receive_factory(host: str, frequency: float) -> Any:
    try:
        import rtde_receive
    except ImportError as exc:
        raise ImportError(f"{_INSTALL_HINT} ({exc})") from exc
    return rtde_receive.RTDEReceiveInterface(host, frequency)


class URRTDEWorld:
    """A UR arm driven by joint velocity through ur-rtde (module docstring).

    Parameters
    ----------
    host : the robot's IP address or host name.
    frequency : RTDE rate [Hz], at most 500; -1 lets ur-rtde pick (125 Hz on a CB3,
        500 Hz on an e-Series), and ``dt`` is then the controller's ``getStepTime()``
        (RobotLinkError if that cannot be read: pass the rate then).
    acceleration : ``speedJ`` acceleration of the leading joint [rad/s²].
    deceleration : ``speedStop`` deceleration [rad/s²] for ``stop()``, ``Command(stop=True)``
        and rejected commands.
    watchdog_hz : minimum kick rate [Hz] of the controller-side watchdog; None disables
        it (not recommended).
    tcp_offset : TCP pose in the flange frame ``[x, y, z, rx, ry, rz]`` sent with
        ``setTcp``; None keeps the controller's.
    payload : ``(mass [kg], cog [m, 3])`` sent with ``setPayload``; None keeps the
        controller's.
    zero_sensor : call ``zeroFtSensor()`` at connect (tool still, nobody touching it).
    link_timeout : [s] a robot timestamp that does not advance for this long is a lost link.
    overrun_tolerance : fraction of ``dt`` a period may run over before ``last_overrun``
        reports it (absorbs scheduler jitter).
    control_factory, receive_factory : ``(host, frequency) -> interface``; default the
        real ``rtde_control.RTDEControlInterface`` / ``rtde_receive.RTDEReceiveInterface``.

    Attributes
    ----------
    dt, command_space, n_joints, realtime : the World protocol.
    last_overrun : [s] how far the last period ran over ``dt`` (0.0 when on time).
    last_period : [s] the last period's measured length.
    safety_status_bits : the last ``getSafetyStatusBits()`` (see :class:`SafetyStatus`).
    rejected_commands : commands replaced by ``speedStop`` (non-finite or wrong shape).
    """

    dt: float  # set at connect
    command_space = "joint_velocity"
    n_joints = 6
    realtime = True
    noise_free_sensor = False  # a real sensor: the frozen-sensor check stays on

    def __init__(
        self,
        host: str,
        *,
        frequency: float = -1.0,
        acceleration: float = 1.4,
        deceleration: float = 4.0,
        watchdog_hz: float | None = 10.0,
        tcp_offset: Sequence[float] | None = None,
        payload: tuple[float, Sequence[float]] | None = None,
        zero_sensor: bool = True,
        link_timeout: float = 0.1,
        overrun_tolerance: float = 0.1,
        control_factory: Callable[[str, float], Any] | None = None,
        receive_factory: Callable[[str, float], Any] | None = None,
    ) -> None:
        if not isinstance(host, str) or not host.strip():
            raise ValueError(f"host must be the robot's IP address or host name, got {host!r}")
        frequency = _check_number(frequency, "frequency", positive=False)
        if frequency != -1.0 and not 0.0 < frequency <= _MAX_FREQUENCY:
            raise ValueError(
                f"frequency must be -1 (let ur-rtde choose) or in (0, {_MAX_FREQUENCY:g}] Hz, got {frequency!r}"
            )
        self.acceleration = _check_number(acceleration, "acceleration")
        self.deceleration = _check_number(deceleration, "deceleration")
        self.watchdog_hz = None if watchdog_hz is None else _check_number(watchdog_hz, "watchdog_hz")
        self.tcp_offset = None if tcp_offset is None else _check_vector(tcp_offset, "tcp_offset", 6)
        if payload is None:
            self.payload = None
        else:
            try:
                mass, cog = payload
            except (TypeError, ValueError):
                raise ValueError(f"payload must be (mass, cog), got {payload!r}") from None
            self.payload = (_check_number(mass, "payload mass", allow_zero=True), _check_vector(cog, "payload cog", 3))
        self.link_timeout = _check_number(link_timeout, "link_timeout")
        self.overrun_tolerance = _check_number(overrun_tolerance, "overrun_tolerance", allow_zero=True)
        self.zero_sensor = bool(zero_sensor)
        if self.watchdog_hz is None:
            log.warning("URRTDEWorld: watchdog disabled; a hung loop leaves the last speedJ running")

        self.host = host
        self.requested_frequency = frequency
        self.last_overrun = 0.0
        self.last_period = 0.0
        self.safety_status_bits = 0
        self.rejected_commands = 0
        self.step_time: float | None = None

        self._rtde_c: Any = None
        self._rtde_r: Any = None
        self._closed = False
        self._watchdog_armed = False
        self._t0: Any = None  # what initPeriod returned for the open period
        self._t0_wall = 0.0
        self._last_ts: float | None = None
        self._last_t = -math.inf
        self._last_force: np.ndarray | None = None
        self._last_advance_wall = time.monotonic()
        self._wrench_seq = 0

        control_factory = control_factory or _default_control_factory
        receive_factory = receive_factory or _default_receive_factory
        try:
            self._connect(control_factory, receive_factory)
        except BaseException:
            self.close()
            raise

    # -- connect ---------------------------------------------------------------------

    def _connect(self, control_factory: Callable, receive_factory: Callable) -> None:
        host, freq = self.host, self.requested_frequency
        hint = (
            "check the IP address, that the robot is powered on and its brakes released, that "
            "an e-Series is in remote control mode, and that no other program holds the RTDE "
            "interface"
        )
        try:
            self._rtde_r = receive_factory(host, freq)
            self._rtde_c = control_factory(host, freq)
        except ImportError:
            raise
        except Exception as exc:
            raise RobotLinkError(f"could not connect to the UR at {host}: {exc}; {hint}") from exc
        if not (self._call_r("isConnected") and self._call_c("isConnected")):
            raise RobotLinkError(f"the RTDE interfaces to {host} are not connected; {hint}")
        if self.tcp_offset is not None:
            self._require(self._call_c("setTcp", self.tcp_offset), "setTcp", self.tcp_offset)
        if self.payload is not None:
            self._require(self._call_c("setPayload", *self.payload), "setPayload", self.payload)
        if freq > 0:
            self.dt = 1.0 / freq
        else:
            # ur-rtde's -1 picks 500 Hz on an e-Series and 125 Hz on a CB3: the controller's
            # own step (get_steptime: 0.002 s / 0.008 s). Guessing wrong would make every
            # dt-based gain wrong by 4x, so a step time that cannot be read is an error.
            step = float(self._call_c("getStepTime"))
            if not (math.isfinite(step) and 0.0 < step <= 1.0 / _MIN_AUTO_FREQUENCY):
                raise RobotLinkError(
                    f"could not read the control period from {host} (getStepTime() = {step!r}); "
                    "pass frequency= explicitly (125 for a CB3, 500 for an e-Series)"
                )
            self.step_time = step
            self.dt = step
        if self.zero_sensor:
            # Zero with the tool still and nobody touching it (module docstring).
            self._require(self._call_c("zeroFtSensor"), "zeroFtSensor")
        log.info("URRTDEWorld: connected to %s, dt = %.4f s", host, self.dt)

    def _call_c(self, name: str, *args: Any) -> Any:
        """Call the control interface; RobotLinkError when it raises."""
        try:
            return getattr(self._rtde_c, name)(*args)
        except Exception as exc:
            raise RobotLinkError(
                f"lost the RTDE control link to {self.host} ({name}: {exc}). The watchdog (when "
                "armed) stops the arm; check the network and the teach pendant, then rerun."
            ) from exc

    def _call_r(self, name: str) -> Any:
        """Call the receive interface; RobotLinkError when it raises."""
        try:
            return getattr(self._rtde_r, name)()
        except Exception as exc:
            raise RobotLinkError(
                f"lost the RTDE receive link to {self.host} ({name}: {exc}). The watchdog (when "
                "armed) stops the arm; check the network and the teach pendant, then rerun."
            ) from exc

    def _require(self, ok: Any, name: str, *args: Any) -> None:
        if ok is False:
            shown = ", ".join(repr(a) for a in args)
            raise RobotLinkError(f"the controller at {self.host} rejected {name}({shown})")

    def _check_open(self, what: str) -> None:
        if self._closed:
            raise RobotLinkError(f"{what} on a closed URRTDEWorld ({self.host}); build a new one")

    # -- World -----------------------------------------------------------------------

    def _open_period(self) -> None:
        self._t0 = self._call_c("initPeriod")
        self._t0_wall = time.perf_counter()

    def read(self) -> RobotState:
        """The robot's latest sample (ur-rtde's receive thread keeps it; no waiting).

        ``t`` is the robot's timestamp [s since the controller started]; when it has not
        advanced since the last read, ``t`` is the last one + 1 µs (the protocol wants it
        strictly increasing) and ``wrench_seq`` is unchanged. ``wrench_seq`` grows when
        the timestamp advanced or the force sample changed. The getters are separate
        calls, so in rare cases one reading mixes two consecutive controller steps.
        Raises :class:`RobotLinkError` when the link is lost (module docstring).
        """
        self._check_open("read()")
        if self._t0 is None:
            self._open_period()
        if not self._call_r("isConnected"):
            raise RobotLinkError(
                f"the RTDE receive interface to {self.host} reports it is disconnected; the "
                "watchdog (when armed) stops the arm. Check the network cable and the robot, then rerun."
            )
        ts = float(self._call_r("getTimestamp"))
        q = self._vector("getActualQ", 6)
        qd = self._vector("getActualQd", 6)
        pose = self._vector("getActualTCPPose", 6)
        twist = self._vector("getActualTCPSpeed", 6)
        force = self._vector("getActualTCPForce", 6)
        bits = int(self._call_r("getSafetyStatusBits"))
        now = time.monotonic()

        advanced = self._last_ts is None or ts > self._last_ts
        if advanced:
            self._last_advance_wall = now
        elif now - self._last_advance_wall > self.link_timeout:
            raise RobotLinkError(
                f"no new data from the robot at {self.host} for {now - self._last_advance_wall:.3f} s "
                f"(timestamp stuck at {ts:.3f} s; link_timeout {self.link_timeout:g} s): the link "
                "is lost. The watchdog (when armed) stops the arm; check the network, then rerun."
            )
        if advanced or self._last_force is None or not np.array_equal(force, self._last_force):
            self._wrench_seq += 1
        self._last_force = force
        self._last_ts = ts if self._last_ts is None else max(ts, self._last_ts)
        t = ts if ts > self._last_t else self._last_t + 1e-6
        self._last_t = t
        self.safety_status_bits = bits

        R = rotation_matrix(pose[3:])
        wrench = np.concatenate((R.T @ force[:3], R.T @ force[3:]))
        return RobotState(
            t=t,
            q=q,
            qd=qd,
            tool_pose=pose,
            tool_twist=twist,
            wrench=wrench,
            sensor_rotation=R,
            wrench_seq=self._wrench_seq,
            protective_stop=bool(bits & SafetyStatus.PROTECTIVE),
            emergency_stop=bool(bits & SafetyStatus.EMERGENCY),
        )

    def _vector(self, name: str, n: int) -> np.ndarray:
        value = self._call_r(name)
        arr = np.asarray(value, dtype=float)
        if arr.shape != (n,):
            raise RobotLinkError(
                f"{name} from {self.host} returned {len(arr) if arr.ndim else arr!r} values, expected {n}"
            )
        return arr

    def apply(self, command: Command) -> None:
        """Send one period's command and wait for the period to end.

        ``command.qd`` (6 finite values) goes to ``speedJ(qd, acceleration, dt)``;
        ``command.stop``, a missing ``qd``, a wrong shape or any non-finite value send
        ``speedStop(deceleration)`` instead (a non-finite value is never sent). Then
        ``kickWatchdog`` and ``waitPeriod``; :attr:`last_overrun` is updated and the next
        period opens. Raises :class:`RobotLinkError` when a call fails, or when the
        controller rejects ``speedJ`` while not in a protective or emergency stop (its
        control script is no longer running: watchdog, a stop from the pendant).
        """
        self._check_open("apply()")
        if self._t0 is None:
            self._open_period()
        if not self._watchdog_armed:
            if self.watchdog_hz is not None:
                self._require(self._call_c("setWatchdog", self.watchdog_hz), "setWatchdog", self.watchdog_hz)
            self._watchdog_armed = True

        qd = self._checked_qd(command)
        if qd is None:
            self._call_c("speedStop", self.deceleration)
        else:
            ok = self._call_c("speedJ", qd, self.acceleration, self.dt)
            if ok is False:
                self._on_rejected_speedj()
        self._call_c("kickWatchdog")
        self._call_c("waitPeriod", self._t0)
        period = time.perf_counter() - self._t0_wall
        self.last_period = period
        excess = period - self.dt
        self.last_overrun = excess if excess > self.overrun_tolerance * self.dt else 0.0
        self._open_period()

    def _checked_qd(self, command: Command) -> list[float] | None:
        if command.stop or command.qd is None:
            return None
        try:
            arr = np.asarray(command.qd, dtype=float)
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.shape != (self.n_joints,) or not np.all(np.isfinite(arr)):
            self.rejected_commands += 1
            if self.rejected_commands == 1 or self.rejected_commands % 1000 == 0:
                log.warning(
                    "URRTDEWorld: joint velocity command %r is not %d finite values; sent speedStop "
                    "instead (%d so far)",
                    command.qd,
                    self.n_joints,
                    self.rejected_commands,
                )
            return None
        return [float(v) for v in arr]

    def _on_rejected_speedj(self) -> None:
        bits = int(self._call_r("getSafetyStatusBits"))
        self.safety_status_bits = bits
        if bits & (SafetyStatus.PROTECTIVE | SafetyStatus.EMERGENCY):
            return  # the next read() reports the stop
        raise RobotLinkError(
            f"the controller at {self.host} rejected speedJ: ur-rtde's control script is not "
            "running (the watchdog fired, the program was stopped on the pendant, or remote "
            "control was lost). Check the teach pendant, then rerun."
        )

    def stop(self) -> None:
        """``speedStop(deceleration)``; safe to call twice; a no-op after :meth:`close`.

        Raises :class:`RobotLinkError` when the command cannot be sent (the watchdog then
        stops the arm within ``1/watchdog_hz``).
        """
        if self._closed or self._rtde_c is None:
            return
        self._call_c("speedStop", self.deceleration)

    def close(self) -> None:
        """``speedStop``, ``stopScript``, then disconnect both interfaces; never raises."""
        if self._closed:
            return
        self._closed = True
        self._t0 = None
        steps: list[tuple[Any, str, tuple]] = []
        if self._rtde_c is not None:
            steps += [
                (self._rtde_c, "speedStop", (self.deceleration,)),
                (self._rtde_c, "stopScript", ()),
                (self._rtde_c, "disconnect", ()),
            ]
        if self._rtde_r is not None:
            steps.append((self._rtde_r, "disconnect", ()))
        for iface, name, args in steps:
            try:
                getattr(iface, name)(*args)
            except Exception as exc:  # noqa: BLE001 - close must finish
                log.warning("URRTDEWorld.close: %s failed: %s", name, exc)

    def kinematics(self):
        """The UR5's kinematics with a zero TCP offset: the drive builds this world without a
        ``tcp_offset``, so the controller keeps its own (the flange, as shipped)."""
        from coassist.robot.kinematics import UR5Kinematics

        return UR5Kinematics(tcp_offset=np.zeros(6))

    def tool_mass_and_com(self) -> tuple[float, np.ndarray]:
        """(0.0, zeros): the controller removes the payload from ``getActualTCPForce`` itself (``setPayload``)."""
        return 0.0, np.zeros(3)

    def __enter__(self) -> URRTDEWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- information -----------------------------------------------------------------

    def robot_info(self) -> dict[str, Any]:
        """Connection facts for the trial metadata; None where the robot did not answer.

        Some of these go through the control script: call it before or after the loop,
        not inside it. ``controller_version`` is None: ur-rtde 1.6.5's RTDE interfaces do
        not expose it (``dashboard_client.DashboardClient.polyscopeVersion()`` does).
        """

        def ask(iface: Any, name: str) -> Any:
            if iface is None or self._closed:
                return None
            try:
                value = getattr(iface, name)()
            except Exception:  # noqa: BLE001 - informational
                return None
            return [float(v) for v in value] if isinstance(value, (list, tuple)) else value

        return {
            "host": self.host,
            "frequency": 1.0 / self.dt,
            "dt": self.dt,
            "requested_frequency": self.requested_frequency,
            "step_time": self.step_time if self.step_time is not None else ask(self._rtde_c, "getStepTime"),
            "acceleration": self.acceleration,
            "deceleration": self.deceleration,
            "watchdog_hz": self.watchdog_hz,
            "tcp_offset": ask(self._rtde_c, "getTCPOffset"),
            "payload_mass": ask(self._rtde_r, "getPayload"),
            "payload_cog": ask(self._rtde_r, "getPayloadCog"),
            "controller_version": None,
        }


def build_world(request: WorldRequest) -> URRTDEWorld:
    """The ``ur`` world of :data:`coassist.robot.worlds.WORLDS`: the UR at ``request.host``, at the run's rate."""
    return URRTDEWorld(request.host or "", frequency=float(request.rate_hz))  # "": URRTDEWorld names the missing host
