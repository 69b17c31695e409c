"""The study's order-effect test against the Latin square ANOVA by hand (the paired statistics:
tests/analysis/test_paired.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

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
