"""ur_rtde's control script as the controller runs it: the register protocol, one controller cycle at a time.

``RTDEControlInterface`` uploads a URScript program (``rtde_control``, port 30003) and then
talks to it through the RTDE general-purpose registers only (offset 0, or 24 with
``FLAG_UPPER_RANGE_REGISTERS``; the offset is injected into the script's text):

- ``input_int_register_0``: the command code (:data:`COMMANDS`); its other int and double
  input registers are the command's arguments, in the client's input recipes' order.
- ``output_int_register_0``: the handshake, 1 = ready for a command, 2 = done with it.
- ``output_double_register_0…5`` / ``output_int_register_1``: a command's answer.
- ``output_int_register_2``: progress of an asynchronous move.

The script's main loop, one iteration per controller cycle (``sync()``)::

    cmd = input_int_register_0
    if cmd is a real-time command:     process it; output_int_register_0 = 1 (ready)
    elif cmd == 0:                     executing = False; output_int_register_0 = 1
    elif not executing:                process it (a blocking one, e.g. movej or stopj,
                                       holds the loop until it ends); output_int_register_0 = 2;
                                       executing = True

The client, for a command that is not real-time, waits for 1, writes the command, waits for
2, then writes 0; a real-time one (speedJ, speedL, servoJ, forceMode, getStepTime, …) it
writes and returns at once, reading any answer from the registers it has *now* — before the
script could have run. The script reads the registers once per cycle, so of two packages
that arrive within one cycle only the second's command code is seen (the guide: inputs keep
their last received value).

Which functions a program can call depends on the controller's software: the client
deletes the lines marked for a newer version before sending (e.g. ``get_steptime()`` needs
5.4, so a CB3's script has none). :class:`ControlScript` looks for each URScript call it
emulates in the text it received and does nothing where the line is missing, as the
controller would.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from coassist.robot.ur_sim.arm import SimArm

__all__ = ["COMMANDS", "REAL_TIME", "ControlScript", "Program", "RegisterFile", "parse_program"]

log = logging.getLogger(__name__)

#: ur_rtde 1.6's command codes (``RTDE::RobotCommand::Type``) → name; those emulated are in ControlScript.
COMMANDS = {
    0: "NO_CMD",
    1: "MOVEJ",
    2: "MOVEJ_IK",
    3: "MOVEL",
    4: "MOVEL_FK",
    6: "FORCE_MODE",
    7: "FORCE_MODE_STOP",
    8: "ZERO_FT_SENSOR",
    9: "SPEEDJ",
    10: "SPEEDL",
    11: "SERVOJ",
    12: "SERVOC",
    15: "SPEED_STOP",
    16: "SERVO_STOP",
    17: "SET_PAYLOAD",
    18: "TEACH_MODE",
    19: "END_TEACH_MODE",
    20: "FORCE_MODE_SET_DAMPING",
    21: "FORCE_MODE_SET_GAIN_SCALING",
    24: "SERVOL",
    25: "TOOL_CONTACT",
    26: "GET_STEPTIME",
    27: "GET_ACTUAL_JOINT_POSITIONS_HISTORY",
    28: "GET_TARGET_WAYPOINT",
    29: "SET_TCP",
    30: "GET_INVERSE_KINEMATICS_ARGS",
    31: "PROTECTIVE_STOP",
    33: "STOPL",
    34: "STOPJ",
    35: "SET_WATCHDOG",
    36: "IS_POSE_WITHIN_SAFETY_LIMITS",
    37: "IS_JOINTS_WITHIN_SAFETY_LIMITS",
    38: "GET_JOINT_TORQUES",
    39: "POSE_TRANS",
    40: "GET_TCP_OFFSET",
    47: "IS_STEADY",
    58: "GET_ACTUAL_TOOL_FLANGE_POSE",
    255: "STOP_SCRIPT",
}
#: The codes the script's main loop treats as real-time (processed every cycle, no done signal):
#: the list in ur_rtde 1.6.5's rtde_control.script.
REAL_TIME = frozenset({24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})

READY = 1
DONE = 2


@dataclass
class RegisterFile:
    """The controller's general-purpose registers (48 int and 48 double, inputs and outputs)."""

    input_int: list[int] = field(default_factory=lambda: [0] * 48)
    input_double: list[float] = field(default_factory=lambda: [0.0] * 48)
    output_int: list[int] = field(default_factory=lambda: [0] * 48)
    output_double: list[float] = field(default_factory=lambda: [0.0] * 48)

    def write_input(self, name: str, value: object) -> bool:
        """Store an RTDE input field; False when it is not a register (an output, an I/O)."""
        for prefix, regs in (("input_int_register_", self.input_int), ("input_double_register_", self.input_double)):
            if name.startswith(prefix):
                regs[int(name[len(prefix) :])] = value  # type: ignore[call-overload]
                return True
        return False

    def read(self, name: str) -> object:
        """An RTDE field that is a register (input or output), by name."""
        for prefix, regs in (
            ("input_int_register_", self.input_int),
            ("input_double_register_", self.input_double),
            ("output_int_register_", self.output_int),
            ("output_double_register_", self.output_double),
        ):
            if name.startswith(prefix):
                return regs[int(name[len(prefix) :])]
        raise KeyError(name)


