"""The browser as the hand: a pointer pulls the tool through a virtual spring-damper.

The person drags a pointer (mouse, touch or gamepad) on the page; the pointer is where
their virtual hand is. Their arm is a spring-damper between that point and the handle
(the thesis' arm model, eq. 4.1, with the pointer as the desired position)::

    u_h = K_s (p − x) − C_s ẋ,    scaled (not clipped per axis) to ‖u_h‖ ≤ F_max

p (2,) the pointer [m], x, ẋ (2,) the handle's position and velocity [m, m/s],
K_s [N/m], C_s [N·s/m]. u_h is the wrench the loop measures at the sensor.

The hand lets go — u_h = 0, never the last force frozen — when the pointer is up, when
no pointer message arrived for ``stale_after`` seconds (the page sends a heartbeat while
the button is held, so a hung tab or a dropped link lets go), or when the link closed.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from coassist._checks import check_positive_scalar, is_real_number

__all__ = ["BrowserHand", "SpringDamper"]


@dataclass(frozen=True)
class SpringDamper:
    """The virtual arm between the pointer and the handle (module docstring).

    stiffness : K_s [N/m]; 400 N/m pulls with 4 N per cm of lag.
    damping : C_s [N·s/m]; with the preset's plant (M = 10 kg, D = 100 N·s/m) 40 N·s/m
        makes the pointer-to-tool response about critically damped (ζ ≈ 1.1).
    force_limit : F_max [N], the largest hand force (the simulated operators': 40 N).
    stale_after : [s] without a pointer message after which the hand lets go.
    """

    stiffness: float = 400.0
    damping: float = 40.0
    force_limit: float = 40.0
    stale_after: float = 0.25

    def __post_init__(self) -> None:
        for name in ("stiffness", "force_limit", "stale_after"):
            object.__setattr__(self, name, check_positive_scalar(getattr(self, name), f"SpringDamper.{name}"))
        c = self.damping
        if not is_real_number(c) or not math.isfinite(c) or c < 0.0:
            raise ValueError(f"SpringDamper.damping must be a finite number >= 0 [N·s/m], got {c!r}")
        object.__setattr__(self, "damping", float(c))

    def force(self, pointer: tuple[float, float], x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """u_h (module docstring) for a held pointer [N]."""
        fx = self.stiffness * (pointer[0] - x) - self.damping * vx
        fy = self.stiffness * (pointer[1] - y) - self.damping * vy
        norm = math.hypot(fx, fy)
        if norm > self.force_limit:
            s = self.force_limit / norm
            fx, fy = fx * s, fy * s
        return fx, fy


class BrowserHand:
    """A :class:`~coassist.runtime.world.HandOperator` driven by pointer messages from the page.

    The server thread calls :meth:`set_pointer` (and :meth:`release` when the link
    closes); the control loop's world calls :meth:`force` once per period. The two
    share one immutable tuple swapped under a lock, so the loop never sees half an update.

    Attributes
    ----------
    seq : the sequence number of the pointer message behind the last force (the page
        uses it to time pointer event → frame drawn).
    """

    def __init__(self, arm: SpringDamper | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.arm = arm or SpringDamper()
        self._clock = clock
        self._lock = threading.Lock()
        self._pointer: tuple[float, float, bool, int, float] = (0.0, 0.0, False, -1, -math.inf)
        self.seq = -1
        self.held = False

    def set_pointer(self, x: float, y: float, down: bool, seq: int) -> None:
        """A validated pointer message: position [m] in the task plane, button held, sequence number."""
        with self._lock:
            self._pointer = (float(x), float(y), bool(down), int(seq), self._clock())

    def release(self) -> None:
        """The link closed: let go now."""
        with self._lock:
            x, y, _, seq, _ = self._pointer
            self._pointer = (x, y, False, seq, -math.inf)

    def pointer(self) -> tuple[float, float, bool, int, float]:
        """(x, y, down, seq, received) of the last pointer message."""
        with self._lock:
            return self._pointer

    def force_xy(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """u_h [N] on the handle at (x, y) moving at (vx, vy): zero unless held and fresh."""
        px, py, down, seq, received = self.pointer()
        self.seq = seq
        self.held = down and self._clock() - received <= self.arm.stale_after
        if not self.held:
            return 0.0, 0.0
        return self.arm.force((px, py), x, y, vx, vy)

    def force(self, t: float, hand_pose: np.ndarray, hand_twist: np.ndarray) -> np.ndarray:
        """The HandOperator protocol: (6,) wrench [N, N·m] in the base frame."""
        fx, fy = self.force_xy(float(hand_pose[0]), float(hand_pose[1]), float(hand_twist[0]), float(hand_twist[1]))
        return np.array((fx, fy, 0.0, 0.0, 0.0, 0.0))
