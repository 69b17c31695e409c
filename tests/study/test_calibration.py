"""The calibration block: its plan, its trials under the probe, the person model fitted from them, what
uses it (a comparison's condition, an iterative study's rounds), a failed calibration run again, kill -9
during the block and the fit, a model changed after its fit, and what the report says."""

from __future__ import annotations

import base64
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from html import escape
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.control.presets import PROBE
from coassist.control.probe import probe_phases, probe_signal
from coassist.data import read_dataset
from coassist.experiments.person_calibration import thin_ways
from coassist.metrics import f_rms
from coassist.scenario import intent_registry
from coassist.scenario.arm_identification import ARM_SE_MAX, ASSUMED_ARM, ArmEstimate, identify_arm, measured_arm
from coassist.scenario.person_model import PERSON_MODEL_FILE, LeadCheck, fit_person, read_person_model
from coassist.scenario.tasks import task_for_seed
from coassist.study.calibration import FitJob, fit_job
from coassist.study.folder import StudyFolder, StudyFolderError, init_study
from coassist.study.plan import CALIBRATED, PlanError, default_calibration_trials, plan_from_text
from coassist.study.protocols import participant_steps, trial_seed_base
from coassist.study.report import study_summary, write_report
from coassist.study.runner import ParticipantRun

from .conftest import CALIBRATED as CALIBRATED_PLAN
from .conftest import calibrated_plan

SRC = Path(__file__).resolve().parents[2] / "src"


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _plan(**fmt) -> str:
    return CALIBRATED_PLAN.format(**{"trials": 3, "dwell": 1.0, "rest": 0.0, "asked": 0, **fmt})


# ----------------------------------------------------------------------------- the plan


def test_a_calibrated_plan_reads_and_its_steps_open_with_the_block():
    plan = plan_from_text(_plan(), ".")
    assert plan.calibration is not None and plan.calibration.trials == 3
    assert [c.intent for c in plan.conditions] == ["nominal", CALIBRATED] and plan.intent_folders() == ()
    assert CALIBRATED not in intent_registry.INTENT_SOURCES  # the token names no registered source
    steps = participant_steps(plan, {"mg": "A", "person": "B"}, 1, 0)
    base = trial_seed_base(plan, 1)
    cal = steps[:3]
    assert [(s["kind"], s["block"], s["controller"], s["intent"], s["seed"]) for s in cal] == [
        ("trial", "calibration", "manual-probe", "nominal", base + 8000 + j) for j in range(3)
    ]
    assert {s["label"] for s in cal} == {None}  # nothing on the page to name
    fit = steps[3]
    assert (fit["kind"], fit["model"], fit["data"], fit["base"], fit["attempt"]) == (
        "fit",
        "P0",
        ["calibration"],
        None,
        1,
    )
    measured = [s for s in steps[4:] if s["kind"] == "trial"]
    assert {s["condition"]: s["intent"] for s in measured} == {"mg": "nominal", "person": "person:P0"}


@pytest.mark.parametrize(
    ("tasks", "trials"),
    [('["curved"]', 3), ('["linear", "curved", "sinusoidal"]', 9), ('["linear", "curved", "sinusoidal", "z"]', 10)],
)
def test_a_plan_that_does_not_say_calibrates_three_paths_a_task_at_most_ten_trials(tasks, trials):
    # two paths a task were few (docs/person-model.md): three a task, in the block's ten at most
    text = _plan().replace("[calibration]\ntrials = 3\n", "[calibration]\n").replace('["curved"]', tasks)
    plan = plan_from_text(text, ".")
    assert plan.calibration is not None and plan.calibration.trials == trials
    assert default_calibration_trials(tuple(plan.trials.tasks)) == trials


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda t: t.replace("trials = 3", "trials = 0"), "calibration.trials"),
        (lambda t: t.replace("trials = 3", "trials = 11"), "calibration.trials"),
        (lambda t: t.replace("trials = 3", 'trials = "3"'), "calibration.trials"),
        (lambda t: t.replace("trials = 3", "trials = 2.5"), "calibration.trials"),
        (lambda t: t.replace("trials = 3", "trails = 3"), "calibration.trails"),
        (lambda t: t.replace("[calibration]\ntrials = 3\nasked = 0\n", ""), "condition[1].intent"),
        (lambda t: t.replace("asked = 0", "asked = -1"), "calibration.asked"),
        (lambda t: t.replace("asked = 0", "asked = 8"), "calibration.asked"),
        (lambda t: t.replace("asked = 0", "asked = true"), "calibration.asked"),
        (
            lambda t: t.replace("trials = 3", "trials = 1").replace('["curved"]', '["linear", "curved"]'),
            "calibration.trials",
        ),
        (lambda t: t.replace('name = "mg"', 'name = "calibration"'), "condition[0].name"),
        (lambda t: t.replace('name = "mg"', 'name = "calibrated"'), "condition[0].name"),
        (lambda t: t.replace('name = "mg"', 'name = "calibration-2"'), "condition[0].name"),
    ],
)
def test_a_bad_calibration_is_one_line_naming_the_field(edit, field):
    with pytest.raises(PlanError) as err:
        plan_from_text(edit(_plan()), ".")
    assert "\n" not in str(err.value) and str(err.value).startswith(field), str(err.value)


