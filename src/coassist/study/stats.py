"""Paired statistics for a small sample of participants: tests, Holm's correction, effect sizes, order.

Every comparison is within participants: for participant i and conditions a, b the values
are the means over that participant's measured trials, and the differences d_i = a_i − b_i.

- Wilcoxon signed-rank test (:func:`scipy.stats.wilcoxon`, two-sided, exact null distribution
  for n ≤ 50 without ties or zeros): nothing assumed about the shape of d. With n
  participants the smallest two-sided p it can give is 2/2ⁿ (n = 4: 0.125, n = 5: 0.0625):
  below six participants it cannot reach 0.05, whatever the data.
- Paired t test (:func:`scipy.stats.ttest_rel`): t = d̄ / (s_d/√n), n − 1 degrees of freedom;
  assumes d roughly normal, which a sample of four cannot check.
- Holm's step-down correction over a family of m tests (Holm 1979): with p sorted
  ascending, p̃_(i) = max_{j ≤ i} min(1, (m − j + 1) p_(j)); controls the family-wise error.
- Effect sizes: the mean difference d̄ (in the metric's unit), Cohen's d_z = d̄ / s_d, and the
  matched-pairs rank-biserial correlation r = (W⁺ − W⁻)/(W⁺ + W⁻) (Kerby 2014), each with a
  seeded percentile bootstrap interval (participants resampled with replacement; resamples
  where the statistic is undefined, e.g. s_d = 0, are left out and counted).
- Order effects (condition × position): in a Latin-square design the position's effect is
  estimated beside the condition's and the participant's, by least squares::

      y_ij = μ + π_i (participant) + τ_c(ij) (condition) + ρ_j (position) + ε_ij

  and tested with the F test of the position terms (full model against the model without
  them). Condition × position interaction cannot be separated from the other terms in a
  Latin square; the report shows the table of means per condition and position instead.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "PairedComparison",
    "bootstrap_interval",
    "cohen_dz",
    "cohen_dz_rows",
    "holm",
    "holm_family",
    "mean_rows",
    "order_effect",
    "paired_comparison",
    "rank_biserial",
    "rank_biserial_rows",
]


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm-adjusted p values, in the given order (module docstring); NaN stays NaN and is not counted."""
    p = np.asarray(pvalues, dtype=float)
    out = np.full(p.shape, math.nan)
    ok = np.flatnonzero(np.isfinite(p))
    m = ok.size
    running = 0.0
    for rank, i in enumerate(ok[np.argsort(p[ok], kind="stable")]):
        running = max(running, min(1.0, (m - rank) * p[i]))
        out[i] = running
    return [float(v) for v in out]


def rank_biserial(d: Sequence[float]) -> float:
    """(W⁺ − W⁻)/(W⁺ + W⁻) of the non-zero differences ranked by |d| (average ranks for ties); NaN if none."""
    return float(rank_biserial_rows(np.asarray(d, dtype=float)[None, :])[0])


def rank_biserial_rows(d: np.ndarray) -> np.ndarray:
    """:func:`rank_biserial` of every row of (B, n) ``d``. Zeros are dropped before ranking: ranked with the
    rest they take the z lowest (average) ranks, so a non-zero value's rank among the non-zero ones is its
    rank minus z."""
    from scipy.stats import rankdata

    d = np.atleast_2d(np.asarray(d, dtype=float))
    z = (d == 0).sum(axis=1, keepdims=True)
    r = rankdata(np.abs(d), axis=1) - z
    w_plus = np.where(d > 0, r, 0.0).sum(axis=1)
    w_minus = np.where(d < 0, r, 0.0).sum(axis=1)
    total = w_plus + w_minus
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, (w_plus - w_minus) / np.where(total > 0, total, 1.0), np.nan)


def cohen_dz(d: Sequence[float]) -> float:
    """d̄ / s_d (s_d with n − 1); NaN when fewer than two differences or s_d = 0."""
    return float(cohen_dz_rows(np.asarray(d, dtype=float)[None, :])[0])


