"""Paired statistics on scipy.stats: the study's, the ablation's and the application's, in one place.

Every comparison is within pairs: for pair i (a participant, or a trial run with the same operator
and seed under two controllers) and conditions a, b, the differences d_i = a_i − b_i. Pairs where
either value is non-finite are left out.

- Paired mean difference d̄ with its Student-t interval (:func:`paired_difference`):
  d̄ ± t_{n−1, (1+c)/2} · s_d / √n, from :func:`scipy.stats.ttest_rel`'s ``confidence_interval``.
- Where pairs come in clusters that are not independent (trials sharing one calibration of the
  person), the mean difference's cluster-robust t interval (:func:`clustered_difference`): over G
  clusters, se² = G/(G − 1) · Σ_g (Σ_{i∈g} (d_i − d̄))² / n² (the CR1 sandwich; Cameron & Miller,
  J. Human Resources 2015) and t with G − 1 degrees of freedom. With one pair per cluster it is the
  paired t interval above.
- Percentile bootstrap interval of any statistic of paired samples (:func:`bootstrap_interval`):
  :func:`scipy.stats.bootstrap` (``method="percentile"``, ``paired=True``) with the Generator
  ``np.random.default_rng(seed)``, which draws the B × n row indices as
  ``rng.integers(0, n, (B, n))``; the interval is the (α, 1 − α) quantiles, α = (1 − c)/2, of the
  resamples where the statistic is finite (the others, e.g. s_d = 0 in a resample, are left out and
  counted: scipy's own interval would be NaN then).
- The share of a reference's gain (:func:`gain_share`): mean_i(base_i − x_i) / mean_i(base_i − ref_i),
  with its percentile bootstrap interval (the three resampled together).
- Wilcoxon signed-rank test (:func:`scipy.stats.wilcoxon`, two-sided, ``zero_method="wilcox"``:
  a zero difference is dropped before ranking, so the test is on the k ≤ n non-zero pairs; the exact
  null distribution up to 50 pairs without ties or zeros, with them the exact distribution of the 2ⁿ
  sign patterns up to 13 pairs, the normal one beyond): nothing assumed about the shape of d. With k non-zero
  pairs the smallest two-sided p it can give is 2/2ᵏ (k = 4: 0.125, k = 5: 0.0625): below six
  it cannot reach 0.05, whatever the data; five pairs with one zero are four to the test.
- Paired t test (:func:`scipy.stats.ttest_rel`): t = d̄ / (s_d/√n), n − 1 degrees of freedom;
  assumes d roughly normal, which a sample of four cannot check.
- Holm's step-down correction over a family of m tests (Holm 1979): with p sorted
  ascending, p̃_(i) = max_{j ≤ i} min(1, (m − j + 1) p_(j)); controls the family-wise error. m counts
  the tests with a p value (a test that could not run, p NaN, is not one of the family).
- Effect sizes (:func:`paired_comparison`): the mean difference d̄ (in the metric's unit) with its
  paired Student-t interval (:func:`paired_difference`), Cohen's d_z = d̄ / s_d and the matched-pairs
  rank-biserial correlation r = (W⁺ − W⁻)/(W⁺ + W⁻) (Kerby 2014), these two with a seeded percentile
  bootstrap interval (pairs resampled with replacement). A percentile bootstrap of the mean covers
  74–88 % instead of 95 % at 3–8 pairs of normal differences (it resamples from n values: too narrow),
  which is why the mean difference's interval is the t interval.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = [
    "PairedComparison",
    "bootstrap_interval",
    "clustered_difference",
    "cohen_dz",
    "cohen_dz_rows",
    "gain_share",
    "holm",
    "holm_family",
    "mean_rows",
    "paired_comparison",
    "paired_difference",
    "rank_biserial",
    "rank_biserial_rows",
]


def _finite_differences(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a − b over the pairs where both are finite, which pairs those are)."""
    ok = np.isfinite(a) & np.isfinite(b)
    return (a - b)[ok], ok


def paired_difference(a, b, confidence: float = 0.95) -> tuple[float, float, float, int]:
    """Mean of a_i − b_i over the pairs where both are finite, and its Student-t interval.

    ``a`` and ``b`` are per-pair values (same order, one shape). Returns (mean, low, high, n):
    d̄ ± t_{n−1,(1+c)/2} s_d/√n, as :func:`scipy.stats.ttest_rel` gives it; the interval is NaN with
    fewer than 2 pairs, and (d̄, d̄) when every difference is the same.
    """
    from scipy import stats

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired values need the same shape, got {a.shape} and {b.shape}")
    d, ok = _finite_differences(a, b)
    n = int(d.size)
    if n == 0:
        return math.nan, math.nan, math.nan, 0
    mean = float(d.mean())
    if n < 2:
        return mean, math.nan, math.nan, n
    if d.std(ddof=1) == 0.0:  # t is 0/0 there and scipy's interval NaN; the interval has no width
        return mean, mean, mean, n
    with np.errstate(divide="ignore", invalid="ignore"):
        ci = stats.ttest_rel(a[ok], b[ok]).confidence_interval(confidence)
    return mean, float(ci.low), float(ci.high), n


