"""The phase search's window distances (coassist.scenario.curve_search.window_distances)."""

from __future__ import annotations

import numpy as np

from coassist.scenario.curve_search import CurveSearch, window_distances


def test_window_distances_are_the_plain_expression_bit_for_bit_and_a_new_array():
    """(x − px)² + (y − py)² of the gathered window, as fancy indexing and temporaries compute it, on every element:
    random curves with repeated points (ties), NaN and ±inf samples and a tool at NaN or ±inf; the tables untouched."""
    rng = np.random.default_rng(4)
    n, p, widest = 7, 40, 5
    x, y = rng.normal(0.0, 0.1, n * p), rng.normal(0.0, 0.1, n * p)
    x[10:14], y[10:14] = x[10], y[10]  # a repeated point: ties
    y[3::11] = np.nan
    x[5], y[17] = np.inf, -np.inf
    pad_x, pad_y, first, window, _ = CurveSearch(x, y, n, p).tables(widest)
    before = pad_x.copy(), pad_y.copy()
    for trial in range(200):
        idx = rng.integers(0, p, n)
        flat = (first + idx)[:, None] + window
        px, py = (float(v) for v in rng.normal(0.0, 0.1, 2))
        if trial % 50 == 1:
            px = (np.nan, np.inf, -np.inf, 0.0)[trial // 50]
        with np.errstate(invalid="ignore"):
            want = (pad_x[flat] - px) * (pad_x[flat] - px) + (pad_y[flat] - py) * (pad_y[flat] - py)
            got = window_distances(pad_x, pad_y, flat, px, py)
        assert got.tobytes() == want.tobytes()  # NaN for NaN, the same bits elsewhere
        assert not np.shares_memory(got, pad_x) and not np.shares_memory(got, pad_y)
    np.testing.assert_array_equal(pad_x, before[0])
    np.testing.assert_array_equal(pad_y, before[1])
