"""A fake of ur-rtde's RTDEControlInterface / RTDEReceiveInterface for fast tests of URRTDEWorld.

One :class:`FakeRobot` holds a trivial arm shared by the two interfaces and records
every call of either, in order, as ``Call(source, name, args, t)`` (``source`` is
"control" or "receive", ``t`` the monotonic time). Pass ``robot.control_factory`` and
``robot.receive_factory`` to ``URRTDEWorld``. The timed and protocol-level behaviour is
tested against the real client and ``coassist ur-sim`` (tests/robot/test_ur_sim_world.py);
this fake keeps what that showed, so the fast tests cannot pass on what the protocol forbids:

- one controller cycle per ``waitPeriod`` (:meth:`FakeRobot.step`); the control script sees
  only the *last* command code sent in a cycle: ``kickWatchdog`` (code 0) after ``speedJ``
  in the same cycle drops the speedJ (:attr:`FakeRobot.dropped_speedj` counts them);
- ``getStepTime`` is real-time: it returns ``output_double_register_0`` as it is *before* the
  script runs it (0.0 at first, or the x of the last ``getTCPOffset``), the step time appears
  there one cycle later;
- ``speedStop``, ``setWatchdog``, ``zeroFtSensor``, ``setTcp``, ``setPayload`` and
  ``getTCPOffset`` wait for the script's answer: each costs at least one cycle, and
  ``speedStop`` runs the arm to rest before it returns (:attr:`FakeRobot.blocking_cycles`);
- the controller's TCP is ``tcp_offset`` (default the handle's, not the flange);
- with ``stream = True`` the receive timestamp advances one controller step (``step_time``) per
  ``getTimestamp`` call (the RTDE stream running on its own: URRTDEWorld measures its step).

The arm: the joint velocity moves toward the speedJ target by at most a·period per cycle, q
integrates it, the timestamp advances. The TCP pose is ``tcp_pose`` or ``pose_fn(q)``; the TCP
force is ``tcp_force`` (base frame) minus what ``zeroFtSensor`` captured.

Faults to inject (plain attributes):
- ``protective_stop_at = N``: the N-th speedJ (1-based) triggers a protective stop: the
  arm halts, the safety bits say so, and speedJ/speedStop return False from then on.
- ``link_down = True`` or a method name in ``raise_on``: calls raise RuntimeError, as
  ur-rtde does when the connection is gone (the call is still recorded).
- ``connected = False``: isConnected() returns False; ``control_connected = False``: only the
  control interface's does (ur-rtde's receive thread tore that connection down).
- ``rtde_address = (host, port)``: the control interface opens a real TCP connection there when
  it is built, as ur-rtde's does to the RTDE port (``rtde_socket``; closed by its disconnect), so
  what the kernel says of that connection can be tested.
- ``frozen = True``: the timestamp stops advancing (a dead receive thread).
- ``late_by = X``: waitPeriod returns X s after the end of the period (a late tick).
- ``script_running = False``: speedJ returns False (the control script has stopped,
  e.g. the watchdog fired) without any safety stop.
- ``step_time``: the controller's period (what getStepTime answers a cycle late).

Method names and signatures follow ur-rtde 1.6.5 (tests check each exists there).
"""

from __future__ import annotations

import datetime
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

PROTECTIVE_STOPPED_BIT = 1 << 2
EMERGENCY_STOPPED_BIT = 1 << 7
NORMAL_MODE_BIT = 1 << 0


@dataclass
class Call:
    source: str
    name: str
    args: tuple
    t: float


