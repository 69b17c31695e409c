"""Verdicts across seeds (issue 35): the per-claim table against hand-made summaries."""

import pytest

from coassist.experiments.seeds import SeedClaim, claims_across_seeds, parse_seeds, seeds_section


def _summary(*claims):
    return {"claims": [{"claim": text, "holds": holds, "evidence": evidence} for text, holds, evidence in claims]}


def test_a_claim_that_holds_on_two_of_three_seeds_says_so():
    summaries = {
        0: _summary(("A", True, "a0"), ("B", True, "b0"), ("C", False, "c0")),
        1: _summary(("A", True, "a1"), ("B", False, "b1"), ("C", False, "c1")),
        2: _summary(("A", True, "a2"), ("B", True, "b2"), ("C", False, "c2")),
    }
    claims = claims_across_seeds(summaries)
    assert [c.text for c in claims] == ["A", "B", "C"]
    a, b, c = claims
    assert (a.held, a.checked, a.status) == (3, 3, "robust")
    assert (b.held, b.checked, b.status) == (2, 3, "seed-dependent")
    assert (c.held, c.checked, c.status) == (0, 3, "not holding")
    assert b.per_seed == {0: (True, "b0"), 1: (False, "b1"), 2: (True, "b2")}
    assert b.to_dict()["seeds"]["1"] == {"holds": False, "evidence": "b1"} and b.to_dict()["holds_on"] == 2
    section = seeds_section(claims, (0, 1, 2))
    ((_, header, rows),) = section.tables
    assert header == ["claim", "holds on", "status", "seed 0", "seed 1", "seed 2"]
    assert rows[1] == ["B", "2 of 3", "seed-dependent", "holds: b0", "does not hold: b1", "holds: b2"]


def test_a_claim_one_seed_did_not_check_counts_the_others():
    # seed 1 ran without the real recordings: its claim is missing, not failed
    claims = claims_across_seeds({0: _summary(("R", True, "r0")), 1: _summary(), 2: _summary(("R", True, "r2"))})
    (r,) = claims
    assert r.per_seed == {0: (True, "r0"), 1: None, 2: (True, "r2")}
    assert (r.held, r.checked, r.status) == (2, 2, "robust")
    assert SeedClaim("x", {0: None}).status == "not holding"
    with pytest.raises(ValueError, match="twice"):
        claims_across_seeds({0: _summary(("A", True, ""), ("A", False, ""))})


def test_seeds_option():
    assert parse_seeds("3") == (0, 1, 2)
    assert parse_seeds("0,1,2") == (0, 1, 2) and parse_seeds("5,2") == (5, 2) and parse_seeds("4,") == (4,)
    for bad in ("0", "-1,2", "1,1", "a", ""):
        with pytest.raises(ValueError, match="--seeds"):
            parse_seeds(bad)