def test_the_other_protocols_take_the_person_model(tmp_path):
    iterative = (
        '[study]\nname = "it"\nprotocol = "iterative"\n\n[calibration]\ntrials = 2\n\n'
        '[iterative]\nrounds = 2\ntrials_per_round = 1\nsource = "calibrated"\n\n'
        '[trials]\ntasks = ["curved"]\nmotion_time = 3.0\ndwell = 1.0\n'
    )
    plan = plan_from_text(iterative, ".")
    assert plan.training is None and plan.iterative.source == CALIBRATED
    steps = participant_steps(plan, {}, 1, 0)
    assert not [s for s in steps if s["kind"] == "train"]  # no network
    fits = [(s["model"], s["data"], s["base"]) for s in steps if s["kind"] == "fit"]
    assert fits == [("P0", ["calibration"], None), ("P1", ["round-0"], "P0"), ("P2", ["round-0", "round-1"], "P0")]
    rounds = {s["block"]: s["intent"] for s in steps if s["kind"] == "trial" and s["block"].startswith("round-")}
    assert rounds == {"round-0": "person:P0", "round-1": "person:P1"}
    for edit, field in (
        (lambda t: t.replace('source = "calibrated"', 'source = "person"'), "iterative.source"),
        (lambda t: t.replace("[calibration]\ntrials = 2\n", ""), "iterative.source"),
        (lambda t: t + "\n[training]\nepochs = 1\n", "training"),
    ):
        with pytest.raises(PlanError, match=rf"^{field}"):
            plan_from_text(edit(iterative), ".")
    # transfer (online alike): the person model as a third blinded condition, beside the networks
    (tmp_path / "source").mkdir()
    (tmp_path / "source" / "model.json").write_text("{}")  # parse_plan checks the folder's marker only
    transfer = (
        '[study]\nname = "tr"\nprotocol = "transfer"\n\n[calibration]\ntrials = 2\n\n'
        '[transfer]\nsource_model = "source"\ntrials = 2\ncompare_calibrated = true\n\n'
        '[trials]\ntasks = ["curved"]\nper_condition = 1\npractice = 0\nmotion_time = 3.0\ndwell = 1.0\n'
    )
    plan = plan_from_text(transfer, tmp_path)
    steps = participant_steps(plan, {"source": "A", "transferred": "B", CALIBRATED: "C"}, 1, 0)
    compared = {s["condition"]: s["intent"] for s in steps if s["kind"] == "trial" and s["label"]}
    assert compared[CALIBRATED] == "person:P0" and compared["transferred"] == "model:transferred"
    with pytest.raises(PlanError, match=r"^transfer\.compare_calibrated"):
        plan_from_text(transfer.replace("[calibration]\ntrials = 2\n", ""), tmp_path)


def test_init_refuses_a_calibration_that_could_not_measure_the_arm(tmp_path):
    # a 1.5 s motion and 0.5 s dwell: the arm is measured from trials of 3 s at least
    plan = calibrated_plan(tmp_path / "plans")
    plan.write_text(
        plan.read_text().replace("motion_time = 3.0", "motion_time = 1.5").replace("dwell = 1.0", "dwell = 0.5")
    )
    result = CliRunner().invoke(app, ["study", "init", str(plan), "--out", str(tmp_path / "study")])
    assert result.exit_code != 0 and not (tmp_path / "study").exists()
    line = " ".join(result.output.split())
    end = task_for_seed("curved", 0, motion_time=1.5).planner.end_time
    assert f"trials.motion_time: a calibration trial as planned lasts {end + 0.5:g} s; the arm is measured" in line


def test_init_refuses_a_criterion_beyond_the_person_models_predictions(tmp_path):
    text = (
        '[study]\nname = "it"\nprotocol = "iterative"\n\n[calibration]\ntrials = 2\n\n'
        '[iterative]\nrounds = 2\ntrials_per_round = 1\nsource = "calibrated"\ncriterion_horizon = 51\n\n'
        '[trials]\ntasks = ["curved"]\nmotion_time = 3.0\ndwell = 1.0\n'
    )
    (tmp_path / "plan.toml").write_text(text)
    with pytest.raises(PlanError, match=r"^iterative\.criterion_horizon: 51 samples, but the rounds log the person"):
        init_study(tmp_path / "plan.toml", tmp_path / "study")
    init_study_ok = text.replace("criterion_horizon = 51", "criterion_horizon = 50")
    (tmp_path / "plan.toml").write_text(init_study_ok)
    assert init_study(tmp_path / "plan.toml", tmp_path / "study").record["estimate"]["n_trials"] == 4


# ----------------------------------------------------------------------------- the block and its fit