class FakeRobot:
    def __init__(
        self,
        *,
        step_time: float = 0.002,
        tcp_pose: list[float] | None = None,
        pose_fn: Callable[[np.ndarray], list[float]] | None = None,
        tcp_force: list[float] | None = None,
    ) -> None:
        self.calls: list[Call] = []
        self.step_time = step_time
        self.frequency = -1.0
        self.q = np.zeros(6)
        self.qd = np.zeros(6)
        self.target_qd = np.zeros(6)
        self.acceleration = 0.0
        self.timestamp = 1000.0
        self.tcp_pose = list(tcp_pose) if tcp_pose is not None else [0.4, 0.1, 0.3, 0.0, 0.0, 0.0]
        self.pose_fn = pose_fn
        self.tcp_speed = [0.0] * 6
        self.tcp_force = list(tcp_force) if tcp_force is not None else [0.0] * 6
        self.force_offset = [0.0] * 6
        self.tcp_offset = [0.0, 0.0, 0.06, 0.0, 0.0, 0.0]  # the installation's TCP (the handle), not the flange
        self.payload = (0.0, [0.0, 0.0, 0.0])
        self.safety_bits = NORMAL_MODE_BIT
        self.n_speedj = 0
        # fault injection
        self.protective_stop_at: int | None = None
        self.link_down = False
        self.raise_on: set[str] = set()
        #: [s] how long each interface's disconnect takes (ur-rtde's own: 0.5 s), by source
        self.disconnect_seconds: dict[str, float] = {}
        self.connected = True
        self.control_connected = True
        self.rtde_address: tuple[str, int] | None = None
        self.rtde_socket: socket.socket | None = None
        self.frozen = False
        self.late_by = 0.0
        self.script_running = True
        self.stream = False
        # the register protocol (module docstring)
        self.out_double_0 = 0.0  # output_double_register_0 as the client last received it
        self._pending_code: tuple[int, list[float], float] | None = None  # last command code sent this cycle
        self._answer_next_cycle: float | None = None  # what the script writes into register 0 at the next cycle
        self.dropped_speedj = 0
        self.blocking_cycles = 0

    # -- factories (URRTDEWorld's control_factory / receive_factory) -----------------

    def control_factory(self, host: str, frequency: float) -> FakeRTDEControl:
        self.frequency = frequency
        self.record("control", "__init__", host, frequency)
        if self.rtde_address is not None:
            self.rtde_socket = socket.create_connection(self.rtde_address, timeout=2.0)
        return FakeRTDEControl(self)

    def receive_factory(self, host: str, frequency: float) -> FakeRTDEReceive:
        self.record("receive", "__init__", host, frequency)
        return FakeRTDEReceive(self)

    # -- helpers ---------------------------------------------------------------------

    def record(self, source: str, name: str, *args: object) -> None:
        self.calls.append(Call(source, name, args, time.monotonic()))
        if self.link_down or name in self.raise_on:
            raise RuntimeError(f"RTDE {source} interface: not connected to the robot ({name})")

    def names(self, source: str | None = None) -> list[str]:
        return [c.name for c in self.calls if source is None or c.source == source]

    @property
    def period(self) -> float:
        return 1.0 / self.frequency if self.frequency > 0 else self.step_time

    @property
    def protective_stopped(self) -> bool:
        return bool(self.safety_bits & PROTECTIVE_STOPPED_BIT)

    def step(self) -> None:
        """One controller cycle: the script runs the cycle's last command code, the arm moves one period."""
        pending, self._pending_code = self._pending_code, None
        if pending is not None:
            code, qd, a = pending
            if code == 9:
                self.target_qd, self.acceleration = np.asarray(qd, dtype=float), a
        if self._answer_next_cycle is not None:
            self.out_double_0, self._answer_next_cycle = self._answer_next_cycle, None
        dt = self.period
        dv = np.clip(self.target_qd - self.qd, -self.acceleration * dt, self.acceleration * dt)
        self.qd = self.qd + dv
        self.q = self.q + self.qd * dt
        if not self.frozen:
            self.timestamp += dt

    def send_code(self, code: int, qd: list[float] | None = None, a: float = 0.0) -> None:
        """A command package: the command register holds its code until the cycle runs."""
        if self._pending_code is not None and self._pending_code[0] == 9 and code != 9:
            self.dropped_speedj += 1
        self._pending_code = (code, list(qd) if qd is not None else [], a)

    def wait_for_script(self, cycles: int = 1) -> None:
        """A command that waits for the script's answer: the cycles pass before it returns."""
        for _ in range(cycles):
            self.step()
            self.blocking_cycles += 1

    def pose(self) -> list[float]:
        return list(self.pose_fn(self.q)) if self.pose_fn is not None else list(self.tcp_pose)


