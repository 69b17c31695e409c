"""A participant is never blocked: whatever fails after trials have run leaves them resumable (one line,
nothing lost), and the plan's safe fields can be amended with a recorded reason once trials have run."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import read_dataset
from coassist.study.folder import StudyFolder, StudyFolderError, init_study
from coassist.study.runner import ParticipantRun

from .conftest import comparison_plan


def _amended(folder: Path, old: str, new: str) -> Path:
    """The study's plan with ``old`` replaced by ``new``, written beside the study folder."""
    text = (folder / "plan.toml").read_text()
    assert old in text
    path = folder.parent / "amended.toml"
    path.write_text(text.replace(old, new))
    return path


def test_a_safe_field_is_amended_after_trials_with_its_reason_recorded(finished_study):
    """bdc84ed refused any changed plan once trials had run: a plan that blocked a participant stayed so."""
    old = (finished_study / "plan.toml").read_bytes()
    old_sha = hashlib.sha256(old).hexdigest()
    amended = _amended(finished_study, "between_conditions = 30.0", "between_conditions = 45.0")
    result = CliRunner().invoke(
        app, ["study", "amend", str(finished_study), str(amended), "--reason", "participants asked for longer rests"]
    )
    assert result.exit_code == 0, result.output
    assert "rest.between_conditions: 30.0 -> 45.0" in result.output
    study = StudyFolder(finished_study)
    assert study.plan().rest.between_conditions == 45.0  # the folder's plan, its hash checked
    (record,) = study.record["amendments"]
    assert record["fields"] == {"rest.between_conditions": [30.0, 45.0]} and record["from_sha256"] == old_sha
    assert record["reason"] == "participants asked for longer rests" and record["trials_before"] is True
    assert (finished_study / "plans" / f"{old_sha}.toml").read_bytes() == old  # the plan it replaced, kept
    with ParticipantRun(study, "S02", simulate=True) as run:  # the study goes on under the amended plan
        run.run()
    assert run.complete and len(read_dataset(run.folder.block("manual")).trials) == 1


def test_a_field_that_changes_what_participants_do_is_not_amended(finished_study):
    before = (finished_study / "study.json").read_bytes()
    for old, new, field in [
        ("per_condition = 1", "per_condition = 2", "trials.per_condition"),
        ('controller = "impedance"', 'controller = "cooperative-arbitrated"', "condition"),
        ("motion_time = 3.0", "motion_time = 4.0", "trials.motion_time"),
    ]:
        amended = _amended(finished_study, old, new)
        with pytest.raises(StudyFolderError) as err:
            from coassist.study.folder import amend_study

            amend_study(finished_study, amended, "why not")
        assert str(err.value).startswith(f"{amended}: {field} cannot be amended") and "\n" not in str(err.value)
    amended = _amended(finished_study, "seed = 3", "seed = 3")  # the same plan
    result = CliRunner().invoke(app, ["study", "amend", str(finished_study), str(amended), "--reason", " "])
    assert result.exit_code == 2 and "--reason must say why" in result.output
    assert (finished_study / "study.json").read_bytes() == before


def test_the_stop_criterion_of_an_iterative_study_can_be_amended(tmp_path):
    """The issue's case: the criterion's horizon is a safe field (it changes no finished trial)."""
    pytest.importorskip("torch", reason="an iterative study needs the learn extra")
    from coassist.study.folder import amend_study

    plan = tmp_path / "plans" / "iter.toml"
    plan.parent.mkdir()
    text = (
        '[study]\nname = "iter"\nprotocol = "iterative"\n\n[iterative]\nrounds = 2\ntrials_per_round = 2\n'
        'criterion_horizon = 50\n\n[trials]\ntasks = ["linear"]\npractice = 0\nmotion_time = 3.0\ndwell = 1.0\n\n'
        "[training]\nepochs = 1\nlayers = 1\nhidden = 8\nfc = [8]\n"
    )
    plan.write_text(text)
    study = init_study(plan, tmp_path / "study")
    study.participant("S01").append({"step": 0, "kind": "trial", "key": "trial:round-0:0"})  # a trial has run
    plan.write_text(text.replace("criterion_horizon = 50", "criterion_horizon = 40"))
    amendment = amend_study(study.folder, plan, "the check is wanted at 0.32 s")
    assert amendment["fields"] == {"iterative.criterion_horizon": [50, 40]}
    assert StudyFolder(study.folder).plan().iterative.criterion_horizon == 40
    plan.write_text(
        text.replace("rounds = 2", "rounds = 3").replace("criterion_horizon = 50", "criterion_horizon = 40")
    )
    with pytest.raises(StudyFolderError, match="iterative.rounds cannot be amended"):
        amend_study(study.folder, plan, "more rounds")


