"""A real UR arm as a :class:`~coassist.runtime.world.World`, through ur-rtde (``speedJ``).

Tested with the real ur-rtde 1.6.5 client against ``coassist ur-sim``
(:mod:`coassist.robot.ur_sim`: a UR controller at the protocol level, its dashboard, script
and RTDE ports, ur_rtde's control script run register by register, the MuJoCo UR5 behind it;
``tests/robot/test_ur_sim_world.py``). Not yet run on a real controller or URSim: docs/robots.md
lists what the simulator leaves out. Try it first at low speed with a hand on the emergency stop.

The loop pattern
----------------
One period per control tick::

    t0 = rtde_c.initPeriod()          # start of the period (steady clock)
    ... read, compute ...
    rtde_c.speedJ(qd, acceleration, dt)
    rtde_c.waitPeriod(t0)             # sleep until t0 + dt

The World protocol splits a tick into ``read()`` then ``apply()``, so the first period
opens in the first ``apply()`` (a drive reads the start state long before its loop starts)
and every later one at the end of ``apply()`` (right after ``waitPeriod``): the loop's
computation between ``read`` and ``apply`` falls inside the period, and the tick rate is
1/dt, not 1/(dt + compute). ``apply`` measures the whole
period with the wall clock; when it lasted longer than ``dt·(1 + overrun_tolerance)``,
:attr:`URRTDEWorld.last_overrun` holds the excess [s] (else 0.0) and the loop flags
``Fault.DEADLINE_MISS``.

The periods keep an absolute schedule: period k starts at ``t_first + k·dt``
(``t_first`` what the first ``initPeriod`` returned), not at a fresh ``initPeriod``. With a
fresh one each period, every period carries the previous one's late wake-up
(``waitPeriod``'s sleep, the return into Python): measured against ``coassist ur-sim``,
8.022 ms a period at 125 Hz, 55 ms behind the controller's clock after a 17 s trial. The
controller, and the person at the handle, move in real time, so tick k would no longer be
the time k·dt the log, the controller and the intent model take it for (the trial's tool
track 2.7-5.5 mm off the same trial in MuJoCo, where a tick is exactly dt). A period that
overran is caught up by the next ones (``waitPeriod`` returns at once while behind; each
such period is late and reported in ``last_overrun``), so one late tick does not shift every
later one; a stall of more than 50 ms restarts the schedule from now (``initPeriod``)
rather than run a burst of back-to-back ticks.

What the protocol decides (ur_rtde's control script reads one command code a controller
cycle from ``input_int_register_0`` and answers through ``output_int_register_0``;
:mod:`coassist.robot.ur_sim.registers`):

- Only real-time commands go inside a period: ``speedJ`` returns at once. ``speedStop``
  waits until the arm is at rest and every other command for at least one controller
  round trip, so a stop inside the loop is ``speedJ(zeros, deceleration, dt)``, and
  ``speedStop`` is left to :meth:`URRTDEWorld.stop` and :meth:`URRTDEWorld.close`.
- No ``kickWatchdog`` after ``speedJ``: it writes command code 0 into the same register
  microseconds later, and when both packages land in one controller cycle the script sees
  the 0 and drops the speedJ. The watchdog watches ``input_int_register_0``, which every
  speedJ package updates, so each speedJ is the kick.
- ``setWatchdog`` costs a round trip: it is armed in the first ``apply()``, before the first
  period opens (not at connect: a pause between building the world and starting the loop
  would trip it).
- ``getStepTime`` is real-time: it returns what ``output_double_register_0`` held *before*
  the script ran it (0.0 at first, or the answer of an earlier command such as
  ``getTCPOffset``), and a CB3's script has no ``get_steptime`` at all. With
  ``frequency=-1`` the period is therefore measured from the RTDE stream's timestamps, which
  advance one controller step per package (0.002 s e-Series, 0.008 s CB3).
- The TCP is the controller's (the installation's TCP, or ``tcp_offset`` sent with
  ``setTcp``), read back with ``getTCPOffset`` at connect: :meth:`URRTDEWorld.kinematics`
  uses it, so the pose RTDE reports and the Jacobian of eq. 3.6 are of the same point.

Why ``speedJ`` and not ``servoJ``
---------------------------------
The controller's output is a joint velocity (``command_space = "joint_velocity"``).
``speedJ`` takes it directly and ramps to it with a bounded acceleration. ``servoJ``
takes a position and tracks it through a lookahead filter (``lookahead_time`` ≥ 0.03 s
plus gain), which adds about 34 ms of lag to the human-robot loop: the person feels it
as extra inertia, and it erodes the stability margin of the admittance loop.
``acceleration`` (default 8 rad/s², leading axis; ``drive`` passes the safety layer's
``joint_acceleration``) is how fast the arm ramps to a new command. The safety layer already
bounds how fast the command changes by that much, so the arm follows each command within its
period. A slower ramp (1.4 rad/s², ur-rtde's examples') made the arm lag the command by up to
0.39 rad/s where the person turned: on the curved path round the large obstacle the person and
the lagging arm fell into a 40 N limit cycle that MuJoCo's arm, following its command, never
showed (found on ``coassist ur-sim``, 2026-12-06).

Watchdog
--------
``setWatchdog(watchdog_hz)`` makes the controller stop the program when no input package
updates ``input_int_register_0`` for ``1/watchdog_hz`` (0.1 s at the default 10 Hz): a hung
loop brakes the arm (tested: the simulated arm stops within the timeout). Later commands
then fail and ``apply`` raises :class:`URProgramStopped`, saying the watchdog stopped it when
the last period outlasted the timeout.

Force zeroing and the wrench
----------------------------
At connect (``zero_sensor=True``) the world calls ``zeroFtSensor()``, which subtracts
the current reading from every later one. Do it with **the tool still and nobody
touching it or the object**: whatever force is there at that moment is taken as zero
for the whole run. The reading is ``getActualTCPForce()``: the external wrench on the
tool, force in the base frame's axes and torque about the TCP (UR's script manual);
measured by the flange's sensor on an e-Series, estimated from the joint currents on a
CB3 (noisier, a few N). The controller removes the payload set with ``setPayload``. A hand
pushing the tool along +x_base reads +f_x, coassist's sign (runtime.world). ``read()``
rotates it into the TCP frame (the "sensor" frame here): ``f_tcp = Rᵀ f_base``,
``τ_tcp = Rᵀ τ_base`` with ``R`` the TCP orientation, and reports ``R`` as
``sensor_rotation``. The simulator follows that reading of UR's documentation (tested);
on an arm, push the tool by hand along +x_base once and check the sign.

Link loss, late data, stops
---------------------------
A reading that raises, an interface that reports it is disconnected, a robot timestamp
that has not advanced for ``link_timeout`` seconds (ur-rtde's receive thread keeps serving
its last sample after the link drops), or a sample that arrives more than ``link_timeout``
later than the stream's usual delay, or a quarter of the last second's samples more than two
periods late (a jittery link), makes ``read()`` raise
:class:`~coassist.runtime.world.RobotLinkError` (a ``ConnectionError``); the loop turns it into
a stop. A sample more than two periods late is counted (:attr:`URRTDEWorld.late_samples`) and
reported as an overrun, which the loop flags ``DEADLINE_MISS``. Protective and emergency
stops are not errors: ``read()`` reports them in :class:`~coassist.runtime.world.RobotState`,
and :attr:`URRTDEWorld.stop_detail` / :func:`~coassist.robot.ur_status.stop_message` say what to do.

A connection that has ended is not called into. ur-rtde 1.6.5 tears a control connection down
from two threads and without a lock: the thread whose command fails on it (``sendCommand``
catches the error, disconnects, reconnects) and its own receive thread (when a read fails). Each
guards the socket only with ``isConnected()``, and ``RTDE::disconnect`` drops the socket before
that flag turns false, so a command that meets the receive thread's teardown, or a teardown that
a command started and the receive thread meets, dereferences the dropped socket: the process
dies (SIGSEGV, in ``speedJ`` or in ur-rtde's receive thread; seen with the simulator's dropped
connection, docs/robots.md). Before each ``speedJ`` the world therefore asks the kernel whether
the robot reset or closed the control connection
(:class:`~coassist.robot.socket_watch.SocketWatch`: ``poll(2)`` on the socket the control
interface opened to port 30004, found at connect through ``/proc``, Linux only), then ur-rtde's
``isConnected()`` (together 1.2-1.6 µs a tick: benchmarks/bench_ur_link_check.py). An ended
connection raises :class:`~coassist.runtime.world.RobotLinkError` with no command sent, so no
teardown starts from this thread and none is met in progress. From the first sign of a lost link
(a call that raised, an interface or the kernel saying the connection is gone) the link stays
lost: ``read``, ``apply`` and ``stop`` raise without calling ur-rtde and ``close`` only
disconnects (ur-rtde's ``disconnect`` joins its receive thread first). Left open: a connection
that ends in the microseconds between that check and ``speedJ``'s write, and a receive thread
that tears down and reconnects entirely between two ticks (the controller accepting again at
once).

On a dead link ur-rtde's waiting commands would wait for an answer for up to 300 s (its
``UR_EXECUTION_TIMEOUT``, from its last cached state), so :meth:`URRTDEWorld.stop` and
:meth:`URRTDEWorld.close` send them only while the link is alive (the controller's watchdog
stops the arm otherwise), and ``disconnect`` is given 2 s: against a controller that accepts
connections but sends nothing, ur-rtde's receive thread reconnects for ever and its
disconnect never returns; the interface is then left running.
"""

