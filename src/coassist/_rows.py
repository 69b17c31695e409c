"""Per-run constants of an array twin, gathered for the rows still going once per set of rows.

The array twins of the point-mass tick (:mod:`coassist.sim.array_runner`) hold B runs' state
and constants as arrays of B rows and are called every tick with ``rows``, the indices of the
runs still going. A constant column c (B, …) is read as ``c[rows]``: a fancy-indexing copy,
a microsecond or so each, and a tick read some forty of them. The set of rows changes only
when a run ends (a few dozen times in thousands of ticks), so :class:`RowConstants` gathers
its columns once per set and hands back the same read-only copies while the set stays the same.
The values are those of ``c[rows]`` (a copy, exact), so nothing downstream changes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["RowConstants"]


class RowConstants:
    """Columns that never change after construction, gathered for a set of rows.

    Parameters
    ----------
    columns : arrays with the runs along their first axis (B, …). They are read-only from
        here on (``setflags(write=False)``): a twin that wrote into one would make the copies
        handed out stale.
    """

    def __init__(self, columns: Sequence[np.ndarray]) -> None:
        self._columns = tuple(columns)
        for c in self._columns:
            if not isinstance(c, np.ndarray):
                raise ValueError(f"RowConstants takes numpy arrays, got {type(c).__name__}")
            c.setflags(write=False)
        self._key: tuple | None = None
        self._taken: tuple[np.ndarray, ...] = ()

    def take(self, rows: np.ndarray) -> tuple[np.ndarray, ...]:
        """``tuple(c[rows] for c in columns)``, read-only, the same arrays while ``rows`` holds the
        same indices (compared by value: dtype, shape and bytes, so a caller may reuse or change
        its index array freely)."""
        key = (rows.dtype.str, rows.shape, rows.tobytes())
        if key != self._key:
            taken = tuple(c[rows] for c in self._columns)
            for t in taken:
                t.setflags(write=False)
            self._taken = taken
            self._key = key
        return self._taken