class FakeRTDEControl:
    def __init__(self, robot: FakeRobot) -> None:
        self.robot = robot

    def _rec(self, name: str, *args: object) -> None:
        self.robot.record("control", name, *args)

    def isConnected(self) -> bool:
        self._rec("isConnected")
        return self.robot.connected and self.robot.control_connected

    def getStepTime(self) -> float:
        self._rec("getStepTime")
        r = self.robot
        r.send_code(26)
        r._answer_next_cycle = r.step_time
        return r.out_double_0  # read before the script ran the command

    def setTcp(self, tcp_offset: list[float]) -> bool:
        self._rec("setTcp", list(tcp_offset))
        self.robot.send_code(29)
        self.robot.wait_for_script()
        self.robot.tcp_offset = list(tcp_offset)
        return True

    def getTCPOffset(self) -> list[float]:
        self._rec("getTCPOffset")
        r = self.robot
        r.send_code(40)
        r.wait_for_script()
        r.out_double_0 = r.tcp_offset[0]  # the answer lands in output_double_register_0-5
        return list(r.tcp_offset)

    def setPayload(self, mass: float, cog: list[float]) -> bool:
        self._rec("setPayload", mass, list(cog))
        self.robot.send_code(17)
        self.robot.wait_for_script()
        self.robot.payload = (mass, list(cog))
        return True

    def zeroFtSensor(self) -> bool:
        self._rec("zeroFtSensor")
        self.robot.send_code(8)
        self.robot.wait_for_script()
        self.robot.force_offset = list(self.robot.tcp_force)
        return True

    def setWatchdog(self, min_frequency: float = 10.0) -> bool:
        self._rec("setWatchdog", min_frequency)
        if self.robot.protective_stopped or not self.robot.script_running:  # as the controller: no script to ask
            return False
        self.robot.send_code(35)
        self.robot.wait_for_script()
        return True

    def kickWatchdog(self) -> bool:
        self._rec("kickWatchdog")
        self.robot.send_code(0)
        return True

    def initPeriod(self) -> datetime.timedelta:
        self._rec("initPeriod")
        return datetime.timedelta(seconds=time.monotonic())

    def waitPeriod(self, t_cycle_start: datetime.timedelta) -> None:
        self._rec("waitPeriod", t_cycle_start)
        end = t_cycle_start.total_seconds() + self.robot.period + self.robot.late_by
        while (left := end - time.monotonic()) > 0:
            time.sleep(left)
        self.robot.step()

    def speedJ(self, qd: list[float], acceleration: float = 0.5, time: float = 0.0) -> bool:
        self._rec("speedJ", list(qd), acceleration, time)
        r = self.robot
        r.n_speedj += 1
        if r.protective_stop_at is not None and r.n_speedj >= r.protective_stop_at:
            r.safety_bits |= PROTECTIVE_STOPPED_BIT
        if r.protective_stopped or not r.script_running:
            r.target_qd = np.zeros(6)
            r.qd = np.zeros(6)
            return False
        r.send_code(9, list(qd), acceleration)  # real-time: the script takes it at the next cycle
        return True

    def speedStop(self, a: float = 10.0) -> bool:
        self._rec("speedStop", a)
        r = self.robot
        if r.protective_stopped or not r.script_running:
            return False
        r.send_code(15)
        r.target_qd = np.zeros(6)
        r.acceleration = a
        r.wait_for_script()
        for _ in range(100_000):  # stopj blocks until the arm is at rest
            if not np.any(r.qd):
                break
            r.wait_for_script()
        return True

    def stopScript(self) -> None:
        self._rec("stopScript")

    def disconnect(self) -> None:
        self._rec("disconnect")
        if self.robot.rtde_socket is not None:
            self.robot.rtde_socket.close()
        time.sleep(self.robot.disconnect_seconds.get("control", 0.0))


class FakeRTDEReceive:
    def __init__(self, robot: FakeRobot) -> None:
        self.robot = robot

    def _rec(self, name: str) -> None:
        self.robot.record("receive", name)

    def isConnected(self) -> bool:
        self._rec("isConnected")
        return self.robot.connected

    def getTimestamp(self) -> float:
        self._rec("getTimestamp")
        r = self.robot
        if r.stream and not r.frozen:
            r.timestamp += r.step_time  # the receive interface runs at the controller's own step
        return r.timestamp

    def getActualQ(self) -> list[float]:
        self._rec("getActualQ")
        return [float(v) for v in self.robot.q]

    def getActualQd(self) -> list[float]:
        self._rec("getActualQd")
        return [float(v) for v in self.robot.qd]

    def getActualTCPPose(self) -> list[float]:
        self._rec("getActualTCPPose")
        return self.robot.pose()

    def getActualTCPSpeed(self) -> list[float]:
        self._rec("getActualTCPSpeed")
        return list(self.robot.tcp_speed)

    def getActualTCPForce(self) -> list[float]:
        self._rec("getActualTCPForce")
        return [f - o for f, o in zip(self.robot.tcp_force, self.robot.force_offset, strict=True)]

    def getSafetyStatusBits(self) -> int:
        self._rec("getSafetyStatusBits")
        return self.robot.safety_bits

    def isProtectiveStopped(self) -> bool:
        self._rec("isProtectiveStopped")
        return self.robot.protective_stopped

    def isEmergencyStopped(self) -> bool:
        self._rec("isEmergencyStopped")
        return bool(self.robot.safety_bits & EMERGENCY_STOPPED_BIT)

    def getPayload(self) -> float:
        self._rec("getPayload")
        return self.robot.payload[0]

    def getPayloadCog(self) -> list[float]:
        self._rec("getPayloadCog")
        return list(self.robot.payload[1])

    def disconnect(self) -> None:
        self._rec("disconnect")
        time.sleep(self.robot.disconnect_seconds.get("receive", 0.0))