@dataclass(frozen=True)
class Program:
    """A URScript program as received on a script port.

    name : its ``def name():``.  text : the whole program.  is_control_script : it is
    ur_rtde's ``rtde_control`` (the one program the simulator runs).  offset : its register
    offset (0 or 24).
    """

    name: str
    text: str
    is_control_script: bool
    offset: int

    def calls(self, function: str) -> bool:
        """Whether the program calls the URScript ``function`` (its version-gated line survived)."""
        return re.search(rf"\b{re.escape(function)}\s*\(", self.text) is not None


_DEF = re.compile(r"^def\s+(\w+)\s*\(\s*\)\s*:", re.MULTILINE)
_OFFSET = re.compile(r"# float register offset\s*\n\s*(\d+)")


def parse_program(text: str) -> Program | None:
    """The program in ``text`` (a ``def …():`` block ending in ``end``), or None when it is not one.

    Raises :class:`ValueError` when the control script's register offset is not 0 or 24.
    """
    m = _DEF.search(text)
    if m is None or not text.rstrip().endswith("end"):
        return None
    control = m.group(1) == "rtde_control" and "RTDE Control Script" in text
    offset = 0
    if control:
        o = _OFFSET.search(text)
        offset = int(o.group(1)) if o else 0
        if offset not in (0, 24):
            raise ValueError(f"the control script's register offset is {offset}, not 0 or 24")
    return Program(m.group(1), text, control, offset)


