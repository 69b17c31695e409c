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


@pytest.fixture(scope="session")
def _finished_study(tmp_path_factory) -> Path:
    """A comparison of three conditions, one measured trial each, no practice, run to the end by simulated
    participant S01 (about a second): tests copy it (:func:`finished_study`) before they edit it."""
    from coassist.study.folder import init_study
    from coassist.study.runner import ParticipantRun

    root = tmp_path_factory.mktemp("finished")
    study = init_study(comparison_plan(root / "plans", per_condition=1, practice=0), root / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    return study.folder


@pytest.fixture
def finished_study(_finished_study, tmp_path) -> Path:
    """A copy of the finished study (:func:`_finished_study`) of this test's own."""
    import shutil

    return Path(shutil.copytree(_finished_study, tmp_path / "study"))


CALIBRATED = """
[study]
name = "calibrated"
protocol = "comparison"
world = "play"
participants = 2
seed = 3

[calibration]
trials = {trials}
asked = {asked}

[[condition]]
name = "mg"
controller = "manual"

[[condition]]
name = "person"
controller = "cooperative"
intent = "calibrated"

[trials]
tasks = ["curved"]
per_condition = 1
practice = 0
motion_time = 3.0
dwell = {dwell}

[rest]
between_conditions = {rest}
"""


def calibrated_plan(folder: Path, *, trials: int = 3, dwell: float = 1.0, rest: float = 0.0, asked: int = 0) -> Path:
    """MG against the participant's own person model after a calibration block of ``trials`` (then up to ``asked``
    trials asking for a way shown too seldom), written into ``folder``; returns the file."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "plan.toml"
    path.write_text(CALIBRATED.format(trials=trials, dwell=dwell, rest=rest, asked=asked))
    return path


@pytest.fixture(scope="session")
def _calibrated_study(tmp_path_factory) -> Path:
    """The calibrated comparison run to its end by simulated participant S01 (seconds): tests copy it
    (:func:`calibrated_study`) before they edit it."""
    from coassist.study.folder import init_study
    from coassist.study.runner import ParticipantRun

    root = tmp_path_factory.mktemp("calibrated")
    study = init_study(calibrated_plan(root / "plans"), root / "study")
    said: list[str] = []
    with ParticipantRun(study, "S01", simulate=True, say=said.append) as run:
        run.run()
    (root / "said.txt").write_text("".join(line + "\n" for line in said))  # what the console said, beside the folder
    return study.folder


@pytest.fixture
def calibrated_study(_calibrated_study, tmp_path) -> Path:
    """A copy of the finished calibrated study (:func:`_calibrated_study`) of this test's own."""
    import shutil

    return Path(shutil.copytree(_calibrated_study, tmp_path / "study"))
