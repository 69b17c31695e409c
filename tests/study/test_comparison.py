"""A comparison study end to end with simulated participants: 4 × 3 conditions on the page's world, its
report, and the same plan on the MuJoCo UR5."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import read_dataset
from coassist.metrics import f_rms
from coassist.study.design import latin_square_rows

from .conftest import comparison_plan


def _run_study(tmp_path, plan):
    runner = CliRunner()
    folder = tmp_path / "study"
    for args in (
        ["study", "init", str(plan), "--out", str(folder)],
        ["study", "run", str(folder), "--simulate"],
        ["study", "report", str(folder)],
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
    return folder, json.loads((folder / "report" / "summary.json").read_text())


def _check_comparison(folder, summary, per_condition):
    conditions = ["assistive", "impedance", "manual"]
    assert summary["n_participants"] == summary["n_complete"] == 4 and summary["simulated"]
    assert sorted(summary["labels"].values()) == ["A", "B", "C"]
    rows = latin_square_rows(3)
    for i, pid in enumerate(["S01", "S02", "S03", "S04"]):
        p = summary["participants"][pid]
        assert p["complete"] and p["order"] == [conditions[c] for c in rows[i]]  # row i of the Latin square
        assert set(p["answers"]) == set(conditions)  # a questionnaire after each condition
        for c in conditions:
            trials = read_dataset(folder / "participants" / pid / c).trials
            assert len(trials) == per_condition and all(t.meta.user == pid for t in trials)
            assert {t.meta.controller for t in trials} == {dict(assistive="cooperative").get(c, c)}
            # the summary's per-participant f_RMS is the mean of the trials' (eq. 5.9 recomputed here)
            assert p["means"][c]["f_rms"] == pytest.approx(np.mean([f_rms(t.wrench[:, :2]) for t in trials]), rel=1e-12)
    # the paired tests of the report are scipy's on the per-participant means
    comp = next(
        c for c in summary["comparisons"] if c["metric"] == "f_rms" and c["a"] == "assistive" and c["b"] == "manual"
    )
    a = [summary["participants"][p]["means"]["assistive"]["f_rms"] for p in sorted(summary["participants"])]
    b = [summary["participants"][p]["means"]["manual"]["f_rms"] for p in sorted(summary["participants"])]
    assert comp["p_t"] == pytest.approx(stats.ttest_rel(a, b).pvalue, rel=1e-12)
    assert comp["p_wilcoxon"] == pytest.approx(stats.wilcoxon(a, b).pvalue, rel=1e-12)
    assert comp["p_wilcoxon_holm"] >= comp["p_wilcoxon"]
    assert any("cannot reach 0.05" in line for line in summary["limits"])  # 4 participants, said plainly
    html = (folder / "report" / "report.html").read_text()
    assert "What this sample can and cannot show" in html and html.count("data:image/png;base64,") >= 3


def test_a_comparison_of_4_simulated_participants_runs_end_to_end(tmp_path):
    folder, summary = _run_study(tmp_path, comparison_plan(tmp_path / "plans", per_condition=2, practice=1))
    _check_comparison(folder, summary, per_condition=2)
    # practice trials first, kept apart and not analysed
    assert len(read_dataset(folder / "participants" / "S01" / "practice").trials) == 3
    means = {p: v["means"] for p, v in summary["participants"].items()}
    assert all(math.isfinite(m["assistive"]["sigma"]) for m in means.values())


def test_the_same_plan_runs_on_the_mujoco_ur5(tmp_path):
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    plan = comparison_plan(tmp_path / "plans", world="mujoco", per_condition=1, practice=0, timing="")
    folder, summary = _run_study(tmp_path, plan)
    _check_comparison(folder, summary, per_condition=1)
    trial = read_dataset(folder / "participants" / "S02" / "manual").trials[0]
    assert trial.meta.origin == "mujoco" and trial.meta.extra["world"] == "mujoco" and trial.joints is not None
    assert trial.meta.user == "S02" and trial.meta.extra["study_operator"] == "user-2"  # operator 2 stood in


def test_on_the_mujoco_ur5_the_person_at_the_handle_is_the_participant(tmp_path):
    """A condition naming a person-model folder (coassist calibrate) of the participant runs on an arm world as on the
    page: drive is told the participant's id as the person at the handle (before, it looked the folder up under the
    simulated operator's name, 'user-0', and refused the trial partway through the study)."""
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    from coassist.scenario.arm_identification import ASSUMED_ARM
    from coassist.scenario.path_model import fit_path_model
    from coassist.scenario.person_model import PersonFit, person_filter_for, write_person_model
    from coassist.scenario.tasks import nominal_path

    curve = nominal_path("curved").points  # the plan's task (a model of another path is refused at init)
    line = curve[::25]
    bump = 0.05 * np.exp(-(((curve[:, 0] - 0.15) / 0.05) ** 2))
    detours = [curve + np.stack([np.zeros_like(bump), s * bump], axis=1) for s in (1, 1, -1)]
    cal = write_person_model(  # the MuJoCo world's filter, as calibrate writes it for trials of that world
        tmp_path / "cal",
        {"S01": PersonFit(ASSUMED_ARM, fit_path_model(line, detours, noise=0.001))},
        settings=person_filter_for("mujoco"),
    )
    plan = tmp_path / "plan.toml"
    plan.write_text(
        '[study]\nname = "arm"\nprotocol = "comparison"\nworld = "mujoco"\nparticipants = 1\nseed = 3\n\n'
        '[[condition]]\nname = "manual"\ncontroller = "manual"\n\n'
        f'[[condition]]\nname = "person"\ncontroller = "cooperative"\nintent = {json.dumps(str(cal))}\n\n'
        '[trials]\ntasks = ["curved"]\nper_condition = 1\npractice = 0\n\n[rest]\nbetween_conditions = 0.0\n'
    )
    folder, summary = _run_study(tmp_path, plan)
    assert summary["n_complete"] == 1
    (trial,) = read_dataset(folder / "participants" / "S01" / "person").trials
    assert trial.meta.user == "S01" and trial.meta.model_id.startswith("person:cal@")
