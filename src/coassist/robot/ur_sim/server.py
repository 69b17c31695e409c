"""The simulator's network side and clock: :class:`URSim`, what ``coassist ur-sim`` runs.

Ports, on ``URSimConfig.host``, as on a UR controller:

- 29999 the dashboard server (:mod:`coassist.robot.ur_sim.dashboard`; and coassist's own
  ``coassist …`` commands, :mod:`coassist.robot.ur_sim.hand`: the simulated operator at the
  handle, a start pose);
- 30001, 30002, 30003 the script ports: a program sent there replaces the running one
  (ur_rtde's control script is run: :mod:`coassist.robot.ur_sim.registers`; another program
  is accepted and ends at once). The state packages a controller streams on these ports are
  not sent.
- 30004 RTDE (:mod:`coassist.robot.ur_sim.rtde`): version negotiation, the controller
  version, output and input recipes (ids from 1 per connection, ``NOT_FOUND`` for a name the
  controller does not have, ``IN_USE`` for an input register another connection writes),
  start / pause, the output stream at the rate each client asked.

Two threads: the clock, which runs :meth:`Controller.cycle <coassist.robot.ur_sim.controller.Controller.cycle>`
at each period's start ``t_k = t_0 + k·dt`` (it sleeps until ``spin`` s before ``t_k`` and
spins the rest, so the period holds on a busy machine; a cycle more than 5 periods late
re-anchors the clock instead of bursting, and counts an overrun), and the network thread
(one ``selectors`` loop for every socket). Every port is the controller's fixed one, so two
simulators on one machine need two addresses: any of 127.0.0.0/8 is this machine.

A dropped connection (:meth:`URSim.drop_connections`): every client socket closed at once;
for ``refuse_for`` seconds the ports then refuse connections (the cable out), after that
they accept again.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import re
import selectors
import socket
import struct
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from coassist._checks import check_real
from coassist.robot.arm_mjcf import TOOLS
from coassist.robot.mujoco_world import DEFAULT_START, FTSensorModel
from coassist.robot.ur_sim import dashboard, hand, rtde
from coassist.robot.ur_sim.arm import SimArm
from coassist.robot.ur_sim.controller import Controller, OutputStream
from coassist.robot.ur_sim.registers import parse_program
from coassist.runtime.operators import ScriptedForce
from coassist.runtime.world import HandOperator

__all__ = ["PORTS", "SERIES", "URSim", "URSimConfig"]

log = logging.getLogger(__name__)

DASHBOARD_PORT = 29999
SCRIPT_PORTS = (30001, 30002, 30003)
RTDE_PORT = 30004
PORTS = (DASHBOARD_PORT, *SCRIPT_PORTS, RTDE_PORT)

#: The two controller generations: rate [Hz] and default software version.
SERIES = {
    "e-series": (500.0, (5, 11, 1, 108318)),
    "cb3": (125.0, (3, 15, 7, 106331)),
}
#: Periods the clock catches up (physics only) after a stall of the process; beyond, it re-anchors.
_MAX_CATCH_UP = 250
#: The most a client's outgoing buffer holds before packages are dropped (a client that does not read).
_MAX_BUFFERED = 1 << 16


@dataclass(frozen=True)
class URSimConfig:
    """The simulated controller (every field checked; errors name it as ``URSimConfig.<field>``).

    host : the address to listen on (any 127.x.y.z for a second simulator on one machine).
    series : "e-series" (500 Hz, software 5.x) or "cb3" (125 Hz, 3.x). The arm is the UR5 either way.
    version : (major, minor, bugfix, build) the controller reports; None: the series' default.
    serial : the serial number.  tool : the carried object (handle, board, heavy).
    start : (3,) the TCP's start position [m] (base frame), the tool pointing down.
    tcp_offset : (6,) the installation's TCP in the flange frame; None: the tool's TCP.
    payload : (mass, (3,) cog) the installation's payload; None: the tool's true mass and centre.
    sensor : the flange force/torque sensor; None: 0.05 N / 0.002 N·m noise, a sample every period.
    seed : the sensor noise's and the jitter fault's seed.
    unlock_delay : [s] from a protective stop to when it can be unlocked (UR: 5).
    force_limit : [N] external TCP force that triggers a protective stop (UR's default 150).
    program_start_delay : [s] from a received program to its running.
    spin : [s] how long before each period's start the clock stops sleeping and spins.
    rt_priority : SCHED_FIFO priority (1-99) for the simulator's threads, where the system allows
        it (root, or CAP_SYS_NICE); None: normal priority. It keeps the stream's period on a busy
        machine; the threads sleep most of each period, so other programs keep the processor (a
        clock that finds no time to sleep for a second drops it; processes it starts never get it).
    """

    host: str = "127.0.0.1"
    series: str = "e-series"
    version: tuple[int, int, int, int] | None = None
    serial: str = "20185500020"
    tool: str = "handle"
    start: tuple[float, float, float] = DEFAULT_START
    tcp_offset: tuple[float, ...] | None = None
    payload: tuple[float, tuple[float, float, float]] | None = None
    sensor: FTSensorModel | None = None
    seed: int = 0
    unlock_delay: float = 5.0
    force_limit: float = 150.0
    program_start_delay: float = 0.05
    spin: float = 0.0003
    rt_priority: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.host, str) or not self.host:
            raise ValueError(f"URSimConfig.host must be an address, got {self.host!r}")
        if self.tool not in TOOLS:
            raise ValueError(f"URSimConfig.tool must be one of {TOOLS}, got {self.tool!r}")
        if self.series not in SERIES:
            raise ValueError(f"URSimConfig.series must be one of {tuple(SERIES)}, got {self.series!r}")
        if self.version is not None:
            v = tuple(self.version)
            if len(v) != 4 or not all(isinstance(x, int) and x >= 0 for x in v):
                raise ValueError(f"URSimConfig.version must be 4 integers >= 0, got {self.version!r}")
            object.__setattr__(self, "version", v)
        if not (isinstance(self.serial, str) and self.serial.isdigit()):
            raise ValueError(f"URSimConfig.serial must be digits, got {self.serial!r}")
        start = np.asarray(self.start, dtype=float)
        if start.shape != (3,) or not np.isfinite(start).all():
            raise ValueError(f"URSimConfig.start must be 3 finite numbers [m], got {self.start!r}")
        object.__setattr__(self, "start", tuple(float(x) for x in start))
        if self.tcp_offset is not None:
            off = np.asarray(self.tcp_offset, dtype=float)
            if off.shape != (6,) or not np.isfinite(off).all():
                raise ValueError(f"URSimConfig.tcp_offset must be 6 finite numbers, got {self.tcp_offset!r}")
        if self.payload is not None:
            try:
                mass, cog = self.payload
                cog_arr = np.asarray(cog, dtype=float)
                ok = math.isfinite(float(mass)) and float(mass) >= 0.0 and cog_arr.shape == (3,)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"URSimConfig.payload must be (mass >= 0, 3 numbers), got {self.payload!r}")
        if self.sensor is not None and not isinstance(self.sensor, FTSensorModel):
            raise ValueError(f"URSimConfig.sensor must be an FTSensorModel, got {type(self.sensor).__name__}")
        if self.rt_priority is not None and not (
            isinstance(self.rt_priority, int) and not isinstance(self.rt_priority, bool) and 1 <= self.rt_priority <= 99
        ):
            raise ValueError(f"URSimConfig.rt_priority must be an int in [1, 99] or None, got {self.rt_priority!r}")
        for name, lo in (("unlock_delay", 0.0), ("force_limit", 0.0), ("program_start_delay", 0.0), ("spin", 0.0)):
            object.__setattr__(self, name, check_real(getattr(self, name), f"URSimConfig.{name}", lo))

    @property
    def rate(self) -> float:
        return SERIES[self.series][0]

    @property
    def controller_version(self) -> tuple[int, int, int, int]:
        return self.version if self.version is not None else SERIES[self.series][1]


@dataclass(eq=False)
class _Conn:
    """One client socket: its kind, its input buffer, and a locked, buffered writer."""

    sock: socket.socket
    kind: str
    lock: threading.Lock = field(default_factory=threading.Lock)
    out: bytearray = field(default_factory=bytearray)
    inbuf: bytearray = field(default_factory=bytearray)
    reader: rtde.PackageReader = field(default_factory=rtde.PackageReader)
    inputs: dict[int, rtde.Recipe] = field(default_factory=dict)
    claimed: set[str] = field(default_factory=set)
    stream: OutputStream | None = None
    protocol: int = 1
    dropped: int = 0
    closed: bool = False

    def send(self, data: bytes) -> None:
        with self.lock:
            if self.closed:
                return
            if self.out:
                if len(self.out) + len(data) > _MAX_BUFFERED:
                    self.dropped += 1
                    return
                self.out += data
                self._flush()
                return
            try:
                n = self.sock.send(data)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError:
                self.closed = True
                return
            if n < len(data):
                self.out += data[n:]

    def _flush(self) -> None:
        try:
            n = self.sock.send(self.out)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self.closed = True
            return
        del self.out[:n]

    def flush(self) -> None:
        with self.lock:
            if self.out and not self.closed:
                self._flush()


class URSim:
    """A UR controller at the protocol level with the MuJoCo UR5 behind it (module docstring).

    ``with URSim(URSimConfig(host="127.0.0.2")) as sim:`` starts it (every port bound, the
    clock running) and stops it at the end; :meth:`start` / :meth:`stop` do the same by hand.
    The faults are methods; :meth:`status` is a snapshot. Its threads share this process's
    GIL: for the ur-rtde client, which holds the GIL while it waits for the controller, run it
    in its own (:class:`~coassist.robot.ur_sim.process.URSimProcess`, ``coassist ur-sim``).
    """

    def __init__(self, config: URSimConfig | None = None) -> None:
        self.config = config or URSimConfig()
        c = self.config
        self.arm = SimArm(
            1.0 / c.rate,
            tool=c.tool,
            start=c.start,
            tcp_offset=c.tcp_offset,
            payload=c.payload,
            sensor=c.sensor,
            seed=c.seed,
        )
        self.controller = Controller(
            self.arm,
            rate_hz=c.rate,
            version=c.controller_version,
            serial=c.serial,
            unlock_delay=c.unlock_delay,
            force_limit=c.force_limit,
            program_start_delay=c.program_start_delay,
            seed=c.seed,
        )
        self._sel: selectors.BaseSelector | None = None
        self._listeners: dict[int, socket.socket] = {}
        self._conns: set[_Conn] = set()
        self._conn_lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._refuse_until = 0.0
        self._drop: tuple[float, threading.Event] | None = None
        self._wake_r, self._wake_w = socket.socketpair()
        #: wall times [s, perf_counter] of the cycles that sent output packages (the stream's period)
        self.send_times: deque[float] = deque(maxlen=1_000_000)
        #: wall times the clock woke for a period's start (its own period, whether anyone listens)
        self.wake_times: deque[float] = deque(maxlen=1_000_000)
        #: times the clock fell more than _MAX_CATCH_UP periods behind and re-anchored (simulated time lost)
        self.overruns = 0
        #: periods whose output packages were skipped because the process ran late
        self.skipped = 0
        self._priority_warned = False
        self._push = np.zeros(6)

    # ------------------------------------------------------------------ life cycle
    @property
    def host(self) -> str:
        return self.config.host

    def start(self) -> URSim:
        """Bind every port and start the clock and network threads; OSError naming the port when one is taken."""
        if self._threads:
            return self
        self._sel = selectors.DefaultSelector()
        self._sel.register(self._wake_r, selectors.EVENT_READ, None)
        try:
            self._open_listeners()
        except OSError:
            self._close_listeners()
            raise
        self._stop.clear()
        for target, name in (
            (self._network, "ur-sim-net"),
            (self._clock, "ur-sim-clock"),
            (self._late_sender, "ur-sim-late"),
        ):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)
        log.info("ur-sim: listening on %s (%s, %g Hz)", self.host, self.config.series, self.config.rate)
        return self

    def _open_listeners(self) -> None:
        assert self._sel is not None
        for port in PORTS:
            if port in self._listeners:
                continue
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((self.host, port))
            except OSError as exc:
                s.close()
                raise OSError(
                    exc.errno,
                    f"ur-sim: cannot listen on {self.host}:{port} ({exc.strerror}); another simulator or "
                    "controller holds it: give another --host (any 127.x.y.z is this machine)",
                ) from None
            s.listen(8)
            s.setblocking(False)
            self._listeners[port] = s
            self._sel.register(s, selectors.EVENT_READ, ("listen", port))

    def _close_listeners(self) -> None:
        for s in self._listeners.values():
            with contextlib.suppress(KeyError, ValueError, OSError):
                if self._sel is not None:
                    self._sel.unregister(s)
            s.close()
        self._listeners.clear()

    def stop(self) -> None:
        """Close every socket and stop the threads (idempotent)."""
        self._stop.set()
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        with self.controller.outbox_ready:
            self.controller.outbox_ready.notify_all()
        for t in self._threads:
            t.join(5.0)
        self._threads.clear()
        self._close_listeners()
        for conn in list(self._conns):
            self._close(conn)
        if self._sel is not None:
            self._sel.close()
            self._sel = None

    def __enter__(self) -> URSim:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ faults and the hand
    def protective_stop(self) -> None:
        """The safety system's protective stop (as a collision or a force limit would)."""
        self.controller.protective_stop("injected")

    def emergency_stop(self) -> None:
        """The teach pendant's emergency stop is pressed."""
        self.controller.emergency_stop()

    def release_emergency_stop(self) -> None:
        self.controller.release_emergency_stop()

    def stop_program(self) -> None:
        """The program stopped from the teach pendant."""
        self.controller.stop_program("stopped from the teach pendant")

    def stall(self, on: bool = True) -> None:
        """The RTDE server hangs (``on``): no package goes out, none coming in is applied."""
        self.controller.faults.stalled = bool(on)

    def set_stream_delay(self, late: float = 0.0, jitter: float = 0.0) -> None:
        """Each output package leaves ``late`` s after its cycle, plus uniform jitter in [0, ``jitter``] s."""
        self.controller.faults.late = check_real(late, "late", 0.0, 1.0)
        self.controller.faults.jitter = check_real(jitter, "jitter", 0.0, 1.0)

    def set_remote_control(self, on: bool) -> None:
        """Remote control on the pendant: off, scripts are ignored and dashboard commands refused."""
        self.controller.faults.remote_control = bool(on)

    def drop_connections(self, refuse_for: float = 0.0) -> None:
        """Close every client connection now; refuse new ones for ``refuse_for`` s (the cable out)."""
        refuse_for = check_real(refuse_for, "refuse_for", 0.0)
        done = threading.Event()
        self._drop = (refuse_for, done)  # the network thread owns the sockets: it closes them
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        if not done.wait(5.0):
            raise RuntimeError("ur-sim: the network thread did not drop the connections within 5 s")

    def _do_drop(self) -> None:
        refuse_for, done = self._drop  # type: ignore[misc]
        self._drop = None
        self._refuse_until = time.perf_counter() + refuse_for
        if refuse_for > 0.0:
            self._close_listeners()
        for conn in list(self._conns):
            self._close(conn, reset=True)
        done.set()

    @property
    def operator(self) -> HandOperator | None:
        """Whoever pushes on the handle (a :class:`~coassist.runtime.world.HandOperator`, its time the simulator's)."""
        return self.arm.operator

    @operator.setter
    def operator(self, value: HandOperator | None) -> None:
        with self.controller.lock:
            self.arm.operator = value

    def push(self, wrench: Sequence[float] | None) -> None:
        """A constant hand wrench (6,) [N, N·m] on the handle, base frame, from the next period on; None lets go."""
        if wrench is None:
            self.operator = None
            return
        w = np.asarray(wrench, dtype=float)
        if w.shape != (6,) or not np.isfinite(w).all():
            raise ValueError(f"push must be 6 finite numbers [N, N·m], got {wrench!r}")
        self.operator = ScriptedForce.constant(w)

    def status(self) -> dict[str, object]:
        """The controller's :meth:`~coassist.robot.ur_sim.controller.Controller.status` plus the clock's overruns."""
        out = self.controller.status()
        out["overruns"] = self.overruns
        out["skipped"] = self.skipped
        out["clients"] = sum(1 for c in self._conns if c.kind == "rtde")
        return out

    def stream_periods(self) -> np.ndarray:
        """The intervals [s] between the cycles that sent output packages, oldest first."""
        t = np.asarray(self.send_times, dtype=float)
        return np.diff(t)

    def clock_periods(self) -> np.ndarray:
        """The intervals [s] between the clock's wake-ups for its periods, oldest first."""
        return np.diff(np.asarray(self.wake_times, dtype=float))

    # ------------------------------------------------------------------ the clock
    def _clock(self) -> None:
        self._set_priority()
        ctrl, dt, spin = self.controller, self.controller.dt, self.config.spin
        clock = time.perf_counter
        t_next = clock() + dt
        busy = 0  # periods in a row the clock found no time to sleep
        while not self._stop.is_set():
            rem = t_next - clock()
            busy = 0 if rem > 0.0 else busy + 1
            if busy > round(1.0 / dt) and self.config.rt_priority is not None:
                # a second without a pause: at real-time priority it would take a core from everything else
                with contextlib.suppress(OSError):
                    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
                log.warning("ur-sim: the cycle does not fit its period on this machine; real-time priority dropped")
                busy = -(1 << 30)
            if rem > spin:
                time.sleep(rem - spin)
            while clock() < t_next:
                pass
            self.wake_times.append(clock())
            # Periods this process missed (the machine ran something else): their physics runs now,
            # their packages are skipped, as a controller short of time sends only the newest.
            behind = int((clock() - t_next) / dt)
            if behind > _MAX_CATCH_UP:
                self.overruns += 1
                t_next = clock()
                behind = 0
            for _ in range(behind):
                ctrl.cycle(send=False)
                self.skipped += 1
            t_next += behind * dt
            sent = ctrl.cycle()
            if sent is not None:
                self.send_times.append(sent)
            t_next += dt

    def _late_sender(self) -> None:
        """Sends the packages a late or jittery stream holds back, each at its due time."""
        self._set_priority()
        ctrl = self.controller
        while not self._stop.is_set():
            with ctrl.outbox_ready:
                if not ctrl.outbox:
                    ctrl.outbox_ready.wait(0.05)
                    continue
                due = ctrl.outbox[0][0]
            wait = due - time.perf_counter()
            if wait > 0.0:
                time.sleep(min(wait, 0.05))
                continue
            with ctrl.outbox_ready:
                if not ctrl.outbox or ctrl.outbox[0][0] != due:
                    continue
                batch = []
                while ctrl.outbox and ctrl.outbox[0][0] == due:
                    batch.append(ctrl.outbox.popleft())
            for _, stream, data in batch:
                stream.send(data)
            self.send_times.append(time.perf_counter())

    def _set_priority(self) -> None:
        """SCHED_FIFO at ``URSimConfig.rt_priority`` for the calling thread, when asked and allowed."""
        prio = self.config.rt_priority
        if prio is None:
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(prio))
        except (AttributeError, OSError) as exc:
            if not self._priority_warned:
                self._priority_warned = True
                log.warning("ur-sim: real-time priority %d not granted (%s); running at normal priority", prio, exc)

    # ------------------------------------------------------------------ the network
    def _network(self) -> None:
        self._set_priority()
        sel = self._sel
        assert sel is not None
        while not self._stop.is_set():
            if self._drop is not None:
                self._do_drop()
            if not self._listeners and time.perf_counter() >= self._refuse_until:
                with contextlib.suppress(OSError):
                    self._open_listeners()
            for key, _ in sel.select(timeout=0.005):
                if key.data is None:
                    with contextlib.suppress(OSError):
                        self._wake_r.recv(4096)
                    continue
                try:
                    if key.data[0] == "listen":
                        self._accept(key.fileobj, key.data[1])  # type: ignore[arg-type]
                    else:
                        self._readable(key.data[1])
                except Exception:  # noqa: BLE001 - one connection's bug must not take the simulator down
                    log.exception("ur-sim: error on a %s connection; closed", key.data[0])
                    if key.data[0] == "conn":
                        self._close(key.data[1])
            for conn in list(self._conns):
                conn.flush()
                if conn.closed:
                    self._close(conn)

    def _accept(self, listener: socket.socket, port: int) -> None:
        try:
            sock, _ = listener.accept()
        except OSError:
            return
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setblocking(False)
        kind = "dashboard" if port == DASHBOARD_PORT else ("rtde" if port == RTDE_PORT else "script")
        conn = _Conn(sock, kind)
        with self._conn_lock:
            self._conns.add(conn)
        assert self._sel is not None
        self._sel.register(sock, selectors.EVENT_READ, ("conn", conn))
        if kind == "dashboard":
            conn.send((dashboard.GREETING + "\n").encode())

    def _close(self, conn: _Conn, reset: bool = False) -> None:
        with conn.lock:
            conn.closed = True
        with self._conn_lock:
            self._conns.discard(conn)
        if conn.stream is not None:
            with self.controller.lock:
                if conn.stream in self.controller.streams:
                    self.controller.streams.remove(conn.stream)
        with contextlib.suppress(KeyError, ValueError, OSError):
            if self._sel is not None:
                self._sel.unregister(conn.sock)
        if reset:  # RST, as a pulled cable's timeout ends it: no graceful FIN
            with contextlib.suppress(OSError):
                conn.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        with contextlib.suppress(OSError):
            conn.sock.close()

    def _readable(self, conn: _Conn) -> None:
        try:
            data = conn.sock.recv(1 << 16)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._close(conn)
            return
        try:
            if conn.kind == "dashboard":
                self._dashboard(conn, data)
            elif conn.kind == "script":
                self._script(conn, data)
            else:
                self._rtde(conn, data)
        except ValueError as exc:  # a malformed package: the controller drops the connection
            log.warning("ur-sim: %s connection closed: %s", conn.kind, exc)
            self._close(conn)

    def _dashboard(self, conn: _Conn, data: bytes) -> None:
        conn.inbuf += data
        while b"\n" in conn.inbuf:
            line, _, rest = bytes(conn.inbuf).partition(b"\n")
            conn.inbuf = bytearray(rest)
            text_in = line.decode("utf-8", errors="replace")
            if text_in.lower().startswith("coassist "):  # coassist's own commands (ur_sim.hand)
                text, close = hand.reply(self.controller, self.config.series, text_in), False
            else:
                text, close = dashboard.reply(self.controller, text_in)
            conn.send((text + "\n").encode())
            if close:
                conn.flush()
                self._close(conn)
                return

    _END = re.compile(rb"^end[ \t]*\r?$", re.MULTILINE)

    def _script(self, conn: _Conn, data: bytes) -> None:
        conn.inbuf += data
        while True:
            m = self._END.search(conn.inbuf)
            if m is None:
                return
            text = bytes(conn.inbuf[: m.end()]).decode("utf-8", errors="replace")
            del conn.inbuf[: m.end()]
            program = parse_program(text)
            if program is not None:
                self.controller.load_program(program)

    def _rtde(self, conn: _Conn, data: bytes) -> None:
        ctrl = self.controller
        for kind, payload in conn.reader.feed(data):
            if kind == rtde.REQUEST_PROTOCOL_VERSION:
                (version,) = struct.unpack(">H", payload[:2])
                ok = version in (1, 2)
                if ok:
                    conn.protocol = version
                conn.send(rtde.package(kind, bytes((int(ok),))))
            elif kind == rtde.GET_URCONTROL_VERSION:
                conn.send(rtde.package(kind, struct.pack(">IIII", *ctrl.version)))
            elif kind == rtde.CONTROL_PACKAGE_SETUP_OUTPUTS:
                if conn.protocol >= 2:
                    (freq,) = struct.unpack(">d", payload[:8])
                    names = rtde.split_names(payload[8:])
                else:
                    freq, names = 125.0, rtde.split_names(payload)
                self._setup_outputs(conn, names, freq)
            elif kind == rtde.CONTROL_PACKAGE_SETUP_INPUTS:
                self._setup_inputs(conn, rtde.split_names(payload))
            elif kind == rtde.CONTROL_PACKAGE_START:
                ok = conn.stream is not None or bool(conn.inputs)
                if conn.stream is not None:
                    conn.stream.started = True
                conn.send(rtde.package(kind, bytes((int(ok),))))
            elif kind == rtde.CONTROL_PACKAGE_PAUSE:
                if conn.stream is not None:
                    conn.stream.started = False
                conn.send(rtde.package(kind, b"\x01"))
            elif kind == rtde.DATA_PACKAGE:
                if not payload:
                    raise ValueError("an RTDE data package without a recipe id")
                recipe = conn.inputs.get(payload[0])
                if recipe is None:
                    conn.send(rtde.text_message(f"unknown input recipe id {payload[0]}"))
                    continue
                ctrl.receive(recipe.unpack(payload[1:]))
            else:
                conn.send(rtde.text_message(f"unknown RTDE package type {kind}"))

    def _setup_outputs(self, conn: _Conn, names: list[str], freq: float) -> None:
        ctrl = self.controller
        types = [
            rtde.OUTPUT_FIELDS[n] if n in rtde.OUTPUT_FIELDS and rtde.field_available(n, ctrl.version) else "NOT_FOUND"
            for n in names
        ]
        ok = bool(names) and "NOT_FOUND" not in types and 0.0 < freq <= ctrl.rate
        rid = 1 if ok else 0
        if ok:
            stream = OutputStream(rtde.Recipe(rid, tuple(names), tuple(types)), freq, conn.send)
            with ctrl.lock:
                if conn.stream is not None and conn.stream in ctrl.streams:
                    ctrl.streams.remove(conn.stream)
                conn.stream = stream
                ctrl.streams.append(stream)
        elif names and "NOT_FOUND" not in types:
            conn.send(rtde.text_message(f"output frequency {freq:g} Hz is not in (0, {ctrl.rate:g}]"))
        conn.send(rtde.package(rtde.CONTROL_PACKAGE_SETUP_OUTPUTS, bytes((rid,)) + rtde.join_types(types)))

    def _setup_inputs(self, conn: _Conn, names: list[str]) -> None:
        with self._conn_lock:
            others = set().union(*(c.claimed for c in self._conns if c is not conn))
        types = []
        for n in names:
            if n not in rtde.INPUT_FIELDS:
                types.append("NOT_FOUND")
            elif n in others:
                types.append("IN_USE")
            else:
                types.append(rtde.INPUT_FIELDS[n])
        ok = bool(names) and not any(t in ("NOT_FOUND", "IN_USE") for t in types)
        rid = 0
        if ok:
            rid = len(conn.inputs) + 1
            conn.inputs[rid] = rtde.Recipe(rid, tuple(names), tuple(types))
            conn.claimed.update(names)
        conn.send(rtde.package(rtde.CONTROL_PACKAGE_SETUP_INPUTS, bytes((rid,)) + rtde.join_types(types)))
