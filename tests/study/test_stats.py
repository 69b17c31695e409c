"""The statistics against hand computations and scipy on fixed data."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats

from coassist.study.stats import (
    bootstrap_interval,
    cohen_dz,
    holm,
    mean_rows,
    order_effect,
    paired_comparison,
    rank_biserial,
    rank_biserial_rows,
)

A = {"P1": 12.0, "P2": 9.5, "P3": 14.0, "P4": 11.0, "P5": 10.2, "P6": 13.1}
B = {"P1": 10.0, "P2": 9.9, "P3": 11.0, "P4": 8.5, "P5": 9.0, "P6": 10.0}


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


def test_order_effect_equals_the_latin_square_anova_by_hand():
    # a 4 x 4 Latin square: participant i takes condition (i + j) mod 4 at position j
    rng = np.random.default_rng(0)
    person = rng.normal(0, 1, 4)
    effect_c = np.array([0.0, 1.0, -0.5, 0.3])
    effect_p = np.array([0.0, 0.4, 0.9, 1.5])
    rows, y = [], np.zeros((4, 4))
    for i in range(4):
        for j in range(4):
            c = (i + j) % 4
            y[i, j] = 5 + person[i] + effect_c[c] + effect_p[j] + rng.normal(0, 0.3)
            rows.append((f"P{i}", f"c{c}", j, float(y[i, j])))
    out = order_effect(rows)
    # the classic Latin square ANOVA: SS_total = SS_rows + SS_cols + SS_treatments + SS_error
    g = y.mean()
    ss_rows = 4 * ((y.mean(axis=1) - g) ** 2).sum()
    ss_cols = 4 * ((y.mean(axis=0) - g) ** 2).sum()
    cond_means = np.array(
        [np.mean([y[i, j] for i in range(4) for j in range(4) if (i + j) % 4 == c]) for c in range(4)]
    )
    ss_treat = 4 * ((cond_means - g) ** 2).sum()
    ss_error = ((y - g) ** 2).sum() - ss_rows - ss_cols - ss_treat
    F = (ss_cols / 3) / (ss_error / 6)
    assert (out["df1"], out["df2"]) == (3, 6)
    assert out["F"] == pytest.approx(F, rel=1e-9)
    assert out["p"] == pytest.approx(stats.f.sf(F, 3, 6), rel=1e-9)
    assert out["means"]["c0"][0] == pytest.approx(y[0, 0])