def test_an_error_after_trials_have_run_is_one_line_and_the_participant_resumes(tmp_path, monkeypatch):
    """Whatever fails mid-session (here a KeyError the run did not expect, which bdc84ed printed as a
    traceback), the run says so in one line, keeps what finished and the same command continues."""
    from coassist.study.session import StudySession

    study = init_study(comparison_plan(tmp_path / "plans", per_condition=1, practice=0), tmp_path / "study")
    real_run = StudySession.run
    calls = []

    def failing(self, setup, *, wait_for_page):
        calls.append(setup.step)
        if len(calls) == 2:
            raise KeyError("lost_a_field")
        return real_run(self, setup, wait_for_page=wait_for_page)

    monkeypatch.setattr(StudySession, "run", failing)
    args = ["study", "run", str(study.folder), "--participant", "S01", "--simulate"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 1 and not isinstance(result.exception, KeyError), result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and errors[0].startswith("error: S01: 'lost_a_field' (KeyError)"), result.output
    assert "the same command continues where it stopped" in errors[0]
    pf = study.participant("S01")
    assert [r["kind"] for r in pf.progress()] == ["trial", "questionnaire", "rest"]  # what finished is kept
    monkeypatch.setattr(StudySession, "run", real_run)
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    lines = pf.progress()
    assert len(lines) == 8 and [r["step"] for r in lines] == list(range(8))
    for block in ("assistive", "impedance", "manual"):
        assert len(read_dataset(pf.block(block)).trials) == 1  # none lost, none run twice
    assert json.loads((study.folder / "participants.json").read_text())["S01"]["number"] == 1


def test_a_rest_amended_from_none_says_whom_it_does_not_reach(tmp_path):
    """A rest of 0 s is no step of an order, and an order is fixed at a participant's first run: an amendment to a
    rest of some seconds reached only those who began after it, while the docs said it applied from everyone's next
    run (review, 2026-12-06). It says whom it does not reach, in the output and the record."""
    study = init_study(comparison_plan(tmp_path / "plans", per_condition=2, practice=0), tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True):
        pass  # S01 begins: their order is written
    amended = _amended(study.folder, "between_conditions = 30.0", "between_conditions = 30.0\nbetween_trials = 5.0")
    result = CliRunner().invoke(app, ["study", "amend", str(study.folder), str(amended), "--reason", "tired"])
    assert result.exit_code == 0, result.output
    assert "rest.between_trials: 0.0 -> 5.0" in result.output
    assert "rest.between_trials: S01 began with none there" in " ".join(result.output.split()), result.output
    (record,) = StudyFolder(study.folder).record["amendments"]
    assert record["not_reached"] == {"rest.between_trials": ["S01"]}
    with ParticipantRun(StudyFolder(study.folder), "S02", simulate=True) as run:  # who begins now has the rests
        assert sum(s["kind"] == "rest" and s["why"] == "between trials" for s in run.steps) == 3
    # from some seconds to more: everyone's order holds the rests, nobody is left out
    again = _amended(study.folder, "between_trials = 5.0", "between_trials = 8.0")
    amended_again = CliRunner().invoke(app, ["study", "amend", str(study.folder), str(again), "--reason", "longer"])
    assert amended_again.exit_code == 0 and "began with none" not in amended_again.output
