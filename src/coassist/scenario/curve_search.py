"""The tables of the phase search both path filters run each tick: each curve's nearest sample to the tool
within a window of ±``widest`` samples of its last one.

Curves sampled alike (N curves of P samples, x and y flat: curve n's sample i at n·P + i) are padded with
``widest`` copies of their end points at either end, so the window of sample i of curve n is the run of
2·widest + 1 padded samples from n·(P + 2·widest) + i: no clipping per tick, and the copies are what a clipped
index reads (the same distances, the first least of them at the same sample).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SearchTables", "search_tables"]

#: (padded x (N·(P + 2·widest),), padded y (same), each curve's first padded index (N,), the window's offsets
#: (2·widest + 1,), the sample within its curve each padded index stands for (N·(P + 2·widest),)).
SearchTables = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def search_tables(flat_x: np.ndarray, flat_y: np.ndarray, n_curves: int, n_points: int, widest: int) -> SearchTables:
    """The padded tables (module docstring) of N = ``n_curves`` curves of P = ``n_points`` samples each."""
    width = n_points + 2 * widest
    local = np.minimum(np.maximum(np.arange(width) - widest, 0), n_points - 1)  # (P + 2·widest,)
    flat = ((np.arange(n_curves) * n_points)[:, None] + local[None, :]).ravel()
    return flat_x[flat], flat_y[flat], np.arange(n_curves) * width, np.arange(2 * widest + 1), np.tile(local, n_curves)
