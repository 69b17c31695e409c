"""Order effects in a Latin-square study: the position's F test beside the condition's and the participant's.

The paired statistics (tests, Holm's correction, effect sizes, bootstrap intervals) are
:mod:`coassist.analysis.paired`'s, shared with the main job's ablation and application. Here,
the position's effect is estimated beside the condition's and the participant's, by least squares::

    y_ij = μ + π_i (participant) + τ_c(ij) (condition) + ρ_j (position) + ε_ij

and tested with the F test of the position terms (full model against the model without
them). Condition × position interaction cannot be separated from the other terms in a
Latin square; the report shows the table of means per condition and position instead.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["order_effect"]


def order_effect(rows: Sequence[tuple[str, str, int, float]]) -> dict[str, Any]:
    """The position's F test in ``y ~ participant + condition + position`` (module docstring).

    rows : (participant, condition, position, value), one per participant and condition.
    Returns {F, df1, df2, p, means: {condition: {position: mean}}}; F and p NaN where the
    design leaves no degrees of freedom for the error or the position.
    """
    from scipy import stats

    rows = [r for r in rows if math.isfinite(r[3])]
    means: dict[str, dict[int, float]] = {}
    for c in sorted({r[1] for r in rows}):
        for pos in sorted({r[2] for r in rows}):
            vals = [r[3] for r in rows if r[1] == c and r[2] == pos]
            if vals:
                means.setdefault(c, {})[pos] = float(np.mean(vals))
    out: dict[str, Any] = {"F": math.nan, "df1": 0, "df2": 0, "p": math.nan, "means": means, "n": len(rows)}
    if not rows:
        return out
    y = np.array([r[3] for r in rows])

    def design(with_position: bool) -> np.ndarray:
        cols = [np.ones(len(rows))]  # treatment coding: each factor's first level is the baseline
        for key in (0, 1, 2) if with_position else (0, 1):
            levels = sorted({r[key] for r in rows})
            cols += [np.array([1.0 if r[key] == lv else 0.0 for r in rows]) for lv in levels[1:]]
        return np.column_stack(cols)

    def fit(X: np.ndarray) -> tuple[float, int]:
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        resid = y - X @ beta
        return float(resid @ resid), int(np.linalg.matrix_rank(X))

    rss_full, rank_full = fit(design(True))
    rss_red, rank_red = fit(design(False))
    df1, df2 = rank_full - rank_red, len(rows) - rank_full
    out.update(df1=df1, df2=df2)
    if df1 > 0 and df2 > 0 and rss_full > 0:
        F = ((rss_red - rss_full) / df1) / (rss_full / df2)
        out.update(F=float(F), p=float(stats.f.sf(F, df1, df2)))
    return out