from __future__ import annotations

import datetime
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from coassist.errors import CoassistError
from coassist.robot.ros2_config import MAX_TCP_OFFSET
from coassist.robot.socket_watch import SocketWatch, socket_fds, sockets_to
from coassist.robot.ur_status import SafetyStatus, check_software, connect_hint, controller_version, stop_message
from coassist.robot.worlds import WorldRequest
from coassist.runtime.world import MAX_LINK_TIMEOUT, Command, RobotLinkError, RobotState
from coassist.spatial import rotation_matrix

__all__ = ["URProgramStopped", "URRTDEWorld", "build_world"]

log = logging.getLogger(__name__)

#: With ``frequency=-1``, a controller step time slower than this rate is not believed.
_MIN_AUTO_FREQUENCY = 100.0
#: [s] how long connect watches the RTDE stream to measure its period (``frequency=-1``).
_STEP_PROBE_TIME = 0.25
#: [s/s] how fast the stream's usual delay may drift upward (the robot's clock against ours).
_CLOCK_DRIFT = 1e-3
_LATE = "the robot's state arrived late"
#: [s], fraction: over the last _JITTER_WINDOW of samples, this share more than two periods late is a failing link.
_JITTER_WINDOW = 1.0
_JITTER_SHARE = 0.25
#: The RTDE interface runs at most at the e-Series controller rate.
_MAX_FREQUENCY = 500.0
#: [rad/s²] the largest joint acceleration speedJ takes (ur-rtde's UR_JOINT_ACCELERATION_MAX): it refuses more
#: with an argument error, which on the stop's speedJ left the arm to the watchdog
MAX_JOINT_ACCELERATION = 40.0
#: Why the link is lost when the control socket's watch says ended: the robot reset or closed it, or the link
#: dropped and ur-rtde reconnected under the same descriptor (coassist.robot.socket_watch), its script gone.
_CONTROL_ENDED = "the control connection ended: the robot closed it, or it dropped and ur-rtde reconnected"