class ControlScript:
    """One run of ur_rtde's control script (module docstring): :meth:`cycle` once per controller cycle.

    Parameters
    ----------
    program : the received control script.
    regs : the controller's registers.
    arm : the arm the script's motion commands move.
    step_time : the controller period [s] (what ``get_steptime()`` returns).
    on_watchdog : called with (variable name, minimum frequency [Hz]) by ``rtde_set_watchdog``.
    on_protective_stop : called by ``protective_stop()``.
    """

    def __init__(
        self,
        program: Program,
        regs: RegisterFile,
        arm: SimArm,
        step_time: float,
        on_watchdog: Callable[[str, float], None],
        on_protective_stop: Callable[[], None],
    ) -> None:
        self.program, self.regs, self.arm, self.step_time = program, regs, arm, step_time
        self.on_watchdog, self.on_protective_stop = on_watchdog, on_protective_stop
        self.off = program.offset
        self.running = True
        self.executing = False
        self._started = False
        self._blocking: Callable[[], bool] | None = None
        self._async_finished = -2
        #: command codes received that the simulator does not emulate (name → times)
        self.unsupported: dict[str, int] = {}
        #: every command code processed, in order (real-time ones once per change of code)
        self.processed: list[int] = []
        self._last_rt: int | None = None
        self._async_watch: Callable[[], bool] | None = None  # an asynchronous move's end

    # -- registers, with the program's offset
    def _in_int(self, i: int) -> int:
        return int(self.regs.input_int[i + self.off])

    def _in_f(self, i: int) -> float:
        return float(self.regs.input_double[i + self.off])

    def _in_vec(self, i: int, n: int = 6) -> list[float]:
        return [self._in_f(i + k) for k in range(n)]

    def _out_int(self, i: int, v: int) -> None:
        self.regs.output_int[i + self.off] = int(v)

    def _out_f(self, i: int, v: float) -> None:
        self.regs.output_double[i + self.off] = float(v)

    def _out_vec(self, i: int, values) -> None:
        for k, v in enumerate(values):
            self._out_f(i + k, float(v))

    def _async_done(self) -> None:
        # signal_async_operation_finished: output_int_register_2 toggles -1/-2 (not offset: the script writes 2)
        self._async_finished = -2 if self._async_finished == -1 else -1
        self.regs.output_int[2] = self._async_finished

    # -- the main loop
    def cycle(self) -> None:
        """One iteration of the script's main loop (module docstring); sets :attr:`running` False when it ends."""
        if not self.running:
            return
        if not self._started:  # the lines before the loop: reset_async_progress(); signal_ready()
            self._started = True
            self._async_finished = -2
            self._async_done()
            self._out_int(0, READY)
            return
        if self._blocking is not None:
            if not self._blocking():
                return  # the blocking URScript call holds the loop
            self._blocking = None
            self._out_int(0, DONE)
            self.executing = True
            return
        cmd = self._in_int(0)
        if cmd in REAL_TIME:
            if cmd != self._last_rt:
                self.processed.append(cmd)
            self._last_rt = cmd
            self.running = self._process(cmd)
            self._out_int(0, READY)
            return
        self._last_rt = None
        if cmd == 0:
            self.executing = False
            self._out_int(0, READY)
            return
        if not self.executing:
            self.processed.append(cmd)
            self.running = self._process(cmd)
            if not self.running:
                return
            if self._blocking is None:
                self._out_int(0, DONE)
        self.executing = True

    def _block_until(self, done: Callable[[], bool]) -> None:
        self._blocking = done

    def _process(self, cmd: int) -> bool:
        """process_cmd of the script: False ends the program (stopScript)."""
        arm, p = self.arm, self.program
        if cmd == 9:  # speedJ: qd (0-5), acceleration (6), time (7)
            arm.speedj(self._in_vec(0), self._in_f(6))
        elif cmd == 10:  # speedL
            arm.speedl(self._in_vec(0), self._in_f(6))
        elif cmd == 11:  # servoJ: q (0-5), v, a, time, lookahead (9), gain
            arm.servoj(self._in_vec(0), self._in_f(9))
        elif cmd == 6:  # forceMode: type (int 1), selection (int 2-7); frame (0-5), wrench (6-11), limits (12-17)
            selection = [self._in_int(2 + k) for k in range(6)]
            arm.force_mode(self._in_vec(0), selection, self._in_vec(6), self._in_vec(12))
        elif cmd == 26:  # getStepTime
            if p.calls("get_steptime"):
                self._out_f(0, self.step_time)
        elif cmd in (1, 3, 4):  # moveJ / moveL / moveL_FK: target (0-5), speed (6), acceleration (7), async (int 1)
            target, v, a = self._in_vec(0), self._in_f(6), self._in_f(7)
            if cmd == 1:
                arm.movej(target, v, a)
            elif cmd == 3:
                arm.movel(target, v, a)
            else:
                arm.movel(_fk_pose(arm, target).tolist(), v, a)
            if self._in_int(1) == 1:  # async: the move thread runs, the loop goes on
                self.regs.output_int[2] = 0

                def finished() -> bool:
                    if arm.move_done:
                        self._async_done()
                        return True
                    return False

                self._async_watch = finished
            else:
                self._block_until(lambda: arm.move_done)
        elif cmd == 7:  # forceModeStop: end_force_mode(); stopl(10)
            arm.end_force_mode()
            arm.stop(10.0, linear=True)
            self._block_until(lambda: arm.at_rest)
        elif cmd == 8:
            if p.calls("zero_ftsensor"):
                arm.zero_ftsensor()
        elif cmd in (15, 16):  # speedStop / servoStop: decelerate (0), blocking until at rest
            linear = cmd == 16 or arm.mode == "speedl"
            arm.stop(self._in_f(0), linear=linear)
            self._block_until(lambda: arm.at_rest)
        elif cmd in (33, 34):  # stopL / stopJ: deceleration (0), async (int 1)
            arm.stop(self._in_f(0), linear=cmd == 33)
            if self._in_int(1) != 1:
                self._block_until(lambda: arm.at_rest)
        elif cmd == 17:  # setPayload: mass (0), cog (1-3); a zero cog keeps the present one
            cog = self._in_vec(1, 3)
            arm.set_payload(self._in_f(0), None if not any(cog) else cog)
        elif cmd == 29:  # setTcp
            arm.set_tcp(self._in_vec(0))
        elif cmd == 40:  # getTCPOffset
            if p.calls("get_tcp_offset"):
                self._out_vec(0, arm.tcp_offset)
        elif cmd == 31:
            if p.calls("protective_stop"):
                self.on_protective_stop()
        elif cmd == 35:  # setWatchdog: min frequency (0), on input_int_register_<offset>
            if p.calls("rtde_set_watchdog"):
                self.on_watchdog(f"input_int_register_{self.off}", self._in_f(0))
        elif cmd == 47:  # isSteady
            self._out_int(1, 1 if arm.at_rest else 0)
        elif cmd == 255:
            return False
        else:
            name = COMMANDS.get(cmd, f"command {cmd}")
            if name not in self.unsupported:
                log.warning("ur-sim: %s (%d) is not emulated; the script answers done without moving", name, cmd)
            self.unsupported[name] = self.unsupported.get(name, 0) + 1
        return True

    def background(self) -> None:
        """Threads of the script that run beside its loop (an asynchronous move's end)."""
        if self._async_watch is not None and self._async_watch():
            self._async_watch = None


def _fk_pose(arm: SimArm, q) -> np.ndarray:
    """The TCP pose at joints ``q`` (movel_fk's target), by the arm's own kinematics."""
    saved = arm.q_ref.copy()
    arm.q_ref = np.asarray(q, dtype=float)
    try:
        return arm.target_tcp_pose()
    finally:
        arm.q_ref = saved