def test_the_block_runs_under_the_probe_and_fits_the_participants_person_model(calibrated_study):
    study = StudyFolder(calibrated_study)
    pf = study.participant("S01")
    progress = pf.progress()
    cal = read_dataset(pf.block("calibration"))
    assert len(cal.trials) == 3 and {t.meta.controller for t in cal.trials} == {"manual-probe"}
    for t in cal.trials:  # the robot's effort is the probe of the step's seed, to the bit (coassist.control.probe)
        push = probe_signal(t.time, PROBE, 2, probe_phases(PROBE, t.meta.seed))
        assert (
            np.array_equal(t.effort_r[:, :2], push)
            and t.meta.seed == trial_seed_base(study.plan(), 1) + 8000 + (t.meta.extra["study_step"])
        )
    (fit,) = [r for r in progress if r["kind"] == "fit"]
    assert fit["demonstrations"] == {"curved": [f"calibration/{f}" for f in cal.files]}
    # the arm is identify_arm's on these trials, used where it says enough (else the typical arm, and why)
    arm, note = measured_arm(identify_arm(cal.trials))
    assert ArmEstimate(**fit["arm"]) == arm
    assert fit["arm_measured"] == (not note) and fit["arm"]["trials"] == (3 if not note else 0)
    folder = pf.folder / "models" / "P0" / "curved"
    assert fit["sha256"] == {"curved": _sha(folder / PERSON_MODEL_FILE)}
    assert (folder / "person-model.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # its paths and arm, drawn
    # the folder is this participant's, whatever name the world gives the person at the handle
    source = read_person_model(folder)
    assert set(source.paths) == {"S01"} and source.default_arm == arm and source.default_paths is source.paths["S01"]
    by_hand = fit_person(list(cal.trials), arm=arm).paths
    assert np.allclose(source.paths["S01"].weights, by_hand.weights, rtol=0, atol=1e-12)
    # how far the demonstrations repeat, recorded with the fit (None where no way was taken twice)
    r = by_hand.repeatability()
    assert fit["paths"]["curved"]["repeatability"] == (None if r is None else pytest.approx(r, abs=1e-9))
    # whether the model leads them, recorded with the fit and written with the model (the twin check)
    lead = fit["paths"]["curved"]["lead"]
    assert lead is not None and lead["follow"] == ("S01" not in source.held) and lead["folds"] in (0, 3)
    # the calibrated condition ran with it, each trial recording its file's hash; MG with nothing
    person = read_dataset(pf.block("person")).trials
    # the model's id: the folder's name and the first 12 hex digits of the file's SHA-256
    assert {t.meta.model_id for t in person} == {f"person:curved@{fit['sha256']['curved'][:12]}"}
    assert {t.meta.extra["study_model"] for t in person} == {"P0"}
    lines = {r["block"]: r for r in progress if r["kind"] == "trial"}
    assert lines["person"]["model_sha256"] == fit["sha256"]["curved"] and "model_sha256" not in lines["mg"]
    mg = read_dataset(pf.block("mg")).trials
    assert {t.meta.model_id for t in mg} == {None}
    # the same path and obstacle in both conditions (paired): the person model takes less hand force than MG
    assert person[0].meta.seed == mg[0].meta.seed
    assert f_rms(person[0].wrench[:, :2]) < f_rms(mg[0].wrench[:, :2])


def test_the_report_says_what_used_the_person_model_and_what_it_was_fitted_from(calibrated_study, _calibrated_study):
    html_path, json_path = write_report(calibrated_study)
    summary = json.loads(json_path.read_text())
    assert summary["calibration"] == {"trials": 3, "calibrated": ["person"], "asked": 0}
    (p0,) = summary["participants"]["S01"]["person_models"]
    assert p0["model"] == "P0" and p0["trials"] == {"curved": 3} and p0["blocks"] == ["calibration"]
    html = html_path.read_text()
    assert "With the participant's own person model (fitted from their 3 calibration trials): person (" in html
    assert "<h2>Person models</h2>" in html and "3 curved trials of calibration" in html
    assert ("measured (3 trials with pushes)" if p0["arm"]["measured"] else "assumed: ") in html
    # what the model was told, and the blocks whose trials ran with its file (by the hash on their lines)
    arm = "measured" if p0["arm"]["measured"] else "assumed"
    learnt = "paths round obstacles and the arm" if p0["arm"]["measured"] else "paths round obstacles"
    assert p0["told"] == f"arm {arm}; from the person's trials: {learnt}"
    assert p0["used_in"] == ["person"] and f"<td>{escape(p0['told'])}</td>" in html and "<td>person</td>" in html
    # and the person model as the calibration drew it, the figure's own bytes
    png = (calibrated_study / "participants" / "S01" / "models" / "P0" / "curved" / "person-model.png").read_bytes()
    uri = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
    assert f'<img src="{uri}" alt="person model: S01, P0, curved">' in html
    # a way round shown in too few of the calibration's trials is named, with what to record (here: three trials)
    (fit,) = [r for r in StudyFolder(calibrated_study).participant("S01").progress() if r["kind"] == "fit"]
    note = thin_ways(np.asarray(fit["paths"]["curved"]["sides"]))
    assert p0["thin_ways"] == ({"curved": note} if note else {})
    assert (f"curved: {escape(note)}" in html) if note else ("record more going" not in html)
    # whether the model led them (its twin check), as the calibrate line says it, and as the console said at the fit
    lead = LeadCheck(**fit["paths"]["curved"]["lead"])
    assert p0["lead"] == {"curved": lead.line} and f"<td>curved: {escape(lead.line)}</td>" in html
    (said,) = [x for x in (_calibrated_study.parent / "said.txt").read_text().splitlines() if "fitted in" in x]
    assert said.startswith("S01: person model P0 fitted in ") and said.endswith(f"; curved: {lead.line}"), said


def test_the_report_says_who_the_twin_check_turned_away(calibrated_study):
    """A participant whose twin overshot more with the lead got the present estimate held in the calibrated
    condition: the report says so on their person model's row (and summary.json), not the line of one led."""
    held = LeadCheck(follow=False, folds=3, person_mm=6.2, mg_mm=2.1, low_mm=1.4, worse=3)
    html_path, p0 = _report_with_the_fit(calibrated_study, "lead", asdict(held))
    line = (
        "present estimate held (the lead did not pay): their twin overshot 6.2 mm with the lead, 2.1 mm under MG "
        "(3 trials replayed, more with the lead in 3, the difference's 95 % interval from +1.4 mm)"
    )
    assert p0["lead"] == {"curved": line} and f"<td>curved: {escape(line)}</td>" in html_path.read_text()


def _report_with_the_fit(study: Path, field: str, value) -> tuple[Path, dict]:
    """The report of ``study`` after its S01's fit record's curved ``paths`` entry ``field`` is set to ``value``:
    (report.html, S01's person model in summary.json)."""
    progress = study / "participants" / "S01" / "progress.jsonl"
    lines = [json.loads(line) for line in progress.read_text().splitlines()]
    for r in lines:
        if r["kind"] == "fit":
            r["paths"]["curved"][field] = value
    progress.write_text("".join(json.dumps(r) + "\n" for r in lines))
    html_path, json_path = write_report(study)
    (p0,) = json.loads(json_path.read_text())["participants"]["S01"]["person_models"]
    return html_path, p0


def test_the_report_names_a_way_shown_in_too_few_calibration_trials(calibrated_study):
    # the fit's record, as if one of the three paths had gone left: both ways thin, each named with what to record
    html_path, p0 = _report_with_the_fit(calibrated_study, "sides", [1, -1, -1])
    note = (
        "the left way shown in 1 trial only: the model follows that path alone there; record more going left (asked: --ask-way left); "
        "the right way shown in 2 trials only: the model follows those 2 paths alone there; record more going right (asked: --ask-way right)"
    )
    assert p0["thin_ways"] == {"curved": note} and f"<br>curved: {escape(note)}</td>" in html_path.read_text()


def test_the_arm_is_assumed_where_the_measurement_says_too_little():
    good = ArmEstimate(stiffness=600.0, damping=5.0, stiffness_se=0.4 * 600.0, trials=3, method="probe-iv")
    assert measured_arm(good) == (good, "")
    vague = ArmEstimate(
        stiffness=600.0, damping=5.0, stiffness_se=(ARM_SE_MAX + 0.01) * 600.0, trials=3, method="probe-iv"
    )
    arm, why = measured_arm(vague)
    assert arm is ASSUMED_ARM and "too uncertain" in why
    clipped = ArmEstimate(stiffness=100.0, damping=95.0, stiffness_se=715.0, trials=3, method="probe-iv")
    assert measured_arm(clipped)[0] is ASSUMED_ARM and "bound" in measured_arm(clipped)[1]
    assert measured_arm(ASSUMED_ARM) == (ASSUMED_ARM, "no pushes measured in the trials")


def test_a_person_model_trial_recovered_after_a_kill_keeps_its_model_on_its_line(calibrated_study):
    """A kill between the person-model trial's dataset commit and its progress line: the recovered line names the
    model and its file's hash as the run's own line does (from the trial's meta; a trial written before the meta
    held the hash: from the model's fit line), so the report still says the person model was used there."""
    pf = StudyFolder(calibrated_study).participant("S01")
    lines = pf.progress_file.read_text().splitlines(keepends=True)
    k = next(i for i, line in enumerate(lines) if json.loads(line).get("block") == "person")
    original = json.loads(lines[k])
    assert original["model"] == "P0" and len(original["model_sha256"]) == 64
    pf.progress_file.write_text("".join(lines[:k]))  # the kill: the trial is in its dataset, its line is not
    with ParticipantRun(StudyFolder(calibrated_study), "S01", simulate=True) as run:
        recovered = run.done[k]
        assert recovered["recovered"] is True
        step = run.steps[k]
        run.run()
    assert recovered["model"] == "P0" and recovered["model_sha256"] == original["model_sha256"]
    assert recovered["waited_for_model_s"] is None  # not kept: the wait is unknown after a kill
    assert {key for key in original if key != "t"} | {"recovered"} == {key for key in recovered if key != "t"}
    (p0,) = study_summary(calibrated_study)["participants"]["S01"]["person_models"]
    assert p0["used_in"] == ["person"]
    # a trial whose meta lacks the hash (written before it was kept there): the fit line's digest for its task
    from coassist.study.folder import _recovered_model_fields

    (trial,) = read_dataset(pf.block("person")).trials
    extra = {key: v for key, v in trial.meta.extra.items() if key != "study_model_sha256"}
    done = [json.loads(line) for line in lines[:k]]
    assert _recovered_model_fields(done, step, extra) == {
        "model": "P0",
        "waited_for_model_s": None,
        "model_sha256": original["model_sha256"],
    }
    mg = next(json.loads(line) for line in lines if json.loads(line).get("block") == "mg")
    mg_extra = read_dataset(pf.block("mg")).trials[0].meta.extra
    assert _recovered_model_fields(done, run.steps[mg["step"]], mg_extra) == {"model": None, "waited_for_model_s": None}


def test_a_person_model_changed_after_its_fit_is_refused_in_one_line(calibrated_study):
    study = StudyFolder(calibrated_study)
    path = study.participant("S01").folder / "models" / "P0" / "curved" / PERSON_MODEL_FILE
    path.write_text(path.read_text().replace('"stiffness": ', '"stiffness": 1'))
    for attempt in (
        lambda: ParticipantRun(study, "S01", simulate=True).__enter__(),
        lambda: study_summary(study.folder),
    ):
        with pytest.raises(StudyFolderError, match="changed since it was fitted") as err:
            attempt()
        assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_calibration_without_motion_fails_in_one_line_and_the_same_command_runs_it_again(tmp_path, monkeypatch):
    from coassist.study.participants import OperatorHand

    plan = calibrated_plan(tmp_path / "plans", trials=2)
    study = init_study(plan, tmp_path / "study")
    monkeypatch.setattr(OperatorHand, "force_xy", lambda self, x, y, vx, vy: (0.0, 0.0))  # a hand that never pushes
    result = CliRunner().invoke(app, ["study", "run", str(study.folder), "--participant", "S01", "--simulate"])
    line = " ".join(result.output.split())
    assert result.exit_code == 1, result.output
    assert (
        "error: S01: the calibration failed: no calibration trial of task 'curved' ended in the target (2 ended: "
        "time_limit; the tool moved" in line
    )
    assert ": no motion): the person model cannot learn the way there; recorded, and the block is run again" in line
    pf = study.participant("S01")
    failed = pf.progress()[-1]
    assert failed["kind"] == "fit" and failed["failed"] and failed["redo"] == "calibration-2"
    assert not (pf.folder / "models" / "P0").exists()
    order = json.loads((pf.folder / "order.json").read_text())
    assert [s["block"] for s in order["steps"][3:6]] == ["calibration-2", "calibration-2", "models"]
    assert order["inserted"] == [
        {"after": 2, "keys": ["trial:calibration-2:0", "trial:calibration-2:1", "fit:models:P0-2"]}
    ]
    monkeypatch.undo()
    result = CliRunner().invoke(app, ["study", "run", str(study.folder), "--participant", "S01", "--simulate"])
    assert result.exit_code == 0, result.output
    fits = [r for r in pf.progress() if r["kind"] == "fit"]
    assert [(r["attempt"], bool(r.get("failed"))) for r in fits] == [(1, True), (2, False)]
    assert fits[1]["demonstrations"]["curved"] == [
        f"calibration-2/{f}" for f in read_dataset(pf.block("calibration-2")).files
    ]
    assert len(read_dataset(pf.block("calibration")).trials) == 2  # the failed attempt's trials are kept
    summary = study_summary(study.folder)
    attempts = summary["participants"]["S01"]["person_models"]
    assert attempts[0]["failed"] and "no motion" in attempts[0]["reason"] and attempts[1]["trials"] == {"curved": 2}


def _lines(pf, kind: str) -> list[dict]:
    return [r for r in pf.progress() if r["kind"] == kind]


def test_kill_9_during_the_block_and_during_the_fit_then_resume(tmp_path):
    study = init_study(calibrated_plan(tmp_path / "plans"), tmp_path / "study")
    pf = study.participant("S01")
    env = {**os.environ, "PYTHONPATH": f"{SRC}{os.pathsep}{os.environ.get('PYTHONPATH', '')}", "OMP_NUM_THREADS": "1"}
    cmd = [
        sys.executable,
        "-m",
        "coassist.cli",
        "study",
        "run",
        str(study.folder),
        "-p",
        "S01",
        "--simulate",
        "--realtime",
    ]

    def run_until(done, what: str, then: float) -> None:
        """Run the participant paced, and kill -9 the run ``then`` seconds after ``done()``."""
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            t_end = time.monotonic() + 180  # generous: a busy machine starts processes slowly
            while not done():
                assert proc.poll() is None, proc.stdout.read().decode()
                assert time.monotonic() < t_end, f"{what} did not come in 180 s"
                time.sleep(0.05)
            time.sleep(then)
            os.kill(proc.pid, signal.SIGKILL)
        finally:
            proc.kill()
            proc.wait()

    # 1. inside the second calibration trial (each lasts about 4 s, paced)
    run_until(lambda: len(_lines(pf, "trial")) >= 1, "the first calibration trial", then=1.0)
    assert len(_lines(pf, "trial")) == 1
    first = _sha(pf.block("calibration") / _lines(pf, "trial")[0]["file"])
    # 2. inside the fit: its trials are recorded, its line is not (the fit takes seconds: a worker starts, fits)
    run_until(lambda: len(_lines(pf, "trial")) == 3, "the fit", then=0.5)
    assert not _lines(pf, "fit") and len(_lines(pf, "trial")) == 3
    with ParticipantRun(study, "S01", simulate=True) as run:  # the resume fits again, then runs the rest
        assert [r["kind"] for r in run.done] == ["trial"] * 3
        run.run()
        assert run.complete
    cal = read_dataset(pf.block("calibration"))
    assert [t.meta.extra["study_step"] for t in cal.trials] == [0, 1, 2]  # each once; the killed one run again
    assert _sha(pf.block("calibration") / cal.files[0]) == first
    (fit,) = _lines(pf, "fit")
    assert sorted(p.name for p in (pf.folder / "models").iterdir()) == ["P0"]  # nothing half-written left
    # the fit is what fitting those trials again makes, byte for byte
    again = fit_job(FitJob(root=str(pf.folder), data=("calibration",), model="P0-again", person="S01"))
    assert again["sha256"] == fit["sha256"] and again["arm"] == fit["arm"]


#: An iterative study of two rounds of one trial after a calibration of three (seconds, simulated).
ITERATIVE_PLAN = (
    '[study]\nname = "it"\nprotocol = "iterative"\nseed = 3\n\n[calibration]\ntrials = 3\n\n'
    '[iterative]\nrounds = 2\ntrials_per_round = 1\nsource = "calibrated"\n\n'
    "[questionnaire]\ntlx = false\nlikert = []\n\n"
    '[trials]\ntasks = ["curved"]\nmotion_time = 3.0\ndwell = 1.0\n\n[rest]\nbetween_conditions = 0.0\n'
)


def test_an_iterative_study_refits_the_person_model_between_rounds(tmp_path):
    (tmp_path / "plan.toml").write_text(ITERATIVE_PLAN)
    study = init_study(tmp_path / "plan.toml", tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
        assert run.complete
    pf = study.participant("S01")
    fits = {r["model"]: r for r in _lines(pf, "fit")}
    assert list(fits) == ["P0", "P1", "P2"] and not any(r.get("failed") for r in fits.values())
    # the arm stays the calibration's (the rounds ran without pushes); the paths take each round's trials too
    assert fits["P1"]["arm"] == fits["P2"]["arm"] == fits["P0"]["arm"] and fits["P1"]["base"] == "P0"
    demos = {m: r["demonstrations"]["curved"] for m, r in fits.items()}
    assert demos["P1"][:3] == demos["P0"] and demos["P2"][: len(demos["P1"])] == demos["P1"]
    assert len(demos["P0"]) == 3 and len(demos["P2"]) == 5  # every round's trial ended in the target
    for k in (0, 1):
        (trial,) = read_dataset(pf.block(f"round-{k}")).trials
        line = next(r for r in _lines(pf, "trial") if r["block"] == f"round-{k}")
        assert trial.meta.extra["study_model"] == f"P{k}" and line["model_sha256"] == fits[f"P{k}"]["sha256"]["curved"]
    used = {f["model"]: f["used_in"] for f in study_summary(study.folder)["participants"]["S01"]["person_models"]}
    assert used == {"P0": ["round-0"], "P1": ["round-1"], "P2": []}  # P2 is fitted after the last round
    (check,) = _lines(pf, "check")
    assert np.isfinite(check["e_rms"]) and np.isfinite(check["e_rms_before"])  # the person model's predictions logged


def test_a_calibration_asks_for_a_way_shown_too_seldom_then_fits_again(tmp_path):
    """[calibration] asked: after P0's fit, a way round shown in one or two of a task's paths is asked for (the page
    says which way; the simulated participant goes that way), within the budget, then P0 is fitted again from both
    blocks: the asked paths join that way's, the prior stays the chosen trials'. A participant whose ways were all
    shown often enough is asked nothing; the finished folders pass the audit of a resumed run."""
    from coassist.experiments.person_calibration import ways_to_ask
    from coassist.scenario.path_model import ASKED_WAY

    study = init_study(calibrated_plan(tmp_path / "plans", asked=2), tmp_path / "study")
    asked_by = {}
    for pid in ("S01", "S02"):
        with ParticipantRun(study, pid, simulate=True) as run:
            run.run()
        pf = study.participant(pid)
        fits = [r for r in pf.progress() if r["kind"] == "fit"]
        sides = fits[0]["paths"]["curved"]["sides"]
        asks = [("curved", way, n) for way, n in ways_to_ask(np.asarray(sides), 2)]
        assert [tuple(a) for a in fits[0].get("asks", [])] == asks
        steps = json.loads((pf.folder / "order.json").read_text())["steps"]
        more = [s for s in steps if s["kind"] == "trial" and s["block"] == "calibration-asked"]
        want = [(way, "manual-probe", "nominal") for _, way, n in asks for _ in range(n)]
        assert [(s["way"], s["controller"], s["intent"]) for s in more] == want
        base = trial_seed_base(study.plan(), pf.order()["number"])
        assert [s["seed"] for s in more] == [base + 8000 + 50 + j for j in range(len(more))]
        if not asks:
            assert len(fits) == 1 and not (pf.folder / "calibration-asked").exists()
            continue
        asked_by[pid] = asks
        trials = read_dataset(pf.block("calibration-asked")).trials
        assert [t.meta.extra[ASKED_WAY] for t in trials] == [w for w, _, _ in want]
        again = fits[1]
        assert again["model"] == "P0" and again["blocks"] == ["calibration", "calibration-asked"]
        assert again["paths"]["curved"]["sides"][: len(sides)] == sides
        # the simulated participant went the way asked: the fit reads it off their paths, told nothing
        assert again["paths"]["curved"]["sides"][len(sides) :] == [w for w, _, _ in want]
        model = read_person_model(pf.folder / "models" / "P0" / "curved").paths[pid]
        assert model.asked.tolist() == [False] * len(sides) + [True] * len(more)
        chosen = np.asarray(sides)
        assert model.ways() == pytest.approx({w: (int(np.sum(chosen == w)) + 1) / (len(chosen) + 2) for w in (1, -1)})
        # the calibrated condition ran with the refitted model (its hash)
        lines = {r["block"]: r for r in pf.progress() if r["kind"] == "trial"}
        assert lines["person"]["model_sha256"] == again["sha256"]["curved"]
        with ParticipantRun(study, pid, simulate=True) as run:  # the audit passes; nothing runs again
            run.run()
        assert len(pf.progress()) == len(steps)
    assert asked_by  # at least one of the two was asked for a way (seed 3: S02, the left way twice)


def test_a_kill_after_the_asked_refit_wrote_p0_but_not_its_line_resumes(tmp_path, monkeypatch):
    """The asked refit fits P0 again into the first fit's folder: a kill after its files were swapped in and before
    its line was written left P0's files the refit's while the log recorded the first fit's hash, and the audit
    refused the participant (and the study's report) for good. The model the next step fits again is left out of
    the audit: the resumed run fits it again (the same trials: the same bytes) and records it."""
    from coassist.study.folder import ParticipantFolder

    study = init_study(calibrated_plan(tmp_path / "plans", asked=2), tmp_path / "study")
    study.register("S01", simulated=True)  # S02 is participant 2: seed 3 asks them for a way

    class Killed(Exception):
        pass

    append = ParticipantFolder.append

    def killed_at_the_refits_line(self, record):
        if record.get("kind") == "fit" and str(record.get("key", "")).endswith("P0-asked"):
            raise Killed  # the refit's files are in models/P0; its line is never written
        return append(self, record)

    monkeypatch.setattr(ParticipantFolder, "append", killed_at_the_refits_line)
    with pytest.raises(Killed), ParticipantRun(study, "S02", simulate=True) as run:
        run.run()
    monkeypatch.setattr(ParticipantFolder, "append", append)
    pf = study.participant("S02")
    swapped = _sha(pf.folder / "models" / "P0" / "curved" / PERSON_MODEL_FILE)
    first = next(r for r in pf.progress() if r["kind"] == "fit")
    assert first["sha256"]["curved"] != swapped  # the state that was refused
    with ParticipantRun(study, "S02", simulate=True) as run:
        run.run()
        assert run.complete
    again = [r for r in pf.progress() if r["kind"] == "fit"][-1]
    assert again["blocks"] == ["calibration", "calibration-asked"] and again["sha256"]["curved"] == swapped
    assert study_summary(study.folder)["participants"]["S02"]["complete"]


def test_an_iterative_refit_builds_on_its_base_as_recorded_not_on_a_file_nothing_checks(tmp_path, monkeypatch):
    """P1 and P2 take P0's arm and demonstrations from P0's progress line (which the audit holds the folder to), not
    from models/P0/fit.json: an edited fit.json refitted them with an arm P0 never had, and a deleted one failed a
    round later with a traceback's words."""
    (tmp_path / "plan.toml").write_text(ITERATIVE_PLAN)
    study = init_study(tmp_path / "plan.toml", tmp_path / "study")
    pf = study.participant("S01")
    from coassist.study.folder import ParticipantFolder

    class Stopped(Exception):
        pass

    append = ParticipantFolder.append

    def stop_after_p0(self, record):
        append(self, record)
        if record.get("kind") == "fit":
            raise Stopped  # the session ends with P0 fitted and recorded

    monkeypatch.setattr(ParticipantFolder, "append", stop_after_p0)
    with pytest.raises(Stopped), ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    monkeypatch.setattr(ParticipantFolder, "append", append)
    (pf.folder / "models" / "P0" / "fit.json").unlink()  # gone: nothing reads it
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
        assert run.complete
    fits = {r["model"]: r for r in pf.progress() if r["kind"] == "fit"}
    assert fits["P1"]["arm"] == fits["P2"]["arm"] == fits["P0"]["arm"] and not fits["P1"].get("failed")
    assert fits["P1"]["demonstrations"]["curved"][:3] == fits["P0"]["demonstrations"]["curved"]


def test_a_participant_whose_calibration_fails_every_attempt_stops_before_the_next_ones_seeds(monkeypatch):
    """Attempt a's seeds start 8000 + 100 (a − 1) past the participant's base: a 21st attempt would draw the next
    participant's. After the 20th failure the session ends in one line (recorded; nothing run), and no step asks
    for a 21st."""
    from coassist.study.protocols import MAX_CALIBRATION_ATTEMPTS, SEED_BAND, calibration_steps

    plan = plan_from_text(_plan(trials=3, asked=2), ".")
    last = calibration_steps(plan, 1, MAX_CALIBRATION_ATTEMPTS)
    base = trial_seed_base(plan, 1)
    assert max(s["seed"] for s in last if s["kind"] == "trial") + plan.calibration.asked + 50 < base + SEED_BAND
    with pytest.raises(ValueError, match="calibration attempt 21 is outside 1 … 20"):
        calibration_steps(plan, 1, MAX_CALIBRATION_ATTEMPTS + 1)


def test_the_last_attempt_failing_ends_the_session_in_one_line(tmp_path, monkeypatch):
    """The runner's side of the limit, with the limit at 2: the second failure is recorded, asks for no third, and the
    session ends in one line, the same line on every later run, nothing run."""
    from coassist.study import runner
    from coassist.study.participants import OperatorHand

    monkeypatch.setattr(runner, "MAX_CALIBRATION_ATTEMPTS", 2)
    monkeypatch.setattr(OperatorHand, "force_xy", lambda self, x, y, vx, vy: (0.0, 0.0))  # a hand that never pushes
    study = init_study(calibrated_plan(tmp_path / "plans", trials=2), tmp_path / "study")
    command = ["study", "run", str(study.folder), "--participant", "S01", "--simulate"]
    assert CliRunner().invoke(app, command).exit_code == 1  # attempt 1 failed: run again
    pf = study.participant("S01")
    for _ in range(2):  # attempt 2 fails; then the same line, nothing run
        result = CliRunner().invoke(app, command)
        line = " ".join(result.output.split())
        assert result.exit_code == 1 and "error: S01: the calibration failed in all 2 attempts (the last: no" in line
        assert "no seeds are left for another: this participant's session ends here" in line
        fits = [r for r in pf.progress() if r["kind"] == "fit"]
        assert [(r["attempt"], bool(r.get("exhausted"))) for r in fits] == [(1, False), (2, True)]
        assert len(pf.progress()) == 6 and not (pf.folder / "models" / "P0").exists()
    assert not study_summary(study.folder)["participants"]["S01"]["complete"]


def test_a_calibration_cannot_ask_beyond_ten_trials():
    plan = plan_from_text(_plan(trials=8, asked=2), ".")
    assert (plan.calibration.trials, plan.calibration.asked) == (8, 2)
    with pytest.raises(PlanError, match=r"calibration.asked must be an integer in 0 … 2"):
        plan_from_text(_plan(trials=8, asked=3), ".")
    # the session's longest estimate counts the trials it may ask for and the fit after them; the expected one not
    from coassist.study.preflight import FIT_SECONDS, preflight

    none, one, two = (preflight(plan_from_text(_plan(trials=8, asked=n), ".")) for n in (0, 1, 2))
    assert two.expected_s == none.expected_s and two.n_trials == none.n_trials
    limit = one.max_s - none.max_s - FIT_SECONDS  # one trial run to its time limit
    assert limit >= plan.trials.motion_time + plan.trials.dwell
    assert two.max_s - none.max_s == pytest.approx(2 * limit + FIT_SECONDS)


def test_a_person_model_folder_that_holds_no_participant_refuses_them_before_they_start(tmp_path):
    """A condition naming a person-model folder (coassist calibrate) that holds no calibration of the participant
    would give them the present estimate held while the report names the model: refused in one line, as drive, play
    and collect refuse it, before the participant is registered (nothing locked); the person it holds runs."""
    from coassist.scenario.path_model import fit_path_model
    from coassist.scenario.person_model import PersonFit, person_filter_for, write_person_model
    from coassist.scenario.tasks import nominal_path

    curve = nominal_path("curved").points  # the plan's task: a model of another path is refused at init (below)
    line = curve[::25]
    bump = 0.05 * np.exp(-(((curve[:, 0] - 0.15) / 0.05) ** 2))
    detours = [curve + np.stack([np.zeros_like(bump), s * bump], axis=1) for s in (1, 1, -1)]
    folder = write_person_model(
        tmp_path / "cal", {"P07": PersonFit(ASSUMED_ARM, fit_path_model(line, detours, noise=0.001))}
    )
    text = (
        _plan()
        .replace("[calibration]\ntrials = 3\nasked = 0\n", "")
        .replace('intent = "calibrated"', f"intent = {json.dumps(str(folder))}")
    )
    (tmp_path / "plan.toml").write_text(text)
    study = init_study(tmp_path / "plan.toml", tmp_path / "study")
    with pytest.raises(StudyFolderError) as err:
        ParticipantRun(study, "P08", page=("127.0.0.1", 0, None))
    msg = str(err.value)
    assert msg.startswith("condition[1] (person): intent ") and "\n" not in msg, msg
    assert "holds no calibration of 'P08' (it holds P07)" in msg and 'intent = "calibrated"' in msg, msg
    assert study.participants() == {}  # not registered: the plan stays open to amend
    run = ParticipantRun(study, "P07", page=("127.0.0.1", 0, None))  # the person it holds: registered, as ever
    assert run.record["number"] == 1 and list(study.participants()) == ["P07"]
    # one registered without the check (a study begun before it) is let in, as one who finished must be to be listed,
    # and refused before their next step
    study.register("P08")
    late = ParticipantRun(study, "P08", page=("127.0.0.1", 0, None))
    with pytest.raises(StudyFolderError, match=r"holds no calibration of 'P08' \(it holds P07\)"):
        late.run()
    # a study's own fit names its participant the default (whoever else is at the handle gets it): another
    # participant is still refused, not given P07's model while the report names it (review, 2026-12-06)
    own = write_person_model(
        tmp_path / "cal-own",
        {"P07": PersonFit(ASSUMED_ARM, fit_path_model(line, detours, noise=0.001))},
        default="P07",
    )
    (tmp_path / "plan-own.toml").write_text(text.replace(json.dumps(str(folder)), json.dumps(str(own))))
    other = init_study(tmp_path / "plan-own.toml", tmp_path / "study-own")
    with pytest.raises(StudyFolderError, match=r"holds no calibration of 'P08' \(it holds P07\)"):
        ParticipantRun(other, "P08", page=("127.0.0.1", 0, None))
    assert other.participants() == {}
    # a folder fitted on one task named for a plan with another: refused at init, naming both (its trials of the
    # other task got the present estimate held, recorded as the person model's; review, 2026-12-06). In shape: a
    # plan laid out elsewhere (an arm's, from where its tool stands) is the same plan
    two = text.replace('tasks = ["curved"]', 'tasks = ["curved", "linear"]')
    assert two != text
    (tmp_path / "plan-two.toml").write_text(two)
    with pytest.raises(PlanError) as err:
        init_study(tmp_path / "plan-two.toml", tmp_path / "study-two")
    msg = str(err.value)
    assert "\n" not in msg and "P07's person model was fitted on task 'curved', not on task 'linear'" in msg, msg
    moved = write_person_model(
        tmp_path / "cal-moved",
        {"P07": PersonFit(ASSUMED_ARM, fit_path_model(line + 0.3, [d + 0.3 for d in detours], noise=0.001))},
    )
    (tmp_path / "plan-moved.toml").write_text(text.replace(json.dumps(str(folder)), json.dumps(str(moved))))
    init_study(tmp_path / "plan-moved.toml", tmp_path / "study-moved")  # accepted
    # a folder calibrated on the MuJoCo UR5 (its filter that world's: person_filter_for) named for a study on the page:
    # refused at init, naming both worlds (its arm, paths and filter are the arm's: review, 2026-12-06)
    arm = write_person_model(
        tmp_path / "cal-mujoco",
        {"P07": PersonFit(ASSUMED_ARM, fit_path_model(line, detours, noise=0.001))},
        settings=person_filter_for("mujoco"),
    )
    (tmp_path / "plan-arm.toml").write_text(text.replace(json.dumps(str(folder)), json.dumps(str(arm))))
    with pytest.raises(
        PlanError, match=r"condition\[1\]\.intent: .*calibrated on trials of the MuJoCo UR5.*not of the play world"
    ):
        init_study(tmp_path / "plan-arm.toml", tmp_path / "study-arm")


@pytest.mark.parametrize("origin", ["sim", "mujoco"])
def test_the_block_measures_the_arm_as_calibrate_does_leaving_a_twisting_mount_out(tmp_path, origin):
    """A study's calibration block on the board measured the arm with the mount's twist in series (K̂ about half the
    handle's) and recorded it as measured, where coassist calibrate leaves those trials out (a review, 2026-12-07):
    the block decides as calibrate does (probes_for_arm); in a world that holds every object rigidly (MuJoCo) the
    board's probes measure the arm."""
    from dataclasses import replace

    from coassist.config import APPLICATION_PRESET
    from coassist.control.presets import get_preset, make_controller
    from coassist.data import TrialMeta, write_dataset
    from coassist.scenario.objects import get_object
    from coassist.scenario.operator import AUTHOR
    from coassist.sim.trial_runner import run_trial

    probe = make_controller("manual-probe", get_preset(APPLICATION_PRESET))
    trials = [
        run_trial(task_for_seed("curved", s, obstacle="large"), AUTHOR, get_object("board"), probe, None, s)
        for s in range(3)
    ]
    trials = [replace(t, meta=TrialMeta(**{**t.meta.to_dict(), "origin": origin, "user": "S01"})) for t in trials]
    write_dataset(trials, tmp_path / "S01" / "calibration", "calibration")
    record = fit_job(FitJob(root=str(tmp_path / "S01"), data=("calibration",), model="P0", person="S01"))
    if origin == "sim":  # the point-mass world's board twists on its mount
        assert record["arm_measured"] is False and record["arm"] == asdict(ASSUMED_ARM)
        assert "3 probe trial(s) on the board left out of the arm's fit" in record["arm_note"]
    else:
        arm, note = measured_arm(identify_arm(trials))
        assert (
            record["arm"] == asdict(arm)
            and record["arm_measured"] is (not note)
            and "left out" not in record["arm_note"]
        )
