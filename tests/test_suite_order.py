"""tests/conftest.py's LONGEST_FIRST names tests that exist, and the collection puts them first: in its order on
one worker, at the heads of the workers' first shares under xdist's ``--dist worksteal``; its checks of the realtime
and alone markers (what ./dev test's realtime runs would miss is refused)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from .conftest import LONGEST_FIRST, longest_first, pytest_collection_modifyitems, workers_of

ROOT = Path(__file__).resolve().parents[1]


def test_every_longest_first_entry_names_a_test_file_or_function():
    for entry, seconds in LONGEST_FIRST:
        file, _, name = entry.partition("::")
        assert (ROOT / file).is_file(), entry
        if name:  # a test of that file: renamed, it would silently lose its place
            assert re.search(rf"^def {re.escape(name)}\(", (ROOT / file).read_text(), re.M), entry
        assert seconds > 0, entry
    assert [s for _, s in LONGEST_FIRST] == sorted((s for _, s in LONGEST_FIRST), reverse=True)  # longest first


class _Item:
    def __init__(self, nodeid: str):
        self.nodeid = nodeid


def test_the_longest_go_first_in_their_order_and_the_rest_keep_theirs():
    ids = [
        "tests/a.py::test_1",
        f"{LONGEST_FIRST[1][0]}test_x",
        "tests/b.py::test_2",
        f"{LONGEST_FIRST[0][0]}test_y",
        f"{LONGEST_FIRST[1][0]}test_w",
        "tests/a.py::test_3",
    ]
    items = [_Item(i) for i in ids]
    longest_first(items)  # type: ignore[arg-type]
    assert [i.nodeid for i in items] == [ids[3], ids[1], ids[4], ids[0], ids[2], ids[5]]


class _Node:
    """A worker as xdist's scheduler sees it: what it was sent to run."""

    shutting_down = False

    def __init__(self, k: int) -> None:
        self.sent: list[int] = []
        self.gateway = type("Gateway", (), {"id": f"gw{k}"})()

    def send_runtest_some(self, indices) -> None:
        self.sent += list(indices)


@pytest.mark.parametrize("workers", [2, 3])
def test_each_worker_is_handed_its_longest_first_at_the_head_of_its_share(workers):
    """xdist's own worksteal scheduler (not a copy of its rule) hands each worker a share that begins with
    the LONGEST_FIRST entries planned for it, whole; their seconds as even as the greedy plan makes them."""
    from xdist.scheduler.worksteal import WorkStealingScheduling

    ids = [f"tests/t{k // 7}.py::test_{k}" for k in range(900)]
    long_ids = [f"{p}test_{j}" if p.endswith("::") else p for p, _ in LONGEST_FIRST for j in range(2)]
    long_ids = list(dict.fromkeys(long_ids))  # an entry naming one test: once
    items = [_Item(i) for i in ids[:450] + long_ids + ids[450:]]
    longest_first(items, workers)  # type: ignore[arg-type]
    collection = [i.nodeid for i in items]

    class Config:
        def getvalue(self, name):
            return [f"{workers}*popen"] if name == "tx" else None

    sched = WorkStealingScheduling(Config())  # type: ignore[arg-type]
    nodes = [_Node(k) for k in range(workers)]
    for node in nodes:
        sched.add_node(node)  # type: ignore[arg-type]
        sched.add_node_collection(node, collection)  # type: ignore[arg-type]
    sched.schedule()
    assert sorted(k for n in nodes for k in n.sent) == list(range(len(collection)))

    def entry(nodeid: str) -> int | None:
        return next((k for k, (p, _) in enumerate(LONGEST_FIRST) if nodeid.startswith(p)), None)

    seconds = []
    for node in nodes:
        share = [collection[k] for k in node.sent]
        heads = [entry(i) for i in share]
        n_long = sum(h is not None for h in heads)
        assert all(h is not None for h in heads[:n_long]) and not any(h is not None for h in heads[n_long:])
        seconds.append(sum(LONGEST_FIRST[k][1] for k in dict.fromkeys(h for h in heads if h is not None)))
    # every entry on one worker, whole
    owners = {entry(collection[k]): w for w, n in enumerate(nodes) for k in n.sent if entry(collection[k]) is not None}
    assert sorted(owners) == list(range(len(LONGEST_FIRST)))
    for k in range(len(LONGEST_FIRST)):
        assert len({w for w, n in enumerate(nodes) for i in n.sent if entry(collection[i]) == k}) == 1
    # greedy (LPT): no worker has more than the least loaded one plus the longest entry
    assert max(seconds) - min(seconds) <= LONGEST_FIRST[0][1]
    assert sum(seconds) == pytest.approx(sum(s for _, s in LONGEST_FIRST))


def test_the_plan_is_for_xdists_workers_under_worksteal_alone():
    """In a worker xdist sets the ``dist`` option to ``no``: the mode is read from the command line it ran."""

    class Config:
        def __init__(self, args, workers=None):
            self.invocation_params = type("Params", (), {"args": tuple(args)})()
            if workers is not None:
                self.workerinput = {"workercount": workers}

    assert workers_of(Config(["-n", "3", "--dist", "worksteal"], 3)) == 3  # type: ignore[arg-type]
    assert workers_of(Config(["-n", "2", "--dist=worksteal", "-q"], 2)) == 2  # type: ignore[arg-type]
    assert workers_of(Config(["-n", "3", "--dist", "load"], 3)) == 1  # type: ignore[arg-type]
    assert workers_of(Config(["-n", "3"], 3)) == 1  # type: ignore[arg-type]
    assert workers_of(Config(["--dist", "worksteal"])) == 1  # type: ignore[arg-type]  # not a worker


class _Marked:
    def __init__(self, path: Path, markers: set[str]):
        self.path, self.nodeid, self.markers = path, f"{path.name}::test_a", markers

    def get_closest_marker(self, name: str) -> object | None:
        return object() if name in self.markers else None


def test_a_realtime_test_must_say_so_in_its_file_and_alone_needs_realtime(tmp_path):
    # ./dev test's realtime runs collect the files that spell the marker out (grep), and run only realtime tests
    # alone: a test either would miss is refused before any test runs
    spelt, bare = tmp_path / "test_spelt.py", tmp_path / "test_bare.py"
    spelt.write_text("import pytest\n\n\n@pytest.mark.realtime\n@pytest.mark.alone\ndef test_a():\n    pass\n")
    bare.write_text("import pytest\n\nMARKS = (pytest.mark.slow,)\n")
    for item in (_Marked(spelt, {"realtime", "alone"}), _Marked(spelt, {"realtime"}), _Marked(bare, set())):
        next(pytest_collection_modifyitems(None, [item]))  # the checks pass: the hook goes on to the others' hooks
    with pytest.raises(pytest.UsageError, match="does not contain 'mark.realtime'"):
        next(pytest_collection_modifyitems(None, [_Marked(bare, {"realtime"})]))
    with pytest.raises(pytest.UsageError, match="marked alone but not realtime"):
        next(pytest_collection_modifyitems(None, [_Marked(spelt, {"alone"})]))
