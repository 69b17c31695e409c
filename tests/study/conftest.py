"""Shared plans of the study tests: small enough to run in seconds on the point-mass page world."""

from __future__ import annotations

from pathlib import Path

import pytest

COMPARISON = """
[study]
name = "comparison"
protocol = "comparison"
world = "{world}"
participants = 4
seed = 3

[[condition]]
name = "assistive"
controller = "cooperative"

[[condition]]
name = "impedance"
controller = "impedance"

[[condition]]
name = "manual"
controller = "manual"

[trials]
tasks = ["linear", "curved"]
per_condition = {per_condition}
practice = {practice}
{timing}

[rest]
between_conditions = 30.0
"""


def comparison_plan(
    folder: Path,
    *,
    world: str = "play",
    per_condition: int = 2,
    practice: int = 1,
    timing: str = "motion_time = 3.0\ndwell = 1.0",
) -> Path:
    """A 3-condition comparison plan written into ``folder``; returns the file."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "plan.toml"
    path.write_text(COMPARISON.format(world=world, per_condition=per_condition, practice=practice, timing=timing))
    return path


@pytest.fixture
def comparison_file(tmp_path: Path) -> Path:
    return comparison_plan(tmp_path / "plans")
