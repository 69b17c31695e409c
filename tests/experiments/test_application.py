"""The application scenario's force saving and first screen (its paired statistics: tests/analysis/test_paired.py)."""

import pytest

from coassist.experiments.application import force_saving
from coassist.experiments.report import Claim, Section, render_html


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
