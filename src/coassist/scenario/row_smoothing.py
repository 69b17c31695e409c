"""The predicted rows low-passed in time, with the filter's lag given back by advancing them.

An intent source's rows R(t) (H, 2) are re-estimated every tick from noisy measurements (the
hand force, the tool's speed, a phase on a curve), so a row of tick t and the same instant's row
of tick t + dt differ by noise as well as by motion; the robot's effort follows those jumps and the
tool's jerk with it. A first-order low-pass of each row over time::

    R̄(t) = R̄(t − dt) + g·(R(t) − R̄(t − dt)),     g = 1 − exp(−dt/τ)

removes the tick-to-tick noise, and lags a row moving at a steady rate by L = (1 − g)/g ticks
(≈ τ/dt − 1/2: the discrete filter's lag on a ramp). The rows are therefore handed on advanced
by m = round(L) rows: row i is R̄'s row i + m, and the last m rows carry R̄'s last step on. On a
path followed at a steady speed the result equals R(t) (to a rounding of the lag); what is
removed is what changes faster than τ.
"""

from __future__ import annotations

import math

import numpy as np

from coassist._checks import check_int, check_real

__all__ = ["RowSmoothing"]


class RowSmoothing:
    """Low-pass of predicted rows over time with its lag advanced away (module docstring).

    Parameters
    ----------
    dt : the control period [s] (one row per period, and one call per period).
    time_constant : τ [s]; 0 hands every row on as it is.
    horizon : rows H of each call; the advance m is kept to H − 2 at most (the last step needs two rows;
        with one row nothing is advanced).
    """

    def __init__(self, dt: float, time_constant: float, horizon: int) -> None:
        self.dt = check_real(dt, "RowSmoothing.dt", 0.0, 1.0, open_lo=True)
        self.time_constant = check_real(time_constant, "RowSmoothing.time_constant", 0.0, 2.0)
        self.horizon = check_int(horizon, "RowSmoothing.horizon", 1)
        if self.time_constant > 0.0:
            self.gain = 1.0 - math.exp(-self.dt / self.time_constant)
            self.lag = (1.0 - self.gain) / self.gain  # ticks a steady ramp lags behind
        else:
            self.gain, self.lag = 1.0, 0.0
        self.advance = max(0, min(int(round(self.lag)), self.horizon - 2))
        self._ahead = np.arange(1, self.advance + 1, dtype=float)[:, None]
        self._state: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the past rows (a new trial)."""
        self._state = None

    def __call__(self, rows: np.ndarray) -> np.ndarray:
        """The rows (H, d) of this tick, low-passed and advanced: (H, d)."""
        if self.gain >= 1.0:
            return rows
        state = self._state
        if state is None:
            self._state = state = np.array(rows, dtype=float)
        else:
            step = rows - state
            step *= self.gain
            state += step
        m = self.advance
        if m == 0:
            return state.copy()
        out = np.empty_like(state)
        out[:-m] = state[m:]
        last = state[-1]
        np.multiply(last - state[-2], self._ahead, out=out[-m:])
        out[-m:] += last
        return out
