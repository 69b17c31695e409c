"""The study's order-effect test against the Latin square ANOVA by hand, and the report's interval of a mean
difference against the paired t interval by hand (the other paired statistics: tests/analysis/test_paired.py)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy import stats

from coassist.analysis.paired import paired_comparison
from coassist.study.stats import order_effect


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


def test_the_reports_mean_difference_interval_is_the_paired_t_interval_by_hand():
    """Four participants, d = 1.0, 0.2, 3.0, 0.2: d̄ ± t_{0.975, 3} · s_d / √4 = 1.1 ± 2.103 = (−1.003, 3.203), which
    holds 0 as both tests say (p_t 0.195, Wilcoxon 0.125); the percentile bootstrap the report gave before,
    (0.2, 2.3), left 0 out (it covers 74–88 % for a nominal 95 % at 3–8 pairs)."""
    a = {"S01": 10.0, "S02": 12.0, "S03": 11.0, "S04": 13.5}
    b = {"S01": 9.0, "S02": 11.8, "S03": 8.0, "S04": 13.3}
    c = paired_comparison("f_rms", "A", "B", a, b, seed=0)
    d = np.array([a[k] - b[k] for k in sorted(a)])
    half = stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size)
    assert half == pytest.approx(2.1030, abs=1e-4)
    assert c.mean_diff == pytest.approx(1.1, abs=1e-12)
    assert c.mean_diff_ci == pytest.approx((1.1 - half, 1.1 + half), abs=1e-12)
    assert c.mean_diff_ci[0] < 0 < c.mean_diff_ci[1]
    # two pairs with the same difference: no width; one pair: no interval
    same = paired_comparison("f_rms", "A", "B", {"S01": 2.0, "S02": 3.0}, {"S01": 1.0, "S02": 2.0})
    assert same.mean_diff_ci == (1.0, 1.0)
    assert all(math.isnan(v) for v in paired_comparison("f_rms", "A", "B", {"S01": 2.0}, {"S01": 1.0}).mean_diff_ci)


def test_what_the_sample_can_show_names_the_t_interval_not_wide_bootstraps():
    from coassist.study.summarise import sample_limits

    lines = sample_limits(4, 18, simulated=False)
    assert lines[2] == (
        "What it can show: whether the differences point the same way for every participant (the lines), and how "
        "large they are: the mean difference with its paired t interval (95 % if the differences are roughly "
        "normal). d_z and r are shown without an interval: a percentile bootstrap of so few pairs covers far less "
        "than it claims (74–88 % for a nominal 95 % at 3–8 participants)."
    )
    assert not any("bootstrap intervals that are wide" in line for line in lines)


def test_the_limits_are_over_the_comparisons_own_n_and_holms_m_counts_the_tests_that_ran():
    """Two comparisons over four participants and one over three (a participant without one of its conditions)
    whose differences are all the same (no paired t p): the limits give 3 to 4 participants, 2/2^3 = 0.25 and
    2/2^4 = 0.125, and Holm's m is the two comparisons with a t p, not three. Before, the limits counted everyone
    with a whole block, and m every comparison."""
    from coassist.study.summarise import comparison_limits

    a = {"S01": 10.0, "S02": 12.0, "S03": 11.0, "S04": 13.5}
    b = {"S01": 9.0, "S02": 11.8, "S03": 8.0, "S04": 13.3}
    four = paired_comparison("f_rms", "A", "B", a, b, n_boot=200)
    other = paired_comparison("jerk", "A", "B", a, b, n_boot=200)
    three = paired_comparison("f_rms", "A", "C", a, {"S01": 9.0, "S02": 11.0, "S03": 10.0}, n_boot=200)
    assert (four.n, three.n) == (4, 3) and math.isfinite(four.p_t) and math.isnan(three.p_t)
    lines = comparison_limits([four, other, three], simulated=False)
    assert lines[0] == (
        "The comparisons are over 3 to 4 participants (those with both conditions; each comparison's n is in its "
        "table): the smallest two-sided p a Wilcoxon signed-rank test can give is 2/2^3 = 0.25 with 3, 2/2^4 = 0.125 "
        "with 4 — it cannot reach 0.05 whatever the data; its p values show direction and consistency, not "
        "significance."
    )
    assert "Holm's correction over 2 tests" in lines[1] and lines[1].startswith("A paired t test on 4 participants")

    # the d_z quoted reach 80 % power by hand: P(|T| > t_{1−α/2, n−1}), T noncentral t (n − 1, d_z √n); scipy's
    # lower tail is NaN at a large noncentrality, where it is below P(Z < −nc) = Φ(−nc): 0 here
    def power(d, alpha, n):
        tc, nc = stats.t.ppf(1 - alpha / 2, n - 1), d * math.sqrt(n)
        lower = stats.nct.cdf(-tc, n - 1, nc)
        assert math.isfinite(lower) or stats.norm.cdf(-nc) < 1e-10
        return stats.nct.sf(tc, n - 1, nc) + (lower if math.isfinite(lower) else 0.0)

    quoted = [float(v) for v in re.findall(r"≥ ([0-9.]+)", lines[1])]
    assert len(quoted) == 4  # at 4 participants, α and α/2; at 3, the same
    for d, alpha, n in zip(quoted, (0.05, 0.025, 0.05, 0.025), (4, 4, 3, 3), strict=True):
        assert power(d - 0.005, alpha, n) < 0.8 < power(d + 0.005, alpha, n)
    # one n for every comparison: the sentence as before
    assert comparison_limits([four, other], simulated=False)[0].startswith(
        "4 participants: the smallest two-sided p a Wilcoxon signed-rank test can give is 2/2^4 = 0.125 —"
    )


def test_the_wilcoxon_floor_is_over_the_pairs_it_ranks_not_the_participants():
    """Six participants, one of whose differences is zero: scipy's Wilcoxon test (zeros dropped) ranks five pairs,
    and its smallest two-sided p is then 2/2^5 = 0.0625, reached when all five point the same way; the limits said
    2/2^6 = 0.031 (below 0.05) for that comparison before."""
    from coassist.study.summarise import comparison_limits

    a = {f"S0{i}": 10.0 + i for i in range(1, 7)}
    b = {pid: v - (0.0 if pid == "S01" else 0.5 + 0.1 * i) for i, (pid, v) in enumerate(a.items())}
    tie = paired_comparison("f_rms", "A", "B", a, b, n_boot=200)
    assert (tie.n, tie.n_wilcoxon) == (6, 5)
    floor = stats.wilcoxon([a[p] - b[p] for p in a], zero_method="wilcox", alternative="two-sided").pvalue
    assert math.isclose(floor, 2 / 2**5, rel_tol=1e-12)  # all five ranked pairs the same way: the floor itself
    assert comparison_limits([tie], simulated=False)[0] == (
        "6 participants: the smallest two-sided p a Wilcoxon signed-rank test can give is 2/2^5 = 0.0625 (over the "
        "pairs it ranks: a zero difference is dropped) — it cannot reach 0.05 whatever the data; its p values show "
        "direction and consistency, not significance."
    )
    c = {pid: v - 0.3 - 0.05 * i for i, (pid, v) in enumerate(a.items())}
    full = paired_comparison("f_rms", "A", "C", a, c, n_boot=200)
    assert comparison_limits([tie, full], simulated=False)[0].startswith(
        "6 participants: the smallest two-sided p a Wilcoxon signed-rank test can give is 2/2^5 = 0.0625 with 5, "
        "2/2^6 = 0.0312 with 6 (over the pairs it ranks: a zero difference is dropped) — with five or fewer"
    )


def test_the_detectable_effect_after_holm_is_not_understated_where_scipys_tail_is_nan():
    """Four participants, 18 tests: 80 % power at α/18 needs d_z ≥ 5.74 (200 000 simulated samples of four normal
    differences with d_z = 5.735 reject at 0.05/18 in 80.05 %). Before, scipy's NaN lower tail was taken as power 1
    and the sentence said 3.74, an effect such a test detects in 43 % of samples."""
    from coassist.study.summarise import sample_limits

    line = sample_limits(4, 18, simulated=False)[1]
    assert "d_z ≥ 2.13 (≥ 5.74 for the smallest p after Holm's correction over 18 tests)" in line


@pytest.mark.parametrize("n", [6, 9, 10])
def test_the_limits_say_when_holms_correction_leaves_the_wilcoxon_column_no_way_to_reach_005(n):
    """The review of 3063e1e: six participants, 18 comparisons, every difference the same way: each exact Wilcoxon
    p is its floor 2/2^6 = 0.03125 (scipy's, below), and Holm's smallest adjusted p is 18 × 0.03125 = 0.5625, so the
    report's Holm-corrected Wilcoxon column could never show significance, and the limits said only the floor."""
    from coassist.analysis.paired import holm_family
    from coassist.study.summarise import comparison_limits

    rng = np.random.default_rng(n)
    a = {f"S{i:02d}": 10.0 + i for i in range(1, n + 1)}
    comps = []
    for k in range(18):  # every difference positive, magnitudes distinct: the exact test's floor each time
        b = {pid: v - 0.5 - rng.uniform(0, 1) for pid, v in a.items()}
        comps.append(paired_comparison(f"m{k}", "A", f"B{k}", a, b, n_boot=50))
    floor = stats.wilcoxon([1.0 + 0.1 * i for i in range(n)], alternative="two-sided").pvalue
    assert math.isclose(floor, 2 / 2**n, rel_tol=1e-12) and all(math.isclose(c.p_wilcoxon, floor) for c in comps)
    smallest = min(c.p_wilcoxon_holm for c in holm_family(comps))
    assert math.isclose(smallest, min(1.0, 18 * 2 / 2**n), rel_tol=1e-12)  # by hand: Holm's first step, m·p
    said = [line for line in comparison_limits(comps, simulated=False) if line.startswith("After Holm's")]
    if smallest > 0.05:  # n = 6: 0.5625; n = 9: 18/256 = 0.0703
        assert said == [
            f"After Holm's correction over the 18 Wilcoxon tests, the smallest adjusted p is at least 18·2/2^{n} = "
            f"{smallest:.3g}: that column cannot reach 0.05 whatever the data; read it for direction and "
            "consistency, the paired t test for significance."
        ]
    else:  # n = 10: 18/512 = 0.0352 can reach it
        assert said == [] and n == 10