def clustered_difference(a, b, clusters, confidence: float = 0.95) -> tuple[float, float, float, int]:
    """Mean of a_i − b_i over the pairs where both are finite, and its cluster-robust Student-t interval.

    ``clusters``: a label per pair (any values; compared as text, so tuples too), pairs of one label not
    independent of each other. With G labels among the n finite pairs:
    d̄ ± t_{G−1,(1+c)/2} · se, se² = G/(G − 1) · Σ_g (Σ_{i∈g} (d_i − d̄))² / n² (module docstring). Returns
    (mean, low, high, n); the interval NaN with fewer than two clusters, and (d̄, d̄) when se is 0. One pair
    per cluster gives :func:`paired_difference`'s interval (se² = s_d²/n); a cluster's pairs repeated k times
    give the same interval as the cluster once, where the pairs' own t interval would narrow by √k.
    """
    from scipy import stats

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"paired values need one shape (n,), got {a.shape} and {b.shape}")
    labels = [str(c) for c in clusters]
    if len(labels) != a.size:
        raise ValueError(f"clusters needs one label per pair ({a.size}), got {len(labels)}")
    d, ok = _finite_differences(a, b)
    n = int(d.size)
    if n == 0:
        return math.nan, math.nan, math.nan, 0
    mean = float(d.mean())
    _, which = np.unique(np.asarray(labels)[ok], return_inverse=True)
    sums = np.bincount(which, weights=d - mean)  # each cluster's summed deviation from the mean
    G = int(sums.size)
    if G < 2:
        return mean, math.nan, math.nan, n
    se = math.sqrt(G / (G - 1) * float(sums @ sums)) / n
    if se == 0.0:
        return mean, mean, mean, n
    half = float(stats.t.ppf((1.0 + confidence) / 2.0, G - 1)) * se
    return mean, mean - half, mean + half, n


def bootstrap_interval(
    d: Sequence[float] | Sequence[np.ndarray],
    statistic: Callable[..., np.ndarray],
    *,
    seed: int,
    n_boot: int = 4000,
    confidence: float = 0.95,
) -> tuple[float, float, int]:
    """Percentile bootstrap interval of ``statistic`` over resamples of the pairs (module docstring).

    d : one sample (n,), or a tuple of samples (n,) each, resampled together (the same rows).
    statistic : maps the (B, n) resample of each sample to (B,) values, one per row
    (:func:`mean_rows`, :func:`cohen_dz_rows`, :func:`rank_biserial_rows`).

    Returns (low, high, undefined): the resamples where the statistic was not finite are left out
    and counted. (NaN, NaN, n_boot) with fewer than two pairs or no finite resample.
    """
    from scipy import stats

    samples = (
        tuple(np.asarray(s, dtype=np.float64) for s in d) if isinstance(d, tuple) else (np.asarray(d, np.float64),)
    )
    n = samples[0].size
    if n < 2:
        return math.nan, math.nan, n_boot

    def vectorized(*resamples: np.ndarray, axis: int = -1) -> np.ndarray:
        if axis != -1:  # scipy asks along the last axis; the row statistics know no other
            raise ValueError(f"the statistic runs along the last axis, asked for {axis}")
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(statistic(*resamples), dtype=np.float64)

    with warnings.catch_warnings(), np.errstate(divide="ignore", invalid="ignore"):
        # scipy's own interval is NaN (and it warns) when a resample's statistic is: ours leaves those out.
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        res = stats.bootstrap(
            samples,
            vectorized,
            n_resamples=n_boot,
            vectorized=True,
            paired=True,
            method="percentile",
            confidence_level=confidence,
            rng=np.random.default_rng(seed),
        )
    dist = np.asarray(res.bootstrap_distribution, dtype=np.float64)
    ok = dist[np.isfinite(dist)]
    if ok.size == 0:
        return math.nan, math.nan, n_boot
    lo, hi = np.quantile(ok, [(1.0 - confidence) / 2.0, (1.0 + confidence) / 2.0])
    return float(lo), float(hi), int(n_boot - ok.size)


