"""Counterbalancing and blinding: the balanced Latin square (Williams design) and the labels A, B, C….

Williams design (Williams 1949) for n conditions numbered 0 … n−1. The first row
alternates from both ends, ::

    r_0 = (0, 1, n−1, 2, n−2, 3, …)          r_i[j] = (r_0[j] + i) mod n,  i = 0 … n−1

For even n the n rows are a Latin square (every condition once in every position) in
which every ordered pair (a, b), a ≠ b, stands next to each other (a just before b)
exactly once: r_0's successive differences r_0[j+1] − r_0[j] = 1, −2, 3, −4, … are all
the non-zero residues mod n once, and adding i to both ends keeps a difference. For odd n
no such square exists; the n rows and their reverses (2n rows) put every condition in
every position twice and every ordered pair next to each other exactly twice.

Participants take the rows in the order they first run (participant p: row p mod rows),
so a study of a whole number of squares is balanced; the order each one got is recorded
in the study folder (:mod:`coassist.study.folder`), never recomputed.

Blinding: the page shows a condition by its label only, A, B, C… in a seeded random
assignment of labels to conditions (not the plan's order), kept in the study folder.
"""

from __future__ import annotations

import string

import numpy as np

from coassist._checks import check_int

__all__ = ["blinding_labels", "latin_square_rows", "participant_order"]


def latin_square_rows(n: int) -> list[list[int]]:
    """The rows of the balanced Latin square for ``n`` conditions (module docstring): n rows for an even
    n, 2n for an odd n (the square and its mirror), each a permutation of 0 … n−1."""
    n = check_int(n, "n", 1)
    first = [0]
    lo, hi = 1, n - 1
    for j in range(1, n):
        if j % 2:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    rows = [[(c + i) % n for c in first] for i in range(n)]
    if n % 2:
        rows += [list(reversed(r)) for r in rows]
    return rows


def participant_order(row_index: int, n: int) -> list[int]:
    """The condition order of the participant given row ``row_index`` (taken modulo the rows)."""
    rows = latin_square_rows(n)
    return rows[check_int(row_index, "row_index", 0) % len(rows)]


def blinding_labels(n: int, seed: int) -> list[str]:
    """``labels[i]``: the label (A, B, C…) condition i of the plan is shown as, a seeded permutation."""
    n = check_int(n, "n", 1, 26)
    perm = np.random.default_rng(np.random.SeedSequence([check_int(seed, "seed", 0), 0x5EED])).permutation(n)
    return [string.ascii_uppercase[int(p)] for p in perm]
