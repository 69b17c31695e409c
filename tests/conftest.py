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
