"""The tables of the phase search both path filters run each tick: each curve's nearest sample to the tool
within a window of ±``widest`` samples of its last one.

Curves sampled alike (N curves of P samples, x and y flat: curve n's sample i at n·P + i) are padded with
``widest`` copies of their end points at either end, so the window of sample i of curve n is the run of
2·widest + 1 padded samples from n·(P + 2·widest) + i: no clipping per tick, and the copies are what a clipped
index reads (the same distances, the first least of them at the same sample).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CurveSearch", "SearchTables", "window_distances"]

#: (padded x (N·(P + 2·widest),), padded y (same), each curve's first padded index (N,), the window's offsets
#: (2·widest + 1,), the sample within its curve each padded index stands for (N·(P + 2·widest),)).
SearchTables = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def window_distances(pad_x: np.ndarray, pad_y: np.ndarray, flat: np.ndarray, px: float, py: float) -> np.ndarray:
    """(x − px)² + (y − py)² [m²] of the padded samples ``flat`` (N, 2·widest + 1) indexes: each curve's window's
    squared distances from the tool (px, py), a new array. Gathered with ``take`` and squared in place: the same
    operations on the same numbers as fancy indexing and temporaries, a third less time (docs/performance.md)."""
    d2 = pad_x.take(flat)
    d2 -= px
    d2 *= d2
    dy = pad_y.take(flat)
    dy -= py
    dy *= dy
    d2 += dy
    return d2


class CurveSearch:
    """The padded tables (module docstring) of N = ``n_curves`` curves of P = ``n_points`` samples each, x and y
    flat (``flat_x``, ``flat_y``): built once per window width and kept with the curves (the person model's are
    shared by every trial of a person; the path hypotheses' are a trial's)."""

    def __init__(self, flat_x: np.ndarray, flat_y: np.ndarray, n_curves: int, n_points: int) -> None:
        self.flat_x, self.flat_y, self.n_curves, self.n_points = flat_x, flat_y, n_curves, n_points
        self._tables: dict[int, SearchTables] = {}

    def tables(self, widest: int) -> SearchTables:
        """The tables of a window of ±``widest`` samples."""
        if widest not in self._tables:
            n, p = self.n_curves, self.n_points
            width = p + 2 * widest
            local = np.minimum(np.maximum(np.arange(width) - widest, 0), p - 1)  # (P + 2·widest,)
            flat = ((np.arange(n) * p)[:, None] + local[None, :]).ravel()
            self._tables[widest] = (
                self.flat_x[flat],
                self.flat_y[flat],
                np.arange(n) * width,
                np.arange(2 * widest + 1),
                np.tile(local, n),
            )
        return self._tables[widest]
