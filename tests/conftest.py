"""Suite-wide checks of how the tests are run (``./dev test``)."""

from __future__ import annotations

import os
from collections.abc import Generator
from pathlib import Path

import pytest

# One BLAS and torch thread per xdist worker, as ``./dev test`` sets them for its whole run: several workers on a
# few cores, each with a thread team of its own, spin while another worker holds the core. The main part under a
# plain ``pytest -n 3`` took 364 s and 638 CPU-s against 285 s and 495 CPU-s with one thread each (docs/performance.md,
# "The suite, once more"). A worker imports this before numpy or torch, which read these when they load; a value
# already set (./dev's, or the caller's) is kept.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_name, "1")

# ``./dev test`` runs the real-time tests after the rest (two at a time, then those also marked ``alone`` one at a
# time: pyproject.toml's markers), and collects only the files that hold
# them: those whose text names the marker (``grep -l 'mark.realtime'``), so that second run does not pay the
# whole suite's imports again (~25 CPU-s of collection for 24 tests). The marker must therefore be spelt
# out in the test's own file; this refuses a realtime test the grep would miss, before any test runs.
REALTIME_TEXT = "mark.realtime"


@pytest.hookimpl(wrapper=True)  # before ``-m`` deselects them every collected test is seen; after it, ordered
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> Generator[None, None, None]:
    seen: dict[Path, bool] = {}
    for item in items:
        if item.get_closest_marker("realtime") is None:
            if item.get_closest_marker("alone") is not None:
                raise pytest.UsageError(
                    f"{item.nodeid} is marked alone but not realtime: ./dev test runs only realtime tests alone "
                    "(mark it pytest.mark.realtime too)"
                )
            continue
        path = Path(item.path)
        if path not in seen:
            seen[path] = REALTIME_TEXT in path.read_text(encoding="utf-8")
        if not seen[path]:
            raise pytest.UsageError(
                f"{item.nodeid} is marked realtime but its file does not contain {REALTIME_TEXT!r}: "
                "./dev test would not run it (write the marker as pytest.mark.realtime in that file)"
            )
    yield  # the other plugins' hooks: ``-m`` deselects
    longest_first(items, workers_of(config))  # the tests xdist shares out: those that run


# ``./dev test`` runs the suite on xdist workers with ``--dist worksteal``: at the start worker i is handed the next
# ``len(pending) // (n - i)`` tests of the collection, in order (a contiguous share), and one that runs out takes
# the last tests of the longest queue, never the head of one. A long test late in the order is then run last,
# alone, while the others idle; the tests of a module-scoped fixture split between workers pay for it twice; and
# long tests all at the head of the first share run one after another on one worker (~255 s of them in CI's
# durations at 9959460: with three workers that chain, not the cores, would bound the main part). So each entry
# here (CI's --durations, 2 cores; a whole file where a module fixture serves several tests, or where two
# Chromium studies must not run at once) goes, in this order, to the head of the share of the worker with the
# fewest of these seconds so far (longest first: LPT); each share is then filled with the rest in their order.
# Entries: (node id prefix, seconds): --durations=0 of ./dev test's main part on a fresh clone of 2434987 (2 cores,
# three workers, 2026-12-03), a file's tests summed. Before, the table held 9959460's two-worker figures, which put
# the tiny run's module at 45 s and test_prefetch.py at 40 s where they now take 85 s and 72 s (issue 44).
LONGEST_FIRST: tuple[tuple[str, float], ...] = (
    ("tests/study/test_browser.py::", 122.6),  # two studies in Chromium, paced trials (~60 s each)
    ("tests/experiments/test_reproduce.py::", 84.8),  # the tiny preset's whole pipeline: the module fixture tiny_run
    ("tests/experiments/test_prefetch.py::", 72.3),  # a module's shared pool
    ("tests/sim/test_ray_backend.py::", 27.5),
    ("tests/study/test_calibration.py::test_kill_9_during_the_block_and_during_the_fit_then_resume", 23.4),
    ("tests/study/test_page.py::", 21.9),  # two studies on the page's websocket, paced trials
    ("tests/test_registered_entries.py::", 19.1),
    ("tests/experiments/test_source_training.py::", 17.3),  # a module fixture
    ("tests/play/test_browser.py::", 12.7),  # Chromium
    ("tests/test_readme.py::test_fast_blocks_run", 10.6),
    (
        "tests/sim/test_trial_runner.py::test_named_intents_on_the_pool_run_in_lockstep_groups_bit_for_bit_as_alone",
        10.5,
    ),
    ("tests/study/test_folder.py::test_kill_9_mid_trial_then_resume_keeps_every_finished_trial_and_the_order", 8.6),
    (
        "tests/faults/test_run_record_faults.py::test_a_kill_during_drive_mcap_never_leaves_a_trial_beside_another_runs_mcap",
        4.7,
    ),
)


def workers_of(config: pytest.Config) -> int:
    """How many workers share the collection the way :func:`longest_first` plans for: xdist's under
    ``--dist worksteal`` (in each worker, whose own ``dist`` option xdist sets to ``no``: read from the
    command line it was started with), else 1."""
    workerinput = getattr(config, "workerinput", None)
    if workerinput is None:
        return 1
    args = [str(a) for a in config.invocation_params.args]
    dist = [b for a, b in zip(args, args[1:]) if a == "--dist"] + [a[7:] for a in args if a.startswith("--dist=")]
    return int(workerinput["workercount"]) if dist[-1:] == ["worksteal"] else 1


def longest_first(items: list[pytest.Item], workers: int = 1) -> None:
    """Reorder ``items`` for ``workers`` workers under ``--dist worksteal``: each LONGEST_FIRST entry's
    tests (in their order) at the head of the share of the worker with the fewest of their seconds so far
    (entries in LONGEST_FIRST's order, longest first), the other tests after them in their order, each
    share as long as xdist's first hand-out makes it. One worker: the entries first, in their order."""

    def rank(item: pytest.Item) -> int:
        return next((k for k, (p, _) in enumerate(LONGEST_FIRST) if item.nodeid.startswith(p)), len(LONGEST_FIRST))

    groups: list[list[pytest.Item]] = [[] for _ in range(len(LONGEST_FIRST) + 1)]
    for item in items:
        groups[rank(item)].append(item)
    rest = groups.pop()
    heads: list[list[pytest.Item]] = [[] for _ in range(workers)]
    seconds = [0.0] * workers
    for k, group in enumerate(groups):
        if group:
            w = min(range(workers), key=lambda i: (seconds[i], i))
            heads[w] += group
            seconds[w] += LONGEST_FIRST[k][1]
    ordered: list[pytest.Item] = []
    left, taken = len(items), 0
    for w in range(workers):
        share = left // (workers - w)  # xdist's worksteal: the next len(pending) // (idle workers left)
        left -= share
        fill = max(0, share - len(heads[w])) if w < workers - 1 else len(rest)
        ordered += heads[w] + rest[taken : taken + fill]
        taken += fill
    items[:] = ordered