#: [kg] The heaviest payload a UR-class arm carries (the UR30's 30 kg): more is a typo, not a tool.
MAX_PAYLOAD = 30.0
#: [s] how far behind its schedule the loop may fall and still catch up (module docstring, the schedule);
#: beyond it (a long stall) the schedule restarts from now rather than run a burst of back-to-back ticks
_MAX_CATCH_UP = 0.05
_INSTALL_HINT = "the real robot needs ur-rtde: pip install 'coassist[robot]'"
#: The controller's RTDE port: the control interface's connection there carries every speedJ.
_RTDE_PORT = 30004


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


class URProgramStopped(CoassistError, RuntimeError):
    """ur_rtde's control script is no longer running (the watchdog fired, the program was stopped
    on the pendant or through the dashboard) while the robot is not in a safety stop: the arm
    is at rest, the run is over; the message says which and what to do."""


class URRTDEWorld:
    """A UR arm driven by joint velocity through ur-rtde (module docstring).

    Parameters
    ----------
    host : the robot's IP address or host name.
    frequency : RTDE rate [Hz], at most 500; -1 lets ur-rtde pick (125 Hz on a CB3,
        500 Hz on an e-Series), and ``dt`` is then the step of the RTDE stream's timestamps
        (RobotLinkError if the stream does not show one: pass the rate then).
    acceleration : ``speedJ`` acceleration of the leading joint [rad/s²].
    deceleration : [rad/s²] how fast ``Command(stop=True)``, a rejected command,
        :meth:`stop` and :meth:`close` bring the joints to rest.
    watchdog_hz : minimum update rate [Hz] of the controller-side watchdog; None disables
        it (not recommended).
    tcp_offset : TCP pose in the flange frame ``[x, y, z, rx, ry, rz]`` sent with
        ``setTcp``; None keeps the controller's (read back with ``getTCPOffset``).
    payload : ``(mass [kg], cog [m, 3])`` sent with ``setPayload``; None keeps the
        controller's.
    zero_sensor : call ``zeroFtSensor()`` at connect (tool still, nobody touching it).
    link_timeout : [s] a robot timestamp that does not advance for this long, or a sample
        this much later than the stream's usual delay, is a lost link.
    overrun_tolerance : fraction of ``dt`` a period may run over before ``last_overrun``
        reports it (absorbs scheduler jitter).
    control_factory, receive_factory : ``(host, frequency) -> interface``; default the
        real ``rtde_control.RTDEControlInterface`` / ``rtde_receive.RTDEReceiveInterface``.

    Attributes
    ----------
    dt, command_space, n_joints, realtime : the World protocol.
    tcp_offset : (6,) the TCP in the flange frame the controller reports the pose of.
    last_overrun : [s] how far the last period (or the last sample's delay) ran over (0.0 when on time).
    last_period : [s] the last period's measured length (from its scheduled start to waitPeriod's return).
    safety_status_bits : the last ``getSafetyStatusBits()`` (see :class:`~coassist.robot.ur_status.SafetyStatus`).
    rejected_commands : commands replaced by a stop (non-finite or wrong shape).
    late_samples : samples that arrived more than two periods behind the stream's usual delay.
    stop_detail : what stopped the robot and what to do (None while it runs).
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
        acceleration: float = 8.0,
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
        for name, value in (("acceleration", self.acceleration), ("deceleration", self.deceleration)):
            if value > MAX_JOINT_ACCELERATION:
                raise ValueError(
                    f"{name} must be at most {MAX_JOINT_ACCELERATION:g} rad/s², the most speedJ takes (ur-rtde refuses "
                    f"more, and a refused stop leaves the arm to the watchdog), got {value!r}"
                )
        self.watchdog_hz = None if watchdog_hz is None else _check_number(watchdog_hz, "watchdog_hz")
        if self.watchdog_hz is not None and frequency > 0 and self.watchdog_hz > frequency:
            raise ValueError(
                f"watchdog_hz must be at most the loop's frequency ({frequency:g} Hz): a loop slower than its watchdog "
                f"stops the program every period, got {watchdog_hz!r}"
            )
        self.requested_tcp_offset = None if tcp_offset is None else _check_vector(tcp_offset, "tcp_offset", 6)
        if self.requested_tcp_offset is not None and np.linalg.norm(self.requested_tcp_offset[:3]) > MAX_TCP_OFFSET:
            raise ValueError(
                f"tcp_offset must be a TCP within {MAX_TCP_OFFSET:g} m of the flange (metres, not mm), got "
                f"{list(self.requested_tcp_offset)}"
            )
        if payload is None:
            self.payload = None
        else:
            try:
                mass, cog = payload
            except (TypeError, ValueError):
                raise ValueError(f"payload must be (mass, cog), got {payload!r}") from None
            self.payload = (_check_number(mass, "payload mass", allow_zero=True), _check_vector(cog, "payload cog", 3))
            if self.payload[0] > MAX_PAYLOAD or np.linalg.norm(self.payload[1]) > MAX_TCP_OFFSET:
                raise ValueError(
                    f"payload must be at most {MAX_PAYLOAD:g} kg with its centre of gravity within {MAX_TCP_OFFSET:g} m "
                    f"of the flange (kg and metres), got {payload!r}"
                )
        self.link_timeout = _check_number(link_timeout, "link_timeout")
        if self.link_timeout > MAX_LINK_TIMEOUT:
            raise ValueError(
                f"link_timeout must be at most {MAX_LINK_TIMEOUT:g} s (a stopped robot clock is a lost link), got "
                f"{link_timeout!r}"
            )
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
        self.late_samples = 0
        self.worst_delay = 0.0
        self.step_time: float | None = None
        self._stream_dt: float | None = None
        self.tcp_offset = np.zeros(6)
        self.stop_detail: str | None = None
        self._late_streak = 0
        self._late_window: deque[bool] = deque(maxlen=8)

        self._rtde_c: Any = None
        self._rtde_r: Any = None
        self._closed = False
        # why a connection was found gone; from then on only disconnect reaches ur-rtde (module docstring, *Link loss*)
        self._lost: str | None = None
        self._watch: SocketWatch | None = None  # the control interface's RTDE socket (module docstring, *Link loss*)
        self._watchdog_armed = False
        self._t0: Any = None  # the open period's start, as initPeriod returns it (module docstring, the schedule)
        self._t0_wall = 0.0  # the same on perf_counter's clock
        self._anchor: Any = None  # the schedule's start (initPeriod's) and its wall clock; k periods since
        self._anchor_wall = 0.0
        self._k = 0
        self._last_ts: float | None = None
        # since the newest stamp: the last older stamp read, and whether the older stamps moved (read())
        self._behind: tuple[float, bool] | None = None
        self._last_t = -math.inf
        self._last_force: np.ndarray | None = None
        self._last_R: np.ndarray | None = None  # the last finite orientation's rotation (a glitched one reuses it)
        self._last_reading: tuple[np.ndarray, np.ndarray] | None = None  # (wrench, rotation) read() last gave
        self._last_advance_wall = time.monotonic()
        self._wrench_seq = 0
        self._usual_delay = math.inf  # the smallest (local clock − robot timestamp) seen, drifting up slowly
        self._delay_seen_at = time.monotonic()

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
        if control_factory is _default_control_factory:
            check_software(host)
        try:
            # the state at the controller's own rate (500 Hz e-Series, 125 Hz CB3): each read() gets a
            # sample at most one controller step old, whatever the loop's rate
            self._rtde_r = receive_factory(host, -1.0)
        except ImportError:
            raise
        except Exception as exc:
            raise RobotLinkError(f"could not connect to the UR at {host}: {exc}; {connect_hint(host, exc)}") from exc
        # every controller streams at least 125 Hz: a faster loop needs an e-Series (500 Hz). Asked of the stream
        # before the control interface opens: a CB3's refuses a 500 Hz recipe with a timeout that names nothing
        if freq > 125.0 and 1.0 / freq < self._stream_step() - 1e-9:
            raise RobotLinkError(
                f"the UR at {host} streams its state every {self._stream_step() * 1e3:g} ms: a {freq:g} Hz loop "
                "would run ahead of it (a CB3); run at 125 Hz: coassist drive/ros2 --rate 125 (URRTDEWorld: "
                "frequency=125, or -1 to take the stream's)"
            )
        try:
            before = socket_fds()
            self._rtde_c = control_factory(host, freq)
            self._watch = self._watch_control_socket(before)
        except ImportError:
            raise
        except Exception as exc:
            raise RobotLinkError(f"could not connect to the UR at {host}: {exc}; {connect_hint(host, exc)}") from exc
        if not (self._call_r("isConnected") and self._call_c("isConnected")):
            raise RobotLinkError(f"the RTDE interfaces to {host} are not connected; {connect_hint(host, Exception())}")
        if self.requested_tcp_offset is not None:
            self._require(self._call_c("setTcp", self.requested_tcp_offset), "setTcp", self.requested_tcp_offset)
        if self.payload is not None:
            self._require(self._call_c("setPayload", *self.payload), "setPayload", self.payload)
        # The TCP the controller reports the pose of: the installation's, or the one just set.
        # getTCPOffset waits for the script's answer (not real-time), so it is today's value.
        offset = np.asarray(self._call_c("getTCPOffset"), dtype=float)
        if offset.shape != (6,) or not np.all(np.isfinite(offset)):
            raise RobotLinkError(f"the UR at {host} returned an unusable TCP offset {offset.tolist()!r}")
        self.tcp_offset = offset
        if freq > 0:
            self.dt = 1.0 / freq
        else:
            # ur-rtde's -1 picks 500 Hz on an e-Series and 125 Hz on a CB3. getStepTime cannot
            # tell which (module docstring): the stream's timestamps advance one step per package.
            self.step_time = self.dt = self._stream_step()
            if self.watchdog_hz is not None and self.watchdog_hz > 1.0 / self.dt + 1e-9:
                # the check the constructor makes of a rate given, now the stream's is known (before the watchdog is
                # armed: nothing has moved)
                raise ValueError(
                    f"watchdog_hz must be at most the loop's frequency ({1.0 / self.dt:g} Hz, the stream's): a loop "
                    f"slower than its watchdog stops the program every period, got {self.watchdog_hz!r}"
                )
        if self.zero_sensor:
            # Zero with the tool still and nobody touching it (module docstring).
            self._require(self._call_c("zeroFtSensor"), "zeroFtSensor")
        log.info("URRTDEWorld: connected to %s, dt = %.4f s, TCP %s", host, self.dt, self.tcp_offset.tolist())

    def _watch_control_socket(self, before: set[int]) -> SocketWatch | None:
        """A watch on the socket the control interface opened to the RTDE port (module docstring,
        *Link loss*); None where it cannot be told (no ``/proc``, a fake interface, two candidates)."""
        found = sockets_to(_RTDE_PORT, before)
        if len(found) != 1:
            log.debug("URRTDEWorld: %d new sockets to port %d: the control link is not watched", len(found), _RTDE_PORT)
            return None
        return SocketWatch(found[0])

    def _control_ended(self) -> str | None:
        """Why the control connection is over (and the link lost for good), or None while it is up.

        Asked before each command: first the kernel (an RST or FIN from the robot, seen before ur-rtde
        acts on it), then ur-rtde's own flag (its receive thread has torn the connection down)."""
        if self._lost is None:
            if self._watch is not None and self._watch.ended():
                self._lose(_CONTROL_ENDED)
            elif not self._call_c("isConnected"):
                self._lose("the control interface reports it is disconnected")
        return self._lost

    def _stream_step(self) -> float:
        """The receive stream's step [s] (the controller's period), measured once."""
        if self._stream_dt is None:
            self._stream_dt = self._measure_step()
        return self._stream_dt

    def _measure_step(self) -> float:
        """The RTDE stream's period [s]: the smallest step between the timestamps of consecutive packages."""
        seen: list[float] = []
        end = time.monotonic() + _STEP_PROBE_TIME
        while time.monotonic() < end and len(seen) < 8:
            ts = float(self._call_r("getTimestamp"))
            if not seen or ts != seen[-1]:
                seen.append(ts)
            time.sleep(0.0005)
        steps = np.diff(seen)
        steps = steps[steps > 0]
        step = float(np.round(steps.min(), 6)) if steps.size >= 3 else math.nan
        if not (math.isfinite(step) and 0.0 < step <= 1.0 / _MIN_AUTO_FREQUENCY):
            raise RobotLinkError(
                f"could not tell the control period of the UR at {self.host} from its RTDE stream "
                f"(timestamps {seen!r}); give the rate: coassist drive/ros2 --rate 125 (a CB3) or 500 (an e-Series) (URRTDEWorld: frequency=)"
            )
        return step

    def _call_c(self, name: str, *args: Any) -> Any:
        """Call the control interface; RobotLinkError when it raises (the link is then lost for good)."""
        try:
            return getattr(self._rtde_c, name)(*args)
        except Exception as exc:
            self._lose(f"{name}: {exc}")
            raise RobotLinkError(
                f"lost the RTDE control link to {self.host} ({name}: {exc}). The watchdog (when "
                "armed) stops the arm; check the network and the teach pendant, then rerun."
            ) from exc

    def _call_r(self, name: str) -> Any:
        """Call the receive interface; RobotLinkError when it raises (the link is then lost for good)."""
        try:
            return getattr(self._rtde_r, name)()
        except Exception as exc:
            self._lose(f"{name}: {exc}")
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
        if self._lost is not None:
            raise RobotLinkError(
                f"{what}: the link to {self.host} was lost ({self._lost}); nothing more is sent to ur-rtde, "
                "the controller's watchdog (when armed) stops the arm. Check the network and the robot, then rerun."
            )

    def _lose(self, why: str) -> None:
        """Latch a lost connection: from now on no call but ``disconnect`` reaches ur-rtde (module docstring,
        *Link loss*): its receive thread may be tearing the connection down, and a command sent then can
        crash the process."""
        if self._lost is None:
            self._lost = why

    # -- World -----------------------------------------------------------------------

    def _before_first_period(self) -> None:
        """Called once, after the watchdog's round trip and right before the first period opens: a subclass
        starts here what must start with the loop's first period (the simulator's hand)."""

    def _open_period(self) -> None:
        """Start the schedule: this period begins now (``initPeriod``)."""
        self._t0 = self._anchor = self._call_c("initPeriod")
        self._t0_wall = self._anchor_wall = time.perf_counter()
        self._k = 0

    def _next_period(self) -> None:
        """The next period of the schedule: ``t_first + k·dt`` (module docstring), no drift from late wake-ups."""
        self._k += 1
        offset = self._k * self.dt
        # ur-rtde's time point is a datetime.timedelta (pybind11's steady_clock); a number in a fake's place
        step = datetime.timedelta(seconds=offset) if isinstance(self._anchor, datetime.timedelta) else offset
        self._t0 = self._anchor + step
        self._t0_wall = self._anchor_wall + offset

    def _arm_watchdog(self) -> None:
        """setWatchdog once, before the first period opens (it waits for the script's answer). Rejected: a safety stop
        the receive stream shows is left to the next read() (the run ends on it, naming it; the watchdog is asked
        for again at the next command), anything else is a control script that is not running, said so."""
        if not self._watchdog_armed:
            if self.watchdog_hz is not None:
                if self._call_c("setWatchdog", self.watchdog_hz) is False:
                    if self._safety_stop_shown():
                        return
                    # a stop in the second before the first tick read as a lost link ("check the cable")
                    what = (
                        f"the controller at {self.host} rejected setWatchdog({self.watchdog_hz!r}): ur-rtde's control "
                        "script is not running (the program was stopped on the teach pendant or through the "
                        "dashboard, or remote control was lost); nothing moved. Check the teach pendant, then rerun."
                    )
                    self.stop_detail = what
                    raise URProgramStopped(what)
            self._watchdog_armed = True

    def _safety_stop_shown(self) -> bool:
        """Whether the receive stream shows a protective or emergency stop, given two controller steps to show it
        (the control interface's answer may be a package ahead of the receive interface's)."""
        end = time.monotonic() + 2.0 * self.dt + 0.004
        while True:
            bits = int(self._call_r("getSafetyStatusBits"))
            if bits & (SafetyStatus.PROTECTIVE | SafetyStatus.EMERGENCY) or time.monotonic() > end:
                break
            time.sleep(0.0005)
        self.safety_status_bits = bits
        return bool(bits & (SafetyStatus.PROTECTIVE | SafetyStatus.EMERGENCY))

    def read(self) -> RobotState:
        """The robot's latest sample (ur-rtde's receive thread keeps it; no waiting).

        ``t`` is the robot's timestamp [s since the controller started]; when it has not
        advanced since the last read, ``t`` is that timestamp plus the time this computer's
        clock has run since it was seen (at least the last ``t`` + 1 µs: the protocol wants it
        strictly increasing), so a sample the stream left unrenewed ages as it would have, and
        ``wrench_seq`` is unchanged. ``wrench_seq`` grows when the timestamp advanced or the
        force sample changed. ``wrench`` is the controller's base-frame force in the tool's
        frame, ``sensor_rotation`` that frame's; a force repeated bit for bit is given with the
        frame it was given in before (the frozen-sensor check compares readings bit for bit;
        rotated by a tool that moved, a stuck sensor's repeats differed). The getters are separate
        calls, so in rare cases one reading mixes two consecutive controller steps.
        Raises :class:`RobotLinkError` when the link is lost (module docstring).
        """
        self._check_open("read()")
        if not self._call_r("isConnected"):
            self._lose("the receive interface reports it is disconnected")
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
            self._behind = None
            self._check_delay(now, ts)
        else:
            # Stamps that move on below the newest are not a stuck stream: the controller's clock went back (a
            # restart) or one sample was stamped ahead of the rest. The run stops either way (every later sample
            # reads as old), but the reason it names is the one the robot gave.
            if self._behind is None:
                self._behind = (ts, False)
            elif ts != self._behind[0]:
                self._behind = (ts, True)
            if now - self._last_advance_wall > self.link_timeout:
                why = (
                    f"its timestamps went back: the newest was {self._last_ts:.3f} s, the stream is at {ts:.3f} s "
                    "(the controller restarted, or one sample was stamped ahead of the rest)"
                    if self._behind[1]
                    else f"timestamp stuck at {ts:.3f} s"
                )
                raise RobotLinkError(
                    f"no new data from the robot at {self.host} for {now - self._last_advance_wall:.3f} s "
                    f"({why}; link_timeout {self.link_timeout:g} s): the link "
                    "is lost. The watchdog (when armed) stops the arm; check the network, then rerun."
                )
        repeated = self._last_force is not None and np.array_equal(force, self._last_force)
        if advanced or not repeated:
            self._wrench_seq += 1
        self._last_force = force
        self._last_ts = ts if self._last_ts is None else max(ts, self._last_ts)
        if advanced:
            t = ts if ts > self._last_t else self._last_t + 1e-6
        else:
            # no new sample: the time since the last one runs on by this computer's clock, so the wrench pipeline's
            # sample age grows (a stream that stopped is SENSOR_STALE after max_sample_age, about 4 periods, and the
            # arm brakes; the link is lost after link_timeout). At +1 µs a read the age stayed at microseconds and the
            # tick pushed on with the last sample for the whole link_timeout
            t = max(self._last_t + 1e-6, self._last_ts + (now - self._last_advance_wall))
        self._last_t = t
        self.safety_status_bits = bits

        state_stop = bool(bits & SafetyStatus.PROTECTIVE), bool(bits & SafetyStatus.EMERGENCY)
        if np.isfinite(pose[3:]).all():
            R = self._last_R = rotation_matrix(pose[3:])
        elif self._last_R is not None:
            # a glitched orientation: the pose goes on with its NaN (the tick flags it, holds the last good pose and
            # brakes), the force is rotated as the last good sample's (it ended the run, a ValueError out of read)
            R = self._last_R
        else:
            raise ValueError(
                f"the robot at {self.host} reports a TCP pose whose orientation is not finite ({pose[3:].tolist()}): "
                "nothing was moved; check the robot's state on the teach pendant, then rerun"
            )
        if repeated and self._last_reading is not None:
            # the controller's force repeated bit for bit: given in the frame it was given in before, so the frozen-
            # sensor check (which compares readings bit for bit) sees the repeat. Rotated by the moving tool's new
            # orientation its low bits moved, and a stuck sensor on a moving arm was never flagged (the arm followed
            # the last push). The same force in the base frame either way.
            wrench, R = self._last_reading
        else:
            wrench = np.concatenate((R.T @ force[:3], R.T @ force[3:]))
            self._last_reading = (wrench, R)
        state = RobotState(
            t=t,
            q=q,
            qd=qd,
            tool_pose=pose,
            tool_twist=twist,
            wrench=wrench,
            sensor_rotation=R,
            wrench_seq=self._wrench_seq,
            protective_stop=state_stop[0],
            emergency_stop=state_stop[1],
        )
        if any(state_stop):
            self.stop_detail = stop_message(state, bits)  # the robot's own stop says most
        return state

    def _check_delay(self, now: float, ts: float) -> None:
        """How late this sample is against the stream's usual delay (module docstring, *Link loss*)."""
        delay = now - ts
        # the usual delay: the smallest seen, allowed to creep up as the two clocks drift apart
        self._usual_delay = min(self._usual_delay + _CLOCK_DRIFT * (now - self._delay_seen_at), delay)
        self._delay_seen_at = now
        late = delay - self._usual_delay
        self.worst_delay = max(self.worst_delay, late)
        if late > self.link_timeout:
            raise RobotLinkError(
                f"the robot's data from {self.host} arrive {late * 1e3:.0f} ms later than usual "
                f"(link_timeout {self.link_timeout * 1e3:.0f} ms): the link is overloaded or failing. "
                "Check the cable (direct, no switch or Wi-Fi in between) and the controller's load, then rerun."
            )
        window = self._late_window
        if window.maxlen != max(8, round(_JITTER_WINDOW / self.dt)):
            window = self._late_window = deque(maxlen=max(8, round(_JITTER_WINDOW / self.dt)))
        window.append(late > 2.0 * self.dt)
        if len(window) == window.maxlen and sum(window) >= _JITTER_SHARE * len(window):
            raise RobotLinkError(
                f"the robot's data from {self.host} arrive irregularly ({sum(window)} of the last {len(window)} "
                f"samples more than two periods late, the worst {self.worst_delay * 1e3:.0f} ms): the link or "
                "this computer cannot keep the rate. Check the cable (direct, no switch or Wi-Fi) and this "
                "computer's load, or lower --rate, then rerun."
            )
        if late > 2.0 * self.dt:
            self.late_samples += 1
            self._late_streak += 1
            self.last_overrun = max(self.last_overrun, late - self.dt)
            if self.stop_detail is None or self.stop_detail.startswith(_LATE):
                self.stop_detail = (
                    f"{_LATE} ({self._late_streak} samples in a row more than two periods behind, the worst "
                    f"{self.worst_delay * 1e3:.0f} ms): the safety layer slowed and stopped the arm. Check the "
                    "cable (direct, no switch or Wi-Fi) and the load of this computer and the controller, then rerun."
                )
        else:
            self._late_streak = 0
            if self.stop_detail is not None and self.stop_detail.startswith(_LATE):
                self.stop_detail = None  # the stream is on time again: a later stop is not about it

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
        ``speedJ(zeros, deceleration, dt)`` instead (a non-finite value is never sent;
        ``speedStop`` would hold the period until the arm is at rest). Then ``waitPeriod``;
        :attr:`last_overrun` is updated and the next period opens. Raises
        :class:`RobotLinkError` when a call fails, :class:`URProgramStopped` when the
        controller rejects ``speedJ`` while not in a protective or emergency stop (its
        control script is no longer running: watchdog, a stop from the pendant).
        """
        self._check_open("apply()")
        if self._t0 is None:
            self._arm_watchdog()
            self._before_first_period()
            self._open_period()
        qd = self._checked_qd(command)
        # never a speedJ on a connection that has ended: ur-rtde would tear it down in this thread while
        # its receive thread does too, and either can crash the process (module docstring, *Link loss*)
        ended = self._control_ended()
        if ended is not None:
            raise RobotLinkError(
                f"lost the RTDE control link to {self.host} ({ended}); no command was sent. The watchdog (when "
                "armed) stops the arm; check the network cable and the robot, then rerun."
            )
        if qd is None:
            ok = self._call_c("speedJ", [0.0] * self.n_joints, self.deceleration, self.dt)
        else:
            ok = self._call_c("speedJ", qd, self.acceleration, self.dt)
        if ok is False:
            self._on_rejected_speedj()
        # No kickWatchdog: the speedJ package updated input_int_register_0 (module docstring).
        self._call_c("waitPeriod", self._t0)
        period = time.perf_counter() - self._t0_wall
        self.last_period = period
        excess = period - self.dt
        self.last_overrun = excess if excess > self.overrun_tolerance * self.dt else 0.0
        if excess > _MAX_CATCH_UP:
            self._open_period()  # a long stall: the schedule restarts from now, no burst of ticks to catch up
        else:
            self._next_period()  # a late period is caught up by the next (module docstring, the schedule)

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
                    "URRTDEWorld: joint velocity command %r is not %d finite values; sent a stop instead (%d so far)",
                    command.qd,
                    self.n_joints,
                    self.rejected_commands,
                )
            return None
        return [float(v) for v in arr]

    def _on_rejected_speedj(self) -> None:
        if self._safety_stop_shown():
            return  # the next read() reports the stop
        timeout = None if self.watchdog_hz is None else 1.0 / self.watchdog_hz
        gap = time.perf_counter() - self._t0_wall
        if timeout is not None and max(self.last_period, gap) > timeout:
            what = (
                f"the controller's watchdog stopped ur-rtde's control script: this loop's period lasted "
                f"{max(self.last_period, gap):.3f} s, over the watchdog's {timeout:g} s, and the arm "
                "braked. Find what held this computer (load, a debugger, swapping), then rerun."
            )
        else:
            what = (
                f"ur-rtde's control script stopped running on the UR at {self.host} (the program was "
                "stopped on the teach pendant or through the dashboard, remote control was lost, or the "
                "controller's watchdog saw no command for its timeout though this loop's periods were on time: "
                "commands delayed on their way); the arm is at rest. Check the teach pendant, then rerun."
            )
        self.stop_detail = what
        raise URProgramStopped(what)

    def _link_ok(self) -> bool:
        """Both interfaces connected and the stream alive: a command that waits for the script's
        answer (``speedStop``, ``stopScript``) would get one. On a dead link ur-rtde waits for it
        for up to 300 s (its UR_EXECUTION_TIMEOUT), answering from its last cached state."""
        if self._lost is not None:
            return False
        if self._watch is not None and self._watch.ended():
            self._lose(_CONTROL_ENDED)
            return False
        try:
            connected = bool(self._rtde_c.isConnected()) and bool(self._rtde_r.isConnected())
        except Exception:  # noqa: BLE001 - a broken interface is a dead link
            return False
        return connected and time.monotonic() - self._last_advance_wall <= self.link_timeout

    def stop(self) -> None:
        """``speedStop(deceleration)`` (it returns once the arm is at rest); safe to call twice;
        a no-op after :meth:`close`. On a dead link (:meth:`_link_ok`) only a real-time
        ``speedJ(zeros, deceleration)`` is tried: the controller's watchdog stops the arm; on a
        lost one (a call raised, an interface reported itself disconnected) nothing is sent.

        Raises :class:`RobotLinkError` when the command cannot be sent or the link was lost (the
        watchdog then stops the arm within ``1/watchdog_hz``).
        """
        if self._closed or self._rtde_c is None:
            return
        self._check_open("stop()")
        self._control_ended()
        self._check_open("stop()")  # a lost link: nothing is sent into a connection ur-rtde may be tearing down
        if self._link_ok():
            self._call_c("speedStop", self.deceleration)
        else:
            self._call_c("speedJ", [0.0] * self.n_joints, self.deceleration, self.dt)

    def close(self) -> None:
        """``speedStop``, ``stopScript`` (on a live link only: :meth:`_link_ok`), then disconnect
        both interfaces, side by side (ur-rtde's disconnect takes 0.5 s each); never raises."""
        if self._closed:
            return
        self._closed = True
        self._t0 = None
        steps: list[tuple[Any, str, tuple]] = []
        if self._rtde_c is not None:
            if self._rtde_r is not None and self._link_ok():
                steps += [(self._rtde_c, "speedStop", (self.deceleration,)), (self._rtde_c, "stopScript", ())]
            else:
                log.warning(
                    "URRTDEWorld.close: the link to %s is down; the controller's watchdog stops the arm", self.host
                )
        for iface, name, args in steps:
            try:
                getattr(iface, name)(*args)
            except Exception as exc:  # noqa: BLE001 - close must finish
                log.warning("URRTDEWorld.close: %s failed: %s", name, exc)
        # after the stop: the two interfaces are two sockets, and each disconnect waits 0.5 s inside ur-rtde
        _disconnect([i for i in (self._rtde_c, self._rtde_r) if i is not None], self.host)

    def kinematics(self):
        """The UR5's kinematics with the controller's TCP (:attr:`tcp_offset`, read at connect)."""
        from coassist.robot.kinematics import UR5Kinematics

        return UR5Kinematics(tcp_offset=self.tcp_offset)

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

        ``controller_version`` comes from the dashboard server (:func:`~coassist.robot.ur_status.controller_version`).
        Call it before or after the loop, not inside it (it waits for answers).
        """

        def ask(iface: Any, name: str) -> Any:
            if iface is None or self._closed or self._lost is not None:
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
            "step_time": self.step_time,
            "acceleration": self.acceleration,
            "deceleration": self.deceleration,
            "watchdog_hz": self.watchdog_hz,
            "tcp_offset": [float(v) for v in self.tcp_offset],
            "payload_mass": ask(self._rtde_r, "getPayload"),
            "payload_cog": ask(self._rtde_r, "getPayloadCog"),
            "controller_version": None if self._closed else controller_version(self.host),
        }


#: Interfaces whose disconnect did not return (module docstring, *Link loss*): kept alive, not destroyed.
_ABANDONED: list[Any] = []
#: [s] how long close() waits for an interface's disconnect.
_DISCONNECT_TIMEOUT = 2.0


def _disconnect(ifaces: list[Any], host: str) -> None:
    """``disconnect()`` of each interface, all at once, each given up after :data:`_DISCONNECT_TIMEOUT`.

    ur-rtde's disconnect joins its receive thread, and against a controller that accepts
    connections but sends nothing that thread reconnects for ever: the interface is then kept
    (never destroyed, which would wait again) and the thread ends when the controller answers
    or goes away.
    """
    import threading

    def run(iface: Any, done: threading.Event) -> None:
        try:
            iface.disconnect()
        except Exception as exc:  # noqa: BLE001 - reported below, close goes on
            log.warning("URRTDEWorld.close: disconnect failed: %s", exc)
        finally:
            done.set()

    waits = []
    for iface in ifaces:
        done = threading.Event()
        threading.Thread(target=run, args=(iface, done), name="ur-rtde-disconnect", daemon=True).start()
        waits.append((iface, done))
    deadline = time.monotonic() + _DISCONNECT_TIMEOUT
    for iface, done in waits:
        if not done.wait(max(0.0, deadline - time.monotonic())):
            _ABANDONED.append(iface)
            log.warning(
                "URRTDEWorld.close: ur-rtde's interface to %s did not disconnect within %g s (its receive thread "
                "keeps reconnecting to a controller that sends nothing); left running",
                host,
                _DISCONNECT_TIMEOUT,
            )


def build_world(request: WorldRequest) -> URRTDEWorld:
    """The ``ur`` world of :data:`coassist.robot.worlds.WORLDS`: the UR at ``request.host``, at the run's rate."""
    return URRTDEWorld(  # "": URRTDEWorld names the missing host
        request.host or "", frequency=float(request.rate_hz), acceleration=request.joint_acceleration
    )
