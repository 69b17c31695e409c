"""The application scenario's paired statistics against scipy and hand-computed cases."""

import numpy as np
import pytest
from scipy import stats

from coassist.experiments.application import force_saving, paired_difference
from coassist.experiments.report import Claim, Section, render_html


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


def test_force_saving_per_trial():
    # 1 − 1/4 = 0.75 and 1 − 2/4 = 0.5: mean 0.625, population std 0.125; a zero baseline is left out
    mean, std = force_saving([1.0, 2.0, 3.0], [4.0, 4.0, 0.0])
    assert (mean, std) == pytest.approx((0.625, 0.125))


def test_the_answer_comes_before_the_claims_and_sections():
    head = Section("The answer: does the assistance help?")
    head.tables.append(("caption", ["object"], [["board"]]))
    body = Section("1. A section")
    body.claims.append(Claim("a claim", True, "evidence"))  # so that the claims table is rendered at all
    page = render_html("t", "intro", [body], head)
    assert page.index("The answer") < page.index("The thesis' claims, checked") < page.index("1. A section")