def cohen_dz_rows(d: np.ndarray) -> np.ndarray:
    """:func:`cohen_dz` of every row of (B, n) ``d``."""
    d = np.atleast_2d(np.asarray(d, dtype=float))
    if d.shape[1] < 2:
        return np.full(d.shape[0], np.nan)
    s = d.std(axis=1, ddof=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(s > 0, d.mean(axis=1) / np.where(s > 0, s, 1.0), np.nan)


def mean_rows(d: np.ndarray) -> np.ndarray:
    """The mean of every row of (B, n) ``d``."""
    return np.atleast_2d(np.asarray(d, dtype=float)).mean(axis=1)


def bootstrap_interval(
    d: Sequence[float],
    statistic: Callable[[np.ndarray], np.ndarray],
    *,
    seed: int,
    n_boot: int = 4000,
    confidence: float = 0.95,
) -> tuple[float, float, int]:
    """Percentile bootstrap interval of ``statistic`` over resamples of ``d``.

    statistic : maps (B, n) resamples to (B,) values, one per row (:func:`mean_rows`,
    :func:`cohen_dz_rows`, :func:`rank_biserial_rows`). The rows are drawn with replacement by
    ``np.random.default_rng(seed).integers(0, n, (n_boot, n))``.

    Returns (low, high, undefined): the resamples where the statistic was not finite are left out
    and counted. (NaN, NaN, n_boot) with fewer than two values.
    """
    arr = np.asarray(d, dtype=np.float64)
    n = arr.size
    if n < 2:
        return math.nan, math.nan, n_boot
    idx = np.random.default_rng(seed).integers(0, n, (n_boot, n))
    stats = np.asarray(statistic(arr[idx]), dtype=np.float64)
    ok = stats[np.isfinite(stats)]
    if ok.size == 0:
        return math.nan, math.nan, n_boot
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.percentile(ok, [100.0 * alpha, 100.0 * (1 - alpha)])
    return float(lo), float(hi), int(n_boot - ok.size)


@dataclass(frozen=True)
class PairedComparison:
    """Condition ``a`` against ``b`` on one metric, over the participants who have both.

    d = a − b per participant. ``p_*_holm``: after Holm's correction over the report's family
    (set by :func:`holm_family`; NaN until then)."""

    metric: str
    a: str
    b: str
    n: int
    mean_a: float
    mean_b: float
    mean_diff: float
    mean_diff_ci: tuple[float, float]
    dz: float
    dz_ci: tuple[float, float]
    rank_biserial: float
    rank_biserial_ci: tuple[float, float]
    wilcoxon_w: float
    p_wilcoxon: float
    t: float
    p_t: float
    p_wilcoxon_holm: float = math.nan
    p_t_holm: float = math.nan
    smallest_p_wilcoxon: float = math.nan  # the smallest two-sided p the exact test can give with n pairs

    def to_json(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def paired_comparison(
    metric: str,
    a_name: str,
    b_name: str,
    a: Mapping[str, float],
    b: Mapping[str, float],
    *,
    seed: int = 0,
    n_boot: int = 4000,
) -> PairedComparison:
    """The tests and effect sizes of ``a`` against ``b`` (participant → value; pairs where both are finite)."""
    from scipy import stats

    keys = sorted(k for k in a if k in b and math.isfinite(a[k]) and math.isfinite(b[k]))
    x = np.array([a[k] for k in keys], dtype=float)
    y = np.array([b[k] for k in keys], dtype=float)
    d = x - y
    n = int(d.size)
    nan2 = (math.nan, math.nan)
    w = p_w = t = p_t = math.nan
    if n >= 1 and np.any(d != 0):
        res = stats.wilcoxon(x, y)
        w, p_w = float(res.statistic), float(res.pvalue)
    if n >= 2 and d.std(ddof=1) > 0:
        res_t = stats.ttest_rel(x, y)
        t, p_t = float(res_t.statistic), float(res_t.pvalue)
    mean_ci = bootstrap_interval(d, mean_rows, seed=seed, n_boot=n_boot)[:2] if n >= 2 else nan2
    dz_ci = bootstrap_interval(d, cohen_dz_rows, seed=seed, n_boot=n_boot)[:2] if n >= 2 else nan2
    rb_ci = bootstrap_interval(d, rank_biserial_rows, seed=seed, n_boot=n_boot)[:2] if n >= 2 else nan2
    return PairedComparison(
        metric=metric,
        a=a_name,
        b=b_name,
        n=n,
        mean_a=float(x.mean()) if n else math.nan,
        mean_b=float(y.mean()) if n else math.nan,
        mean_diff=float(d.mean()) if n else math.nan,
        mean_diff_ci=mean_ci,
        dz=cohen_dz(d),
        dz_ci=dz_ci,
        rank_biserial=rank_biserial(d),
        rank_biserial_ci=rb_ci,
        wilcoxon_w=w,
        p_wilcoxon=p_w,
        t=t,
        p_t=p_t,
        smallest_p_wilcoxon=2.0 / 2**n if n else math.nan,
    )


def holm_family(comparisons: Sequence[PairedComparison]) -> list[PairedComparison]:
    """The comparisons with their p values Holm-corrected over the whole family (each test kind apart)."""
    from dataclasses import replace

    pw = holm([c.p_wilcoxon for c in comparisons])
    pt = holm([c.p_t for c in comparisons])
    return [replace(c, p_wilcoxon_holm=w, p_t_holm=t) for c, w, t in zip(comparisons, pw, pt)]


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
