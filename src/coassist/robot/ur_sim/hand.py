"""coassist's own commands on the simulator's dashboard port: the simulated operator at the handle, a start pose.

A UR controller answers every one of these ``could not understand: …``, so a client can ask
``coassist hello`` to tell the simulator from a robot. The simulator (one line in, one out):

===================================  ==========================================================
``coassist hello``                   ``coassist ur-sim <series> <rate> Hz``
``coassist start X Y Z``             the arm put at rest with its TCP at (X, Y, Z) [m], the tool
                                     down (a reset, not a motion; refused while the arm moves)
``coassist handle``                  the handle's pose and twist: 12 numbers (base frame)
``coassist hand <JSON>``             :meth:`SimulatedHand.to_dict <coassist.scenario.hand.SimulatedHand.to_dict>`'s
                                     hand held at the handle, still (its first tick on ``go``)
``coassist hand go``                 the hand's tick 0 is the next controller cycle
``coassist hand off``                the hand lets go
===================================  ==========================================================

The hand is asked once per its own tick (its ``dt``, the client's control period) at the
simulated time the tick falls on, its wrench held in between, as the MuJoCo world asks it
once per control period. Its ticks fall on the controller cycles whose state the client's
ticks read: ``go`` arrives just before the client's first period opens (coassist's UR world
sends it there), so the client's tick k reads the state of the cycle ``go`` arrived in plus
k periods, and the hand's tick k is that cycle's (its tick 0, already past, is asked at the
next cycle). So at each tick the hand and the loop see the same state and the loop reads the
hand's wrench one tick later, as in the MuJoCo world (measured, 500 Hz: with the hand's ticks
a cycle after the loop's state, the defaults' trial ran 2 ms behind MuJoCo's, 0.3 mm of its track).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from coassist.robot.ur_sim.controller import Controller
from coassist.scenario.hand import SimulatedHand

__all__ = ["TickedHand", "reply"]


class TickedHand:
    """A :class:`~coassist.scenario.hand.SimulatedHand` asked once per its own tick of simulated time.

    hand : the hand.  Until :meth:`go` it applies nothing.
    lead : [s] how long before its first call (the cycle after ``go``) the hand's ticks start: the
        controller's period, so they fall on the cycle ``go`` arrived in and every hand period after it
        (module docstring). Tick 0 is then asked late, at the first call; at a lead of one hand period
        or more (a CB3, 8 ms, at 125 Hz) ticks 0 and 1 are both asked at the first call.
    """

    def __init__(self, hand: SimulatedHand, lead: float = 0.0) -> None:
        self.hand = hand
        self.lead = float(lead)
        self.t0: float | None = None
        self._start = False
        self.ticks = 0
        self._w = np.zeros(6)

    def go(self) -> None:
        self._start = True

    def force(self, t: float, hand_pose: np.ndarray, hand_twist: np.ndarray) -> np.ndarray:
        if self.t0 is None:
            if not self._start:
                return np.zeros(6)
            self.t0 = t - self.lead
        due = math.floor((t - self.t0) / self.hand.dt + 1e-9)
        while self.ticks <= due:
            self._w = self.hand.force(t, hand_pose, hand_twist)
            self.ticks += 1
        return self._w


def reply(controller: Controller, series: str, line: str) -> str:
    """The reply to one ``coassist …`` dashboard line (module docstring)."""
    parts = line.strip().split(maxsplit=2)
    what = parts[1].lower() if len(parts) > 1 else ""
    arm = controller.arm
    if what == "hello":
        return f"coassist ur-sim {series} {controller.rate:g} Hz"
    if what == "start":
        try:
            xyz = [float(v) for v in (parts[2].split() if len(parts) > 2 else [])]
        except ValueError:
            xyz = []
        if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
            return "error: coassist start takes X Y Z [m]"
        with controller.lock:
            if arm.moving:
                return "error: the arm is moving"
            try:
                arm.teleport(xyz)
            except ValueError as exc:
                return f"error: {exc}"
        return "ok"
    if what == "handle":
        with controller.lock:
            pose, twist = arm.world.hand_pose()
        return " ".join(repr(float(v)) for v in (*pose, *twist))
    if what == "hand":
        rest = parts[2].strip() if len(parts) > 2 else ""
        with controller.lock:
            if rest == "off":
                arm.operator = None
                return "ok"
            if rest == "go":
                op = arm.operator
                if not isinstance(op, TickedHand):
                    return "error: no hand to start (send coassist hand <JSON> first)"
                op.go()
                return "ok"
        try:
            data: Any = json.loads(rest)
            hand = SimulatedHand.from_dict(data)
        except (ValueError, TypeError) as exc:
            return f"error: {exc}"
        with controller.lock:
            arm.operator = TickedHand(hand, lead=controller.dt)
        return "ok"
    return f"could not understand: '{line.strip()}'"
