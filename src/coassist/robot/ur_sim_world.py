"""The ``ur`` world when the controller is ``coassist ur-sim``: the simulated operator at its handle.

:func:`build_world` (the ``ur`` entry of :data:`coassist.robot.worlds.WORLDS`) asks the
dashboard ``coassist hello``; a real controller does not know the command
(``could not understand``) and gets :class:`~coassist.robot.ur_rtde_world.URRTDEWorld` as ever.
The simulator gets :class:`URSimWorld`: the same world, the same ur-rtde client and protocol,
and besides it a :class:`~coassist.robot.worlds.HandWorld`: the drive puts its simulated
operator (:class:`~coassist.scenario.hand.SimulatedHand`) at the simulated handle, sent over
the dashboard port as JSON (:mod:`coassist.robot.ur_sim.hand`), and the arm starts each run at
the task's start (a reset of the simulation, not a motion). So studies and drives with
simulated participants run on ``--world ur`` through the simulator as on ``--world mujoco``.
"""

from __future__ import annotations

import json
import socket
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

from coassist.robot.ur_rtde_world import URRTDEWorld
from coassist.robot.worlds import WorldRequest
from coassist.runtime.world import Command, HandOperator, RobotLinkError

__all__ = ["URSimWorld", "build_world", "is_simulator"]

DASHBOARD_PORT = 29999


class _Dashboard:
    """One dashboard connection: a line out, a line back."""

    def __init__(self, host: str, timeout: float = 2.0) -> None:
        self.sock = socket.create_connection((host, DASHBOARD_PORT), timeout=timeout)
        self.file = self.sock.makefile("rwb")
        self.file.readline()  # the greeting
        self.lock = threading.Lock()

    def ask(self, line: str) -> str:
        with self.lock:
            self.file.write(line.encode() + b"\n")
            self.file.flush()
            return self.file.readline().decode("utf-8", errors="replace").strip()

    def close(self) -> None:
        try:
            self.file.close()
        except OSError:  # a dropped connection: nothing left to flush to (a broken pipe lost drive's trial)
            pass
        finally:
            self.sock.close()


def is_simulator(host: str, timeout: float = 1.0) -> bool:
    """Whether ``host``'s dashboard is ``coassist ur-sim``'s (a robot's does not know ``coassist hello``)."""
    try:
        board = _Dashboard(host, timeout)
    except OSError:
        return False
    try:
        return board.ask("coassist hello").startswith("coassist ur-sim")
    except OSError:
        return False
    finally:
        board.close()


class URSimWorld(URRTDEWorld):
    """:class:`~coassist.robot.ur_rtde_world.URRTDEWorld` on ``coassist ur-sim``, with its handle (module docstring).

    Parameters
    ----------
    host : the simulator's address.
    start : (3,) where the TCP starts [m] (the tool down); None: where it is.
    frequency : the loop's rate [Hz] (URRTDEWorld's).
    acceleration : speedJ's [rad/s²] (URRTDEWorld's).
    """

    def __init__(
        self, host: str, *, start: Sequence[float] | None = None, frequency: float = -1.0, acceleration: float = 8.0
    ) -> None:
        self._board = _Dashboard(host)
        self._operator: HandOperator | None = None
        self._go = False
        try:
            if start is not None:
                answer = self._board.ask("coassist start " + " ".join(repr(float(v)) for v in start))
                if answer != "ok":
                    raise RobotLinkError(f"the simulator at {host} could not start at {list(start)}: {answer}")
            super().__init__(host, frequency=frequency, acceleration=acceleration)
        except BaseException:
            self._board.close()
            raise

    @property
    def operator(self) -> HandOperator | None:
        """The hand at the simulated handle: a :class:`~coassist.scenario.hand.SimulatedHand` not yet used, or None."""
        return self._operator

    @operator.setter
    def operator(self, value: HandOperator | None) -> None:
        if value is None:
            self._ask("coassist hand off")
        else:
            to_dict = getattr(value, "to_dict", None)
            if not callable(to_dict):
                raise ValueError(
                    f"the simulator holds coassist's simulated operator (a SimulatedHand) at its handle, not a "
                    f"{type(value).__name__}"
                )
            self._ask("coassist hand " + json.dumps(to_dict()))
            self._go = True
        self._operator = value

    def _ask(self, line: str) -> str:
        try:
            answer = self._board.ask(line)
        except OSError as exc:
            raise RobotLinkError(f"lost the simulator's dashboard at {self.host} ({exc})") from exc
        if answer.startswith(("error", "could not understand")):
            raise RobotLinkError(f"the simulator at {self.host} refused {line.split(' {')[0]!r}: {answer}")
        return answer

    def hand_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The simulated handle's pose (6,) and twist (6,) in the base frame."""
        values = np.array([float(v) for v in self._ask("coassist handle").split()])
        if values.shape != (12,):
            raise RobotLinkError(f"the simulator at {self.host} sent a handle pose of {values.size} numbers, not 12")
        return values[:6], values[6:]

    def _before_first_period(self) -> None:
        # The hand's first tick is the loop's first period: sent after the watchdog's round trip (12-18 ms
        # measured), not before it, else the hand ran that much (two ticks) ahead of the loop for the whole
        # run, 1 mm of the track at the trial's 0.1 m/s against the same trial in MuJoCo.
        if self._go:
            self._go = False
            self._ask("coassist hand go")

    def apply(self, command: Command) -> None:
        if self._go and self._t0 is not None:  # a hand given while the loop runs: from this period on
            self._before_first_period()
        super().apply(command)

    def close(self) -> None:
        try:
            if self._operator is not None:
                self._ask("coassist hand off")
        except RobotLinkError:
            pass
        finally:
            self._operator = None
            super().close()
            self._board.close()


def build_world(request: WorldRequest) -> Any:
    """The ``ur`` world of :data:`coassist.robot.worlds.WORLDS`: :class:`URSimWorld` at the run's start on
    ``coassist ur-sim``, else :class:`~coassist.robot.ur_rtde_world.URRTDEWorld` (a robot), at the run's rate."""
    host = request.host or ""  # "": URRTDEWorld names the missing host
    acc = request.joint_acceleration  # speedJ's ramp: as fast as the safety layer lets the command change
    if host and is_simulator(host):
        return URSimWorld(host, start=request.start, frequency=float(request.rate_hz), acceleration=acc)
    return URRTDEWorld(host, frequency=float(request.rate_hz), acceleration=acc)
