"""The balanced Latin square (Williams design) and the blinding labels."""

from __future__ import annotations

from collections import Counter

import pytest

from coassist.study.design import blinding_labels, latin_square_rows, participant_order


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6, 7, 8])
def test_every_condition_in_every_position_equally_often(n):
    rows = latin_square_rows(n)
    assert len(rows) == (n if n % 2 == 0 else 2 * n)
    for row in rows:
        assert sorted(row) == list(range(n))
    for pos in range(n):
        counts = Counter(row[pos] for row in rows)
        assert set(counts) == set(range(n)) and len(set(counts.values())) == 1


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6, 7, 8])
def test_every_ordered_pair_adjacent_equally_often(n):
    rows = latin_square_rows(n)
    pairs = Counter((a, b) for row in rows for a, b in zip(row, row[1:]))
    expected = {(a, b) for a in range(n) for b in range(n) if a != b}
    assert set(pairs) == expected
    # once each for an even n (a Williams square), twice for an odd n (the square and its mirror)
    assert set(pairs.values()) == ({1} if n % 2 == 0 else {2})


def test_participants_take_the_rows_in_turn():
    assert [participant_order(i, 4) for i in range(5)] == [*latin_square_rows(4), latin_square_rows(4)[0]]
    assert participant_order(0, 4) == [0, 1, 3, 2]  # the textbook first row of n = 4


def test_blinding_labels_are_a_seeded_permutation():
    labels = blinding_labels(5, seed=7)
    assert sorted(labels) == list("ABCDE")
    assert blinding_labels(5, seed=7) == labels
    assert any(blinding_labels(5, seed=s) != labels for s in range(1, 6))
