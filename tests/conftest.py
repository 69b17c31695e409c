"""Suite-wide checks of how the tests are run (``./dev test``)."""

from __future__ import annotations

from pathlib import Path

import pytest

# ``./dev test`` runs the real-time tests alone, after the rest, and collects only the files that hold
# them: those whose text names the marker (``grep -l 'mark.realtime'``), so that second run does not pay the
# whole suite's imports again (~25 CPU-s of collection for 24 tests). The marker must therefore be spelt
# out in the test's own file; this refuses a realtime test the grep would miss, before any test runs.
REALTIME_TEXT = "mark.realtime"


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects them: every collected test is seen
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    seen: dict[Path, bool] = {}
    for item in items:
        if item.get_closest_marker("realtime") is None:
            continue
        path = Path(item.path)
        if path not in seen:
            seen[path] = REALTIME_TEXT in path.read_text(encoding="utf-8")
        if not seen[path]:
            raise pytest.UsageError(
                f"{item.nodeid} is marked realtime but its file does not contain {REALTIME_TEXT!r}: "
                "./dev test would not run it (write the marker as pytest.mark.realtime in that file)"
            )
    longest_first(items)


# ``./dev test`` runs the suite on two workers with ``--dist worksteal``: each worker is handed one half of
# the collection, in order, and one that runs out takes the last tests of the other's queue. A long test
# late in the order is then run last, alone, while the other worker idles; and the tests of a module-scoped
# fixture split between the workers pay for it twice. So the longest tests (CI's --durations, 2 cores, on
# 4e41a44) go first, whole files where a module fixture serves several, in this order; the rest keep theirs.
LONGEST_FIRST = (
    "tests/experiments/test_reproduce.py::",  # the tiny preset's whole pipeline: the module fixture tiny_run
    "tests/study/test_browser.py::",  # two studies in Chromium, paced trials (62 s and 47 s)
    "tests/test_readme.py::test_fast_blocks_run",  # 27 s
    "tests/study/test_calibration.py::test_kill_9_during_the_block_and_during_the_fit_then_resume",  # 26 s
    "tests/experiments/test_source_training.py::",  # 24 s, a module fixture
    "tests/experiments/test_prefetch.py::",  # 23 s, a module's shared pool
    "tests/sim/test_world.py::test_named_intents_on_the_pool_run_in_lockstep_groups_bit_for_bit_as_alone",  # 21 s
    "tests/study/test_comparison.py::test_the_same_plan_runs_on_the_mujoco_ur5",  # 19 s
)


def longest_first(items: list[pytest.Item]) -> None:
    """Put the tests LONGEST_FIRST names first, in its order (./dev test schedules them first)."""

    def rank(item: pytest.Item) -> int:
        return next((k for k, p in enumerate(LONGEST_FIRST) if item.nodeid.startswith(p)), len(LONGEST_FIRST))

    items[:] = sorted(items, key=rank)  # stable: each file's tests keep their order
