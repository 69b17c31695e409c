"""tests/conftest.py's LONGEST_FIRST names tests that exist, and the collection puts them first, in its order."""

from __future__ import annotations

import re
from pathlib import Path

from .conftest import LONGEST_FIRST, longest_first

ROOT = Path(__file__).resolve().parents[1]


def test_every_longest_first_entry_names_a_test_file_or_function():
    for entry in LONGEST_FIRST:
        file, _, name = entry.partition("::")
        assert (ROOT / file).is_file(), entry
        if name:  # a test of that file: renamed, it would silently lose its place
            assert re.search(rf"^def {re.escape(name)}\(", (ROOT / file).read_text(), re.M), entry


class _Item:
    def __init__(self, nodeid: str):
        self.nodeid = nodeid


def test_the_longest_go_first_in_their_order_and_the_rest_keep_theirs():
    ids = [
        "tests/a.py::test_1",
        f"{LONGEST_FIRST[1]}test_x",
        "tests/b.py::test_2",
        f"{LONGEST_FIRST[0]}test_y",
        f"{LONGEST_FIRST[1]}test_w",
        "tests/a.py::test_3",
    ]
    items = [_Item(i) for i in ids]
    longest_first(items)  # type: ignore[arg-type]
    assert [i.nodeid for i in items] == [ids[3], ids[1], ids[4], ids[0], ids[2], ids[5]]
