"""RowConstants (coassist._rows): the columns' rows as fancy indexing gives them, gathered once per set of rows."""

from __future__ import annotations

import numpy as np
import pytest

from coassist._rows import RowConstants


def test_take_is_fancy_indexing_and_is_gathered_again_only_for_other_rows():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=7), rng.normal(size=(7, 2))
    flags = rng.random(7) > 0.5
    constants = RowConstants((a, b, flags))
    rows = np.array([0, 2, 3, 6])
    first = constants.take(rows)
    for got, column in zip(first, (a, b, flags)):
        np.testing.assert_array_equal(got, column[rows])
        assert got.dtype == column.dtype
        assert not got.flags.writeable  # handed out again: no caller may change them
    # the same indices in another array (the runner builds a new one each tick): the same copies
    assert constants.take(rows.copy()) is first
    assert constants.take(np.array([0, 2, 3, 6], dtype=np.intp)) is first
    # other rows, another order, another dtype; int32 [1, 0] has intp [1]'s bytes: gathered again, right
    one = np.array([1], dtype=np.int64)
    same_bytes = np.array([1, 0], dtype=np.int32)
    assert one.tobytes() == same_bytes.tobytes()
    for other in (np.array([0, 2, 6]), np.array([2, 0, 3, 6]), np.array([0, 2, 3, 6], dtype=np.int32), one, same_bytes):
        got = constants.take(other)
        assert got is not first
        for g, column in zip(got, (a, b, flags)):
            np.testing.assert_array_equal(g, column[other])
    assert constants.take(np.zeros(0, dtype=np.intp))[1].shape == (0, 2)


def test_the_columns_become_read_only_and_must_be_arrays():
    a = np.arange(4.0)
    RowConstants((a,))
    with pytest.raises(ValueError, match="read-only"):
        a[0] = 1.0
    with pytest.raises(ValueError, match="numpy arrays"):
        RowConstants(([1.0, 2.0],))  # type: ignore[list-item]
