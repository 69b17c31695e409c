"""Hand operators that need no model of a person: scripted force profiles for tests and demos.

A :class:`~coassist.runtime.world.HandOperator` returns the (6,) wrench the hand applies
at the handle, base frame [N, N·m]. The simulated operator lives with the simulator
(:class:`coassist.scenario.hand.SimulatedHand`); a person in a browser is another one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["ScriptedForce"]


class ScriptedForce:
    """A hand whose wrench is a function of time only: f(t) (6,) [N, N·m], base frame.

    Build with :meth:`constant` or :meth:`steps`, or give any function of t [s]. A
    profile that raises or returns anything but 6 finite numbers gives zero (the hand
    lets go) — worlds apply that rule too, this only keeps scripts honest.
    """

    def __init__(self, profile: Callable[[float], ArrayLike]) -> None:
        if not callable(profile):
            raise ValueError(f"profile must be a function of time, got {type(profile).__name__}")
        self._profile = profile

    @classmethod
    def constant(cls, wrench: ArrayLike) -> ScriptedForce:
        """The same wrench at all times (e.g. (10, 0, 0, 0, 0, 0): 10 N along x)."""
        w = _wrench(wrench, "wrench")
        return cls(lambda t: w)

    @classmethod
    def steps(cls, schedule: Sequence[tuple[float, ArrayLike]]) -> ScriptedForce:
        """Piecewise constant: [(t0, w0), (t1, w1), …] holds w_i from t_i on (zero before t0)."""
        times = [float(t) for t, _ in schedule]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError(f"schedule times must increase, got {times}")
        values = [_wrench(w, f"schedule[{i}]") for i, (_, w) in enumerate(schedule)]
        zero = np.zeros(6)

        def profile(t: float) -> np.ndarray:
            i = int(np.searchsorted(times, t, side="right")) - 1
            return zero if i < 0 else values[i]

        return cls(profile)

    def force(self, t: float, hand_pose: np.ndarray, hand_twist: np.ndarray) -> np.ndarray:
        try:
            w = np.asarray(self._profile(float(t)), dtype=float)
        except Exception:
            return np.zeros(6)
        if w.shape != (6,) or not np.isfinite(w).all():
            return np.zeros(6)
        return w


def _wrench(value: ArrayLike, name: str) -> np.ndarray:
    try:
        w = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 6 numbers [N, N·m], got {value!r}") from None
    if w.shape != (6,) or not np.isfinite(w).all():
        raise ValueError(f"{name} must be 6 finite numbers [N, N·m], got {value!r}")
    w.setflags(write=False)
    return w
