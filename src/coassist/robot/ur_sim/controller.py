"""The simulated controller: its cycle, its safety and program state, its faults, what it streams.

One :meth:`Controller.cycle` is one controller period (2 ms on an e-Series, 8 ms on a CB3),
run by the simulator's clock thread at the period's start ``t_k``:

1. the RTDE input packages received since the last cycle are applied in arrival order (a
   register keeps the last value written: the script sees only the last command code of a
   cycle), and each watchdog'ed input's update time is noted;
2. a watchdog whose input was not updated for ``1 / min_frequency`` stops the program;
3. the control script runs one iteration of its loop (:mod:`coassist.robot.ur_sim.registers`);
4. the output packages are built from the arm's state at ``t_k`` and the registers the script
   has just written, and sent to every started RTDE client whose rate falls on this cycle
   (a client asking f Hz gets every ``rate/f``-th cycle);
5. the arm advances one period (:class:`~coassist.robot.ur_sim.arm.SimArm`).

So an answer to a package that arrives in one period leaves at the start of the next, as on
a controller, and never before the client could have sent the question.

State (the values UR's RTDE guide and ur_rtde use): ``runtime_state`` 1 STOPPED / 2 PLAYING;
``robot_mode`` 3 POWER_OFF, 5 IDLE, 7 RUNNING; ``safety_mode`` 1 NORMAL, 3 PROTECTIVE_STOP,
7 ROBOT_EMERGENCY_STOP; ``safety_status_bits`` bit 0 normal, 2 protective stop, 6 robot
emergency stop, 7 emergency stopped, 10 stopped due to safety; ``robot_status_bits`` bit 0
power on, 1 program running.

Faults (:class:`Faults`, set from the simulator's methods): a protective stop (the arm brakes,
the program stops; cleared with the dashboard's ``unlock protective stop`` after
``unlock_delay``), an emergency stop (the arm brakes, the power goes off; released, then
``power on`` and ``brake release``), a program stopped from the pendant, the stream stalled
(no package out, none applied in: a hung RTDE server), the stream late (each package
``late`` s after its cycle) or jittery (uniform in [0, ``jitter``] s, seeded), remote
control off (scripts ignored, dashboard commands refused). The server adds a dropped
connection and a refused reconnection (:mod:`coassist.robot.ur_sim.server`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from coassist.robot.ur_sim import rtde
from coassist.robot.ur_sim.arm import SAFETY_STOP_DECELERATION, SimArm
from coassist.robot.ur_sim.registers import ControlScript, Program, RegisterFile

__all__ = ["Controller", "Faults", "OutputStream"]

log = logging.getLogger(__name__)

#: Output fields the cycle itself changes (program, safety, time): never taken from the cache.
_DYNAMIC = frozenset(
    {
        "timestamp",
        "control_step",
        "runtime_state",
        "robot_mode",
        "safety_mode",
        "safety_status",
        "safety_status_bits",
        "robot_status_bits",
        "joint_mode",
    }
)
_REGISTER_SUFFIXES = tuple(f"_{i}" for i in range(48))

STOPPED, PLAYING = 1, 2
POWER_OFF, IDLE, RUNNING = 3, 5, 7
NORMAL, PROTECTIVE_STOP, ROBOT_EMERGENCY_STOP = 1, 3, 7


@dataclass
class Faults:
    """The faults in force (module docstring); plain attributes the simulator sets."""

    stalled: bool = False
    late: float = 0.0
    jitter: float = 0.0
    remote_control: bool = True


@dataclass
class OutputStream:
    """One RTDE client's output: its recipe, rate and where its packages go.

    recipe : the output recipe.  frequency : the rate it asked [Hz].  send : called with each
    package (bytes).  started : between 'S' and 'P'.
    """

    recipe: rtde.Recipe
    frequency: float
    send: Callable[[bytes], None]
    started: bool = False
    phase: float = field(default=0.0, repr=False)


class Controller:
    """The controller's state and cycle (module docstring); thread-safe through :attr:`lock`.

    Parameters
    ----------
    arm : the simulated arm.
    rate_hz : the controller rate (500 e-Series, 125 CB3).
    version : the software version (major, minor, bugfix, build).
    serial : the serial number the dashboard gives.
    unlock_delay : [s] how long after a protective stop it can be unlocked (UR: 5 s).
    force_limit : [N] an external TCP force above this is a protective stop (the safety system's limit).
    program_start_delay : [s] from a received program to its running.
    seed : seeds the jitter fault.
    """

    def __init__(
        self,
        arm: SimArm,
        *,
        rate_hz: float,
        version: tuple[int, int, int, int],
        serial: str = "20185500020",
        unlock_delay: float = 5.0,
        force_limit: float = 150.0,
        program_start_delay: float = 0.05,
        seed: int = 0,
    ) -> None:
        self.arm = arm
        self.rate = float(rate_hz)
        self.dt = 1.0 / self.rate
        major, minor, bugfix, build = (int(v) for v in version)
        self.version = (major, minor, bugfix, build)
        self.serial = serial
        self.unlock_delay = float(unlock_delay)
        self.force_limit = float(force_limit)
        self.program_start_delay = float(program_start_delay)
        self.lock = threading.RLock()
        self.regs = RegisterFile()
        self.faults = Faults()
        self.robot_mode = RUNNING
        self.safety_mode = NORMAL
        self.script: ControlScript | None = None
        self.program_name = "<unnamed>"
        self.runtime_state = STOPPED
        self._pending: tuple[float, Program] | None = None
        self._inputs: deque[tuple[float, dict[str, object]]] = deque()
        self.watchdogs: dict[str, float] = {}
        self._updated: dict[str, float] = {}
        self.streams: list[OutputStream] = []
        self.k = 0  # cycles since the start: timestamp = k·dt
        self._rng = np.random.default_rng(seed)
        self._protective_since = -math.inf
        #: what happened, for tests and the status line: name → count or time
        self.events: dict[str, float] = {}
        self.watchdog_fired_at: float | None = None  # wall time
        self.watchdog_silence: float | None = None
        self.watchdog_rest_after: float | None = None
        self.last_program_stop: str | None = None
        self.unsupported_programs = 0
        self._cache: dict[str, object] = {}
        #: packages held back by a late or jittery stream: (due wall time, stream, bytes), in order
        self.outbox: deque[tuple[float, OutputStream, bytes]] = deque()
        self.outbox_ready = threading.Condition()

    # ------------------------------------------------------------------ inputs
    def receive(self, values: dict[str, object]) -> None:
        """An RTDE input package (name → value), applied at the next cycle (any thread)."""
        self._inputs.append((time.perf_counter(), values))

    def _apply_inputs(self, now: float) -> None:
        if self.faults.stalled:
            return
        while self._inputs:
            t, values = self._inputs.popleft()
            for name, value in values.items():
                self.regs.write_input(name, value)
                self._updated[name] = t

    # ------------------------------------------------------------------ programs
    def load_program(self, program: Program) -> None:
        """A program received on a script port: it replaces the running one and starts after the delay."""
        with self.lock:
            if not self.faults.remote_control:
                log.info("ur-sim: program %r ignored (remote control is off)", program.name)
                return
            self._end_program("replaced by a new program")
            self._pending = (time.perf_counter() + self.program_start_delay, program)

    def _start_pending(self, now: float) -> None:
        if self._pending is None or now < self._pending[0]:
            return
        _, program = self._pending
        self._pending = None
        if self.safety_mode != NORMAL or self.robot_mode != RUNNING:
            log.info("ur-sim: program %r not started: the robot is not running normally", program.name)
            return
        self.program_name = program.name
        if not program.is_control_script:
            self.unsupported_programs += 1
            log.warning("ur-sim: program %r is not ur_rtde's control script: run as an empty program", program.name)
            self.runtime_state = STOPPED
            return
        self.script = ControlScript(
            program, self.regs, self.arm, self.dt, self._set_watchdog, lambda: self.protective_stop("script")
        )
        self.runtime_state = PLAYING

    def _set_watchdog(self, variable: str, min_frequency: float) -> None:
        if math.isfinite(min_frequency) and min_frequency > 0.0:
            self.watchdogs[variable] = float(min_frequency)
            self._updated.setdefault(variable, time.perf_counter())

    def _end_program(self, why: str, decelerate: bool = True) -> None:
        """Stop the running program: watchdogs removed, the arm brought to rest."""
        if self.script is not None or self.runtime_state == PLAYING:
            self.last_program_stop = why
            self.events[why] = self.events.get(why, 0) + 1
        self.script = None
        self.runtime_state = STOPPED
        self.watchdogs.clear()
        if decelerate and self.arm.moving:
            self.arm.stop(SAFETY_STOP_DECELERATION)

    def program_state(self) -> tuple[str, str]:
        return ("PLAYING" if self.runtime_state == PLAYING else "STOPPED"), self.program_name

    def stop_program(self, why: str = "stopped from the dashboard") -> bool:
        with self.lock:
            was = self.runtime_state == PLAYING
            self._end_program(why)
            return was

    # ------------------------------------------------------------------ safety
    def protective_stop(self, why: str = "injected") -> None:
        with self.lock:
            if self.safety_mode == PROTECTIVE_STOP:
                return
            self.safety_mode = PROTECTIVE_STOP
            self._protective_since = time.perf_counter()
            self.events["protective stop"] = self.events.get("protective stop", 0) + 1
            self.arm.safety_stop()
            self._end_program(f"protective stop ({why})", decelerate=False)

    def emergency_stop(self) -> None:
        with self.lock:
            self.safety_mode = ROBOT_EMERGENCY_STOP
            self.robot_mode = POWER_OFF
            self.events["emergency stop"] = self.events.get("emergency stop", 0) + 1
            self.arm.safety_stop()
            self._end_program("emergency stop", decelerate=False)

    def release_emergency_stop(self) -> None:
        """The e-stop button released: the safety system is normal, the arm still off (power on, brake release)."""
        with self.lock:
            if self.safety_mode == ROBOT_EMERGENCY_STOP:
                self.safety_mode = NORMAL

    def unlock_protective_stop(self) -> str | None:
        with self.lock:
            if self.safety_mode != PROTECTIVE_STOP:
                return None
            if time.perf_counter() - self._protective_since < self.unlock_delay:
                return (
                    f"Cannot unlock protective stop until {self.unlock_delay:g}s after occurrence. "
                    "Always inspect cause of protective stop before unlocking"
                )
            self.safety_mode = NORMAL
            self.arm.release()
            return None

    def power(self, on: bool) -> None:
        with self.lock:
            if on and self.safety_mode == NORMAL and self.robot_mode == POWER_OFF:
                self.robot_mode = IDLE
            elif not on:
                self.robot_mode = POWER_OFF
                self.arm.safety_stop()
                self._end_program("powered off", decelerate=False)

    def brake_release(self) -> None:
        with self.lock:
            if self.robot_mode == IDLE and self.safety_mode == NORMAL:
                self.robot_mode = RUNNING
                self.arm.release()

    def restart_safety(self) -> None:
        with self.lock:
            if self.safety_mode != NORMAL:
                self.safety_mode = NORMAL
                self.robot_mode = POWER_OFF

    @property
    def remote_control(self) -> bool:
        return self.faults.remote_control

    @property
    def safety_status_bits(self) -> int:
        if self.safety_mode == PROTECTIVE_STOP:
            return (1 << 2) | (1 << 10)
        if self.safety_mode == ROBOT_EMERGENCY_STOP:
            return (1 << 6) | (1 << 7) | (1 << 10)
        return 1 << 0

    @property
    def robot_status_bits(self) -> int:
        return (1 if self.robot_mode >= IDLE else 0) | (2 if self.runtime_state == PLAYING else 0)

    # ------------------------------------------------------------------ the cycle
    def cycle(self, send: bool = True) -> float | None:
        """One controller period (module docstring, steps 1-5); the wall time the packages left, None if none did.

        ``send`` False skips step 4 (a period the simulator's process ran too late for).
        """
        now = time.perf_counter()
        with self.lock:
            self._apply_inputs(now)
            self._start_pending(now)
            for variable, f in list(self.watchdogs.items()):
                silent = now - self._updated.get(variable, now)
                if silent > 1.0 / f:
                    self.watchdog_fired_at = now
                    self.watchdog_silence = silent  # [s] from the input's last update to the stop
                    self.events["watchdog"] = self.events.get("watchdog", 0) + 1
                    self._end_program(f"watchdog: no update of {variable} for {1.0 / f:g} s")
                    break
            if self.watchdog_fired_at is not None and self.watchdog_rest_after is None and self.arm.at_rest:
                self.watchdog_rest_after = now - self.watchdog_fired_at
            script = self.script
            if script is not None:
                script.cycle()
                script.background()
                if not script.running:
                    self._end_program("stopScript", decelerate=False)
            if self.safety_mode == NORMAL and float(np.linalg.norm(self.arm.tcp_force[:3])) > self.force_limit:
                self.protective_stop(f"TCP force above {self.force_limit:g} N")
            packages = [(s, self._package(s)) for s in self.streams if s.started and self._due(s) and send]
        sent = None
        if packages and not self.faults.stalled:
            delay = self.faults.late + (self._rng.uniform(0.0, self.faults.jitter) if self.faults.jitter else 0.0)
            with self.outbox_ready:
                if delay > 0.0 or self.outbox:
                    # a late package leaves later, never before the one ahead of it (TCP keeps order)
                    due = max(now + delay, self.outbox[-1][0] if self.outbox else now)
                    self.outbox.extend((due, stream, data) for stream, data in packages)
                    self.outbox_ready.notify()
                    packages = []
            if packages:
                sent = time.perf_counter()
                for stream, data in packages:
                    stream.send(data)
        with self.lock:
            self.arm.step()
            self.k += 1
            # the next period's state fields now, so its packages leave right at its start
            self._cache.clear()
            for stream in self.streams:
                if stream.started:
                    for name in stream.recipe.names:
                        if name not in _DYNAMIC and not name.endswith(_REGISTER_SUFFIXES):
                            self.value(name)
        return sent

    def _due(self, stream: OutputStream) -> bool:
        stream.phase += stream.frequency / self.rate
        if stream.phase >= 1.0 - 1e-9:
            stream.phase -= 1.0
            return True
        return False

    def _package(self, stream: OutputStream) -> bytes:
        r = stream.recipe
        return r.pack([self.value(n) for n in r.names])

    # ------------------------------------------------------------------ outputs
    def value(self, name: str) -> object:
        """The present value of the output field ``name`` (module docstring of :mod:`.arm` for the conventions).

        The arm's fields are those at the period's start (computed once, right after the physics
        step); the program's and safety state's and the registers as the script left them this cycle.
        """
        if name in _DYNAMIC or "_register" in name:
            return self._value(name)
        cached = self._cache.get(name)
        if cached is not None:
            return cached
        v = self._value(name)
        self._cache[name] = v
        return v

    def _value(self, name: str) -> object:
        arm = self.arm
        if name == "timestamp":
            return self.k * self.dt
        if name == "actual_q":
            return arm.q.tolist()
        if name == "actual_qd":
            return arm.qd.tolist()
        if name == "target_q":
            return arm.q_ref.tolist()
        if name == "target_qd":
            return arm.v_ref.tolist()
        if name == "target_qdd":
            return arm.a_ref.tolist()
        if name == "actual_TCP_pose":
            return arm.tcp_pose.tolist()
        if name == "target_TCP_pose":
            return arm.target_tcp_pose().tolist()
        if name in ("actual_TCP_speed", "target_TCP_speed"):
            return arm.tcp_speed.tolist()
        if name == "actual_TCP_force":
            return arm.tcp_force.tolist()
        if name == "ft_raw_wrench":
            return arm.ft_raw.tolist()
        if name == "tcp_offset":
            return arm.tcp_offset.tolist()
        if name == "payload":
            return arm.payload_mass
        if name == "payload_cog":
            return arm.payload_cog.tolist()
        if name == "runtime_state":
            return self.runtime_state
        if name == "robot_mode":
            return self.robot_mode
        if name in ("safety_mode", "safety_status"):
            return self.safety_mode
        if name == "safety_status_bits":
            return self.safety_status_bits
        if name == "robot_status_bits":
            return self.robot_status_bits
        if name == "joint_mode":
            return [253 if self.robot_mode == RUNNING else 236] * 6  # JOINT_RUNNING_MODE / JOINT_POWER_OFF_MODE
        if name in ("speed_scaling", "target_speed_fraction"):
            return 1.0
        if name == "actual_execution_time":
            return 0.2e-3
        if name == "joint_temperatures":
            return [30.0] * 6
        if name in ("actual_main_voltage", "actual_robot_voltage"):
            return 48.0
        if name == "actual_joint_voltage":
            return [48.0] * 6
        if name == "target_gravity":
            return [0.0, 0.0, -9.81]
        if name == "control_step":
            return self.k
        if name.startswith(("input_", "output_")) and "_register_" in name:
            return self.regs.read(name)
        t = rtde.OUTPUT_FIELDS[name]  # a field the arm does not model: zero of its type
        w = rtde.WIDTH[t]
        zero = False if t == "BOOL" else (0.0 if "D" in t else 0)
        return zero if w == 1 else [zero] * w

    def status(self) -> dict[str, object]:
        """A snapshot for tests and the command line: program, safety, counters."""
        with self.lock:
            script = self.script
            return {
                "time": self.k * self.dt,
                "runtime_state": self.runtime_state,
                "robot_mode": self.robot_mode,
                "safety_mode": self.safety_mode,
                "program": self.program_name,
                "out_of_limits": self.arm.out_of_limits,
                "events": dict(self.events),
                "last_program_stop": self.last_program_stop,
                "watchdogs": dict(self.watchdogs),
                # the last watchdog stop: input silent for [s] when it fired, arm at rest [s] after
                "watchdog_silence": self.watchdog_silence,
                "watchdog_rest_after": self.watchdog_rest_after,
                "unsupported_commands": dict(script.unsupported) if script is not None else {},
                "commands": list(script.processed[-50:]) if script is not None else [],
                "q": self.arm.q.tolist(),
                "qd": self.arm.qd.tolist(),
                "tcp_pose": self.arm.tcp_pose.tolist(),
                "moving": bool(self.arm.moving),
            }
