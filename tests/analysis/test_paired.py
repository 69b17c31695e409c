"""coassist.analysis.paired against independent references: hand-computed t intervals and tests,
exact Wilcoxon by enumeration, scipy on known cases and the naive bootstrap loop."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats

from coassist.analysis.paired import (
    bootstrap_interval,
    clustered_difference,
    cohen_dz,
    cohen_dz_rows,
    gain_share,
    holm,
    holm_family,
    mean_rows,
    paired_comparison,
    paired_difference,
    rank_biserial,
    rank_biserial_rows,
)

#: The ablation's resamples per share (experiments/ablation.py's BOOTSTRAP).
BOOTSTRAP = 2000

A = {"P1": 12.0, "P2": 9.5, "P3": 14.0, "P4": 11.0, "P5": 10.2, "P6": 13.1}
B = {"P1": 10.0, "P2": 9.9, "P3": 11.0, "P4": 8.5, "P5": 9.0, "P6": 10.0}


# --------------------------------------------------------------------------- the t interval of a paired difference


def test_paired_difference_equals_scipys_paired_t_interval():
    rng = np.random.default_rng(4)
    a = rng.normal(4.5, 0.5, 18)
    b = a + rng.normal(0.1, 0.2, 18)
    mean, lo, hi, n = paired_difference(a, b)
    ci = stats.ttest_rel(a, b).confidence_interval(0.95)
    assert n == 18
    assert mean == pytest.approx(np.mean(a - b), abs=1e-12)
    assert (lo, hi) == pytest.approx((ci.low, ci.high), abs=1e-12)


def test_paired_difference_by_hand_and_drops_unfinished_pairs():
    # differences 1, 2, 3 (the NaN pair dropped): mean 2, s = 1, t(0.975, 2) = 4.302653
    mean, lo, hi, n = paired_difference([2.0, 4.0, 6.0, np.nan], [1.0, 2.0, 3.0, 0.0])
    half = 4.302652729911275 / np.sqrt(3)
    assert (mean, n) == (2.0, 3)
    assert (lo, hi) == pytest.approx((2.0 - half, 2.0 + half), abs=1e-9)
    m1, lo1, _, n1 = paired_difference([1.0], [0.5])
    assert (m1, n1) == (0.5, 1) and np.isnan(lo1)
    with pytest.raises(ValueError, match="same shape"):
        paired_difference([1.0, 2.0], [1.0])


def test_paired_difference_of_equal_differences_has_no_width():
    # d = 1, 1, 1: s_d = 0, so the interval is the mean itself (scipy's would be NaN: 0/0)
    assert paired_difference([2.0, 3.0, 4.0], [1.0, 2.0, 3.0]) == (1.0, 1.0, 1.0, 3)
    assert all(math.isnan(v) for v in paired_difference([np.nan], [1.0])[:3])


# --------------------------------------------------------------------------- the clusters' t interval


def test_clustered_difference_by_hand():
    # d = 1, 3 | 2 | 6, 6, 6 (the NaN pair dropped): n = 6, d̄ = 24/6 = 4; the clusters' summed deviations
    # −3 − 1 = −4, −2 and 2 + 2 + 2 = 6, squares 56; se² = 3/2 · 56/36 = 7/3; t(0.975, 2) = 4.302652729911275
    a = [1.0, 3.0, 2.0, 6.0, 6.0, 6.0, np.nan]
    b = [0.0] * 7
    mean, lo, hi, n = clustered_difference(a, b, ["x", "x", "y", "z", "z", "z", "y"])
    half = 4.302652729911275 * math.sqrt(7.0 / 3.0)
    assert (mean, n) == (4.0, 6)
    assert (lo, hi) == pytest.approx((4.0 - half, 4.0 + half), abs=1e-9)


def test_clustered_difference_of_one_pair_per_cluster_is_the_paired_t_interval():
    rng = np.random.default_rng(7)
    a = rng.normal(4.5, 0.5, 18)
    b = a + rng.normal(0.1, 0.2, 18)
    labels = [(f"user-{k % 6}", k // 6) for k in range(18)]  # tuples, as the ablation's (person, draw)
    assert clustered_difference(a, b, labels) == pytest.approx(paired_difference(a, b), abs=1e-12)


def test_a_cluster_repeated_counts_once():
    # each cluster's pair repeated 1-4 times: the clusters' interval is that of the five pairs once (the
    # pairs' own t interval, treating the copies as independent, narrows)
    a, b = np.array([3.0, 1.5, 2.2, 4.1, 0.7]), np.array([2.0, 1.9, 1.0, 2.5, 0.9])
    reps = [1, 4, 2, 3, 2]
    ar, br = np.repeat(a, reps), np.repeat(b, reps)
    labels = np.repeat(np.arange(5), reps)
    once = paired_difference(a, b)
    mean, lo, hi, n = clustered_difference(ar, br, labels)
    assert n == 12
    # the mean is the pairs' weighted by their copies; the width is the five clusters', t with 4 df
    assert mean == pytest.approx(float(np.mean(ar - br)), abs=1e-12)
    d = a - b
    w = np.array(reps, float)
    se = math.sqrt(5 / 4 * float(np.sum((w * (d - mean)) ** 2))) / 12
    assert (hi - lo) / 2 == pytest.approx(stats.t.ppf(0.975, 4) * se, rel=1e-12)
    assert hi - lo > paired_difference(ar, br)[2] - paired_difference(ar, br)[1]
    # equal copies: exactly the five pairs' paired t interval
    eq = clustered_difference(np.repeat(a, 3), np.repeat(b, 3), np.repeat(np.arange(5), 3))
    assert eq == pytest.approx((once[0], once[1], once[2], 15), abs=1e-12)


def test_clustered_difference_needs_two_clusters_and_one_label_per_pair():
    m, lo, hi, n = clustered_difference([1.0, 2.0, 4.0], [0.0, 0.0, 0.0], ["a", "a", "a"])
    assert (m, n) == (pytest.approx(7.0 / 3.0), 3) and math.isnan(lo) and math.isnan(hi)
    assert clustered_difference([2.0, 3.0], [1.0, 2.0], ["a", "b"]) == (1.0, 1.0, 1.0, 2)
    assert all(math.isnan(v) for v in clustered_difference([np.nan], [1.0], ["a"])[:3])
    with pytest.raises(ValueError, match="one label per pair"):
        clustered_difference([1.0, 2.0], [0.0, 0.0], ["a"])
    with pytest.raises(ValueError, match="one shape"):
        clustered_difference([1.0, 2.0], [0.0], ["a", "b"])


def test_bootstrap_interval_is_scipys_percentile_interval_when_every_resample_is_defined():
    d = np.random.default_rng(7).normal(0.5, 1.0, 12)
    lo, hi, undefined = bootstrap_interval(d, mean_rows, seed=11, n_boot=3000)
    ref = stats.bootstrap(
        (d,), np.mean, n_resamples=3000, method="percentile", rng=np.random.default_rng(11), vectorized=True
    ).confidence_interval
    assert undefined == 0
    assert (lo, hi) == pytest.approx((ref.low, ref.high), rel=1e-12)


def test_bootstrap_interval_leaves_out_and_counts_undefined_resamples():
    # A resample that draws one value three times (1, 1, 1 or 2, 2, 2) has s_d = 0: d_z is undefined
    # there, left out and counted; the naive loop below counts the same resamples.
    d = np.array([1.0, 1.0, 2.0])
    lo, hi, undefined = bootstrap_interval(d, cohen_dz_rows, seed=4, n_boot=500)
    idx = np.random.default_rng(4).integers(0, 3, (500, 3))
    dz = np.array([np.nan if d[r].std(ddof=1) == 0 else d[r].mean() / d[r].std(ddof=1) for r in idx])
    ok = dz[np.isfinite(dz)]
    assert undefined == int(np.isnan(dz).sum()) > 0
    assert (lo, hi) == pytest.approx(tuple(np.quantile(ok, [0.025, 0.975])), rel=1e-12)
    assert all(math.isnan(v) for v in bootstrap_interval([1.0], mean_rows, seed=0)[:2])


# --------------------------------------------------------------------------- the share of a reference's gain (the ablation)


def test_share_by_hand():
    # MG − X = (1, 1, 2), mean 4/3; MG − oracle = (2, 3, 3), mean 8/3: half the oracle's benefit.
    mg, x, oracle = [4.0, 5.0, 6.0], [3.0, 4.0, 4.0], [2.0, 2.0, 3.0]
    share, lo, hi = gain_share(mg, x, oracle)
    assert share == pytest.approx(0.5, rel=1e-15)
    assert lo <= share <= hi
    # Per-trial ratios lie in [1/3, 2/3]; a ratio of resampled means cannot leave their range.
    assert 1 / 3 - 1e-12 <= lo and hi <= 2 / 3 + 1e-12
    assert (share, lo, hi) == gain_share(mg, x, oracle)  # seeded: the same interval every time


def test_interval_is_the_naive_percentile_bootstrap():
    rng = np.random.default_rng(5)
    mg = rng.normal(5.0, 0.5, 18)
    oracle = mg - rng.normal(2.0, 0.4, 18)
    x = mg - rng.normal(1.5, 0.6, 18)
    share, lo, hi = gain_share(mg, x, oracle, seed=3)
    # The same resamples drawn one by one, in a loop.
    draw = np.random.default_rng(3).integers(0, 18, (BOOTSTRAP, 18))
    ratios = [np.mean(mg[i] - x[i]) / np.mean(mg[i] - oracle[i]) for i in draw]
    assert (lo, hi) == pytest.approx(tuple(np.quantile(ratios, [0.025, 0.975])), rel=1e-12)
    assert share == pytest.approx(np.mean(mg - x) / np.mean(mg - oracle), rel=1e-14)


def test_undefined_share_and_bad_input():
    assert all(np.isnan(v) for v in gain_share([1.0, 2.0], [0.5, 1.0], [1.0, 2.0]))  # the oracle gains nothing
    # the oracle worse than MG by 1, the source by 2: once a share of 2.0, a bar met by losing more
    assert all(np.isnan(v) for v in gain_share([1.0, 2.0], [3.0, 4.0], [2.0, 3.0]))
    share, _, _ = gain_share([4.0, np.nan, 6.0], [3.0, 1.0, 4.0], [2.0, 2.0, 4.0])  # the NaN trial is left out
    assert share == pytest.approx((1.0 + 2.0) / (2.0 + 2.0))
    with pytest.raises(ValueError, match="one shape"):
        gain_share([1.0, 2.0], [1.0], [1.0, 2.0])


def test_share_of_one_pair_or_one_cluster_has_no_interval():
    # one pair resamples to itself: an interval of no width had been read as a lower bound, and two claims of the
    # report held on a single trial (a review, 2026-12-07)
    share, lo, hi = gain_share([4.0], [3.0], [2.0])
    assert share == 0.5 and np.isnan(lo) and np.isnan(hi)
    share, lo, hi = gain_share([4.0, 5.0], [3.0, 3.0], [2.0, 1.0], clusters=["a", "a"])
    assert share == pytest.approx(3.0 / 6.0) and np.isnan(lo) and np.isnan(hi)


# --------------------------------------------------------------------------- the study's tests and effect sizes


def _exact_wilcoxon(d: np.ndarray) -> tuple[float, float]:
    """W = min(W+, W−) and the exact two-sided p by enumerating the 2^n sign patterns (no ties, no zeros)."""
    ranks = stats.rankdata(np.abs(d))
    w_plus = ranks[d > 0].sum()
    w = min(w_plus, ranks.sum() - w_plus)
    null = [sum(r for r, s in zip(ranks, signs) if s) for signs in itertools.product((0, 1), repeat=len(d))]
    p = sum(1 for v in null if min(v, ranks.sum() - v) <= w) / len(null)
    return float(w), float(p)


def test_wilcoxon_and_paired_t_equal_a_hand_computation():
    c = paired_comparison("f_rms", "a", "b", A, B, seed=0, n_boot=200)
    x, y = np.array([A[k] for k in sorted(A)]), np.array([B[k] for k in sorted(B)])
    d = x - y  # 2.0 −0.4 3.0 2.5 1.2 3.1: no ties, no zeros
    w, p = _exact_wilcoxon(d)
    assert (c.wilcoxon_w, c.p_wilcoxon) == (w, pytest.approx(p, abs=1e-12))
    assert p == pytest.approx(4 / 64)  # W = W− = 1 (the rank of |−0.4|): W+ ∈ {0, 1, 20, 21} are 4 of 64 patterns
    t = d.mean() / (d.std(ddof=1) / math.sqrt(d.size))
    assert c.t == pytest.approx(t, rel=1e-12)
    assert c.p_t == pytest.approx(2 * stats.t.sf(abs(t), d.size - 1), rel=1e-10)
    assert c.mean_diff == pytest.approx(d.mean()) and c.dz == pytest.approx(d.mean() / d.std(ddof=1))
    assert c.rank_biserial == pytest.approx((20 - 1) / 21)  # W+ = 21 − 1 = 20, W− = 1
    assert c.smallest_p_wilcoxon == pytest.approx(2 / 2**6)


def test_holm_equals_the_step_down_by_hand():
    p = [0.01, 0.04, 0.03, 0.005, math.nan]
    # sorted: 0.005 (×4 = 0.02), 0.01 (×3 = 0.03), 0.03 (×2 = 0.06), 0.04 (×1 = 0.04 → max with 0.06 = 0.06)
    assert holm(p)[:4] == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert math.isnan(holm(p)[4])
    assert holm([0.5, 0.6]) == pytest.approx([1.0, 1.0])  # capped at 1


def test_the_wilcoxon_floor_and_n_are_the_non_zero_pairs():
    """Five pairs, one with no difference: scipy's default zero_method "wilcox" drops it, so the test ranks four,
    and its smallest two-sided p is 2/2^4 = 0.125, not 2/2^5 = 0.0625 (what the comparison claimed before). The four
    differences +1, +2, +1, +1 all point one way: of the 2^4 sign patterns only all + and all − have min(W+, W−) = 0,
    p = 2/16 = 0.125, the floor itself."""
    a = {"S01": 6.0, "S02": 6.0, "S03": 5.0, "S04": 7.0, "S05": 4.0}
    b = {"S01": 5.0, "S02": 4.0, "S03": 4.0, "S04": 6.0, "S05": 4.0}
    c = paired_comparison("likert_0", "A", "B", a, b, n_boot=200)
    assert (c.n, c.n_wilcoxon) == (5, 4)  # the mean difference and the t test are over the five pairs
    assert c.smallest_p_wilcoxon == 2 / 2**4 == 0.125
    assert c.p_wilcoxon == pytest.approx(2 / 16, abs=1e-12) and c.wilcoxon_w == 0.0
    assert c.p_wilcoxon == pytest.approx(
        stats.wilcoxon(list(a.values()), list(b.values()), zero_method="wilcox").pvalue
    )
    assert c.mean_diff == pytest.approx(5 / 5)  # (1 + 2 + 1 + 1 + 0) / 5: the zero counts here
    # no zero: the floor is of every pair (2/2^6), and no difference at all: no test, no floor
    assert paired_comparison("f_rms", "a", "b", A, B, n_boot=200).n_wilcoxon == 6
    same = paired_comparison("f_rms", "a", "b", {"S01": 1.0, "S02": 2.0}, {"S01": 1.0, "S02": 2.0})
    assert (same.n, same.n_wilcoxon) == (2, 0) and math.isnan(same.smallest_p_wilcoxon) and math.isnan(same.p_wilcoxon)


def test_holm_family_counts_only_the_comparisons_with_a_p_value():
    """Four comparisons, one with no difference at all (no Wilcoxon p, no t p: NaN): Holm's m is 3, not 4. With p
    0.01, 0.04, 0.03 by hand: 0.01 × 3 = 0.03, 0.03 × 2 = 0.06, 0.04 × 1 = 0.04 → max(0.06, 0.04) = 0.06 (m = 4
    would give 0.04, 0.09, 0.09)."""
    from dataclasses import replace

    base = paired_comparison("f_rms", "a", "b", A, B, n_boot=200)
    none = paired_comparison("f_rms", "a", "c", {"S01": 1.0, "S02": 2.0}, {"S01": 1.0, "S02": 2.0})
    assert math.isnan(none.p_wilcoxon) and math.isnan(none.p_t)
    family = [replace(base, p_wilcoxon=p, p_t=p) for p in (0.01, 0.04)] + [
        none,
        replace(base, p_wilcoxon=0.03, p_t=0.03),
    ]
    out = holm_family(family)
    for got in ([c.p_wilcoxon_holm for c in out], [c.p_t_holm for c in out]):
        assert got[0] == pytest.approx(0.03) and got[1] == pytest.approx(0.06) and got[3] == pytest.approx(0.06)
        assert math.isnan(got[2])


def test_rank_biserial_drops_zeros_and_averages_ties():
    d = np.array([0.0, 1.0, -1.0, 2.0, 0.0, 3.0])
    # non-zero |d|: 1, 1, 2, 3 → ranks 1.5, 1.5, 3, 4; W+ = 1.5 + 3 + 4 = 8.5, W− = 1.5
    assert rank_biserial(d) == pytest.approx((8.5 - 1.5) / 10.0)
    rows = np.array([[0.0, 1.0, -1.0, 2.0, 0.0, 3.0], [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [0.0] * 6])
    out = rank_biserial_rows(rows)
    assert out[0] == pytest.approx(0.7) and out[1] == 1.0 and math.isnan(out[2])
    assert math.isnan(cohen_dz([1.0, 1.0, 1.0]))


def test_bootstrap_is_the_percentile_of_the_seeded_resamples():
    d = np.array([2.0, -0.4, 3.0, 2.5, 1.2, 3.1])
    lo, hi, undefined = bootstrap_interval(d, mean_rows, seed=5, n_boot=1000)
    idx = np.random.default_rng(5).integers(0, d.size, (1000, d.size))
    means = np.array([d[row].mean() for row in idx])
    assert (lo, hi) == tuple(pytest.approx(v, rel=1e-12) for v in np.percentile(means, [2.5, 97.5]))
    assert undefined == 0
    assert bootstrap_interval(d, mean_rows, seed=5, n_boot=1000) == (lo, hi, 0)
    # the mean of a normal sample: the percentile interval close to the t interval for a large n
    big = np.random.default_rng(1).normal(1.0, 2.0, 400)
    lo, hi, _ = bootstrap_interval(big, mean_rows, seed=2, n_boot=4000)
    half = stats.t.ppf(0.975, big.size - 1) * big.std(ddof=1) / math.sqrt(big.size)
    assert lo == pytest.approx(big.mean() - half, abs=0.05) and hi == pytest.approx(big.mean() + half, abs=0.05)


# --------------------------------------------------------------------------- clustered pairs (calibration draws)


def test_clusters_of_one_pair_are_the_pairs_bootstrap():
    # Σ gain_x / Σ gain_ref over n drawn pairs is their means' ratio: the same resamples give the same interval.
    rng = np.random.default_rng(11)
    mg = rng.normal(5.0, 0.5, 20)
    oracle = mg - rng.normal(2.0, 0.4, 20)
    x = mg - rng.normal(1.2, 0.7, 20)
    plain = gain_share(mg, x, oracle, seed=4)
    single = gain_share(mg, x, oracle, seed=4, clusters=[("p", i) for i in range(20)])
    assert single == pytest.approx(plain, rel=1e-12)


def test_clusters_are_resampled_whole():
    # Six clusters of four pairs: the interval is the naive loop over clusters drawn with replacement, each
    # contributing its four pairs' summed gains.
    rng = np.random.default_rng(2)
    labels = [(f"p{c // 2}", c % 2) for c in range(6) for _ in range(4)]
    shift = np.repeat(rng.normal(0.0, 0.8, 6), 4)  # what a cluster's pairs share: its calibration
    mg = rng.normal(5.0, 0.3, 24)
    oracle = mg - rng.normal(2.0, 0.2, 24)
    x = mg - (1.0 + shift + rng.normal(0.0, 0.1, 24))
    share, lo, hi = gain_share(mg, x, oracle, seed=7, clusters=labels)
    assert share == pytest.approx(np.mean(mg - x) / np.mean(mg - oracle), rel=1e-14)
    gx = (mg - x).reshape(6, 4).sum(axis=1)  # clusters in the order they first appear
    gr = (mg - oracle).reshape(6, 4).sum(axis=1)
    draw = np.random.default_rng(7).integers(0, 6, (BOOTSTRAP, 6))
    ratios = [gx[i].sum() / gr[i].sum() for i in draw]
    assert (lo, hi) == pytest.approx(tuple(np.quantile(ratios, [0.025, 0.975])), rel=1e-12)
    # what the clusters share widens the interval against the pairs' bootstrap, which takes them as independent
    _, plo, phi = gain_share(mg, x, oracle, seed=7)
    assert hi - lo > 1.5 * (phi - plo)


def test_clusters_need_one_label_per_pair():
    with pytest.raises(ValueError, match="one label per pair"):
        gain_share([4.0, 5.0, 6.0], [3.0, 4.0, 4.0], [2.0, 2.0, 3.0], clusters=["a", "b"])