def gain_share(
    base, x, ref, *, seed: int = 0, n_boot: int = 2000, confidence: float = 0.95, clusters=None
) -> tuple[float, float, float]:
    """(share, low, high): mean(base − x) / mean(base − ref) over the pairs, with its percentile
    bootstrap interval (:func:`bootstrap_interval`, the pairs resampled ``n_boot`` times).

    ``base``, ``x``, ``ref``: per-pair values of one metric, same order, shape (n,) (the ablation:
    MG, an intent source and the oracle on the same trials). Pairs where any of the three is
    non-finite are left out. All NaN when ``ref`` gains nothing or loses on average (the share is undefined)
    or no pair is left; the interval NaN when the reference's gain is zero in half the resamples or more.

    ``clusters``: a label per pair (shape (n,), any hashable values) for pairs that are not independent
    (trials that share one calibration of the person): the bootstrap then resamples whole clusters (each
    one's summed gains, Σ gain_x / Σ gain_ref over the drawn clusters), so what the pairs of a cluster share
    is in the interval. With one pair per cluster it is the pairs' bootstrap, draw for draw.
    """
    base, x, ref = (np.asarray(v, dtype=float) for v in (base, x, ref))
    if not base.shape == x.shape == ref.shape or base.ndim != 1:
        raise ValueError(f"paired values need one shape (n,), got {base.shape}, {x.shape}, {ref.shape}")
    ok = np.isfinite(base) & np.isfinite(x) & np.isfinite(ref)
    gain_x, gain_ref = (base - x)[ok], (base - ref)[ok]
    # a reference that gains nothing, or loses, on average: no share of it (a source losing more would read as a
    # share above 1, a claim met by being worse)
    if gain_x.size == 0 or not gain_ref.mean() > 0.0:
        return math.nan, math.nan, math.nan
    share = float(gain_x.mean() / gain_ref.mean())
    if clusters is not None:
        labels = [str(c) for c in clusters]  # tuples too: (person, calibration draw)
        if len(labels) != base.size:
            raise ValueError(f"clusters needs one label per pair ({base.size}), got {len(labels)}")
        _, first, which = np.unique(np.asarray(labels)[ok], return_index=True, return_inverse=True)
        which = np.argsort(np.argsort(first))[which]  # clusters in the order they first appear
        # each cluster's summed gains: resampling them resamples the clusters whole
        gain_x, gain_ref = np.bincount(which, weights=gain_x), np.bincount(which, weights=gain_ref)
        statistic = lambda gx, gr: gx.sum(axis=1) / gr.sum(axis=1)  # noqa: E731
    else:
        statistic = lambda gx, gr: gx.mean(axis=1) / gr.mean(axis=1)  # noqa: E731
    if gain_x.size == 1:  # every resample is the one pair (or cluster): no interval (one of no width had been read as
        return share, math.nan, math.nan  # a lower bound, and claims held on a single trial: a review, 2026-12-07)
    lo, hi, undefined = bootstrap_interval(
        (gain_x, gain_ref),
        statistic,
        seed=seed,
        n_boot=n_boot,
        confidence=confidence,
    )
    if n_boot - undefined < n_boot // 2:  # the reference's gain is too often zero in a resample: no interval
        return share, math.nan, math.nan
    return share, lo, hi


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


@dataclass(frozen=True)
class PairedComparison:
    """Condition ``a`` against ``b`` on one metric, over the participants who have both.

    d = a − b per participant. ``mean_diff_ci``: the paired Student-t 95 % interval of the mean difference
    (:func:`paired_difference`); ``dz_ci``, ``rank_biserial_ci``: percentile bootstrap 95 % intervals, which
    cover well under 95 % at a few pairs (module docstring). ``p_*_holm``: after Holm's correction over the
    report's family (set by :func:`holm_family`; NaN until then). ``n``: the pairs (participants with both
    values), what the means, the t test and the intervals are over; ``n_wilcoxon``: those of them with a non-zero
    difference, what the Wilcoxon test ranks (zeros dropped) and ``smallest_p_wilcoxon`` = 2/2^n_wilcoxon is of."""

    metric: str
    a: str
    b: str
    n: int
    n_wilcoxon: int
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
    smallest_p_wilcoxon: float = math.nan  # the smallest two-sided p the test can give: 2/2^n_wilcoxon

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
    k = int(np.count_nonzero(d))  # the pairs the Wilcoxon test ranks: zero_method="wilcox" drops the zeros
    nan2 = (math.nan, math.nan)
    w = p_w = t = p_t = math.nan
    if k >= 1:
        res = stats.wilcoxon(x, y, zero_method="wilcox")
        w, p_w = float(res.statistic), float(res.pvalue)
    if n >= 2 and d.std(ddof=1) > 0:
        res_t = stats.ttest_rel(x, y)
        t, p_t = float(res_t.statistic), float(res_t.pvalue)
    mean_ci = paired_difference(x, y)[1:3]  # the paired t interval (module docstring); NaN below two pairs
    dz_ci = bootstrap_interval(d, cohen_dz_rows, seed=seed, n_boot=n_boot)[:2] if n >= 2 else nan2
    rb_ci = bootstrap_interval(d, rank_biserial_rows, seed=seed, n_boot=n_boot)[:2] if n >= 2 else nan2
    return PairedComparison(
        metric=metric,
        a=a_name,
        b=b_name,
        n=n,
        n_wilcoxon=k,
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
        smallest_p_wilcoxon=2.0 / 2**k if k else math.nan,
    )


def holm_family(comparisons: Sequence[PairedComparison]) -> list[PairedComparison]:
    """The comparisons with their p values Holm-corrected over the whole family (each test kind apart): m is the
    number of comparisons whose test gave a p value (:func:`holm`; a NaN p is not counted and stays NaN)."""
    pw = holm([c.p_wilcoxon for c in comparisons])
    pt = holm([c.p_t for c in comparisons])
    return [replace(c, p_wilcoxon_holm=w, p_t_holm=t) for c, w, t in zip(comparisons, pw, pt, strict=True)]
