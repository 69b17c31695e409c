"""The study folder: resume after kill -9 (nothing finished lost, the order kept), a torn line, a trial
committed without its line, a plan changed after the first trial, one run per participant."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coassist.data import read_dataset
from coassist.study.folder import StudyFolder, StudyFolderError, init_study
from coassist.study.runner import ParticipantRun

from .conftest import comparison_plan

SRC = Path(__file__).resolve().parents[2] / "src"


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _trial_lines(pf) -> list[dict]:
    return [r for r in pf.progress() if r["kind"] == "trial"]


def test_kill_9_mid_trial_then_resume_keeps_every_finished_trial_and_the_order(tmp_path):
    plan = comparison_plan(tmp_path / "plans", timing="motion_time = 1.5\ndwell = 0.5")
    study = init_study(plan, tmp_path / "study")
    env = {
        **os.environ,
        "PYTHONPATH": f"{SRC}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
    }
    # a simulated participant paced to the wall clock, as a person: each trial takes seconds
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "coassist.cli",
            "study",
            "run",
            str(study.folder),
            "--participant",
            "S01",
            "--simulate",
            "--realtime",
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    pf = study.participant("S01")
    try:
        t_end = time.monotonic() + 90
        while len(_trial_lines(pf)) < 2:
            assert proc.poll() is None, proc.stdout.read().decode()
            assert time.monotonic() < t_end, "two trials did not finish in 90 s"
            time.sleep(0.05)
        time.sleep(0.8)  # well inside the next trial (each lasts > 3 s): it is in progress
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    done = _trial_lines(pf)
    assert 2 <= len(done) < 9
    finished = {(r["block"], r["file"]): _sha(pf.block(r["block"]) / r["file"]) for r in done}
    order = json.loads((pf.folder / "order.json").read_text())["steps"]

    with ParticipantRun(study, "S01", simulate=True) as run:  # resume, unpaced
        assert len(run.done) == len(pf.progress()) >= len(done)
        run.run()
        assert run.complete
    lines = pf.progress()
    assert [r["key"] for r in lines] == [f"{s['kind']}:{s.get('block', '')}:{s.get('index', '')}" for s in order]
    assert json.loads((pf.folder / "order.json").read_text())["steps"] == order  # the recorded order, not recomputed
    for (block, file), digest in finished.items():  # nothing of the finished trials lost or rewritten
        assert _sha(pf.block(block) / file) == digest
    # every block holds exactly its trials, each once, in step order (the killed trial was run again, once)
    for block, n in (("assistive", 2), ("impedance", 2), ("manual", 2), ("practice", 3)):
        ds = read_dataset(pf.block(block))
        assert len(ds.trials) == n
        steps = [t.meta.extra["study_step"] for t in ds.trials]
        assert steps == sorted(steps) == [r["step"] for r in lines if r["kind"] == "trial" and r["block"] == block]
    # participant 1 takes the first row of the Latin square: the plan's conditions in order
    measured = [s["condition"] for s in order if s["kind"] == "trial" and not s["practice"]]
    assert measured == ["assistive"] * 2 + ["impedance"] * 2 + ["manual"] * 2


def test_a_trial_written_but_not_recorded_is_recovered_not_run_twice(tmp_path):
    study = init_study(comparison_plan(tmp_path / "plans", per_condition=1, practice=0), tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    pf = study.participant("S01")
    lines = pf.progress_file.read_bytes().splitlines(keepends=True)
    k = max(i for i, line in enumerate(lines) if json.loads(line)["kind"] == "trial")
    # the kill fell between the trial's dataset commit and its progress line, and mid-way through that line
    pf.progress_file.write_bytes(b"".join(lines[:k]) + lines[k][:17])
    assert len(pf.progress()) == k  # the torn line is not a record
    block = json.loads(lines[k])["block"]
    before = _sha(pf.block(block) / "manifest.json")
    with ParticipantRun(study, "S01", simulate=True) as run:
        assert len(run.done) == k + 1 and run.done[k]["recovered"] is True
        run.run()
    assert _sha(pf.block(block) / "manifest.json") == before  # not run again
    assert len(read_dataset(pf.block(block)).trials) == 1
    assert all(line.endswith(b"\n") for line in pf.progress_file.read_bytes().splitlines(keepends=True))


def test_a_plan_changed_after_a_participant_started_but_logged_no_step_is_refused(tmp_path):
    """A run stopped during its first trial has written the participant's order (and maybe the trial's file) but no
    step: the plan it ordered from is in use. Before, init took the changed plan and the old order ran under it
    (two controllers pooled under one condition name)."""
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    study = init_study(plan, tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True):
        pass  # registered, ordered; killed before its first trial's line
    assert (study.participant("S01").folder / "order.json").is_file() and not study.participant("S01").progress()
    plan.write_text(plan.read_text().replace("per_condition = 1", "per_condition = 2"))
    with pytest.raises(StudyFolderError) as err:
        init_study(plan, tmp_path / "study")
    assert "\n" not in str(err.value) and "participants have started" in str(err.value)


def test_a_plan_changed_after_the_first_trial_is_refused_in_one_line(tmp_path):
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    study = init_study(plan, tmp_path / "study")
    # before any trial the plan may change
    plan.write_text(plan.read_text().replace("per_condition = 1", "per_condition = 2"))
    study = init_study(plan, tmp_path / "study")
    assert study.plan().trials.per_condition == 2
    with ParticipantRun(study, "S01", simulate=True) as run:
        run._trial(0, run.steps[0])  # one trial of one participant
        run.folder.append({"step": 0, "kind": "trial", "key": "trial:assistive:0"})
    plan.write_text(plan.read_text().replace("per_condition = 2", "per_condition = 3"))
    with pytest.raises(StudyFolderError) as err:
        init_study(plan, tmp_path / "study")
    assert "\n" not in str(err.value) and "a changed plan needs a new study folder" in str(err.value)
    copy = tmp_path / "study" / "plan.toml"
    copy.write_text(copy.read_text().replace("per_condition = 2", "per_condition = 3"))
    with pytest.raises(StudyFolderError) as err:
        StudyFolder(tmp_path / "study").plan()
    assert "\n" not in str(err.value) and "changed after study init" in str(err.value)
    assert "trials have run under the old one" in str(err.value)


def test_one_run_per_participant_and_each_their_own_folder(tmp_path):
    study = init_study(comparison_plan(tmp_path / "plans", per_condition=1, practice=0), tmp_path / "study")
    env = {**os.environ, "PYTHONPATH": f"{SRC}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    with ParticipantRun(study, "S01", simulate=True):
        # another process (a second terminal) on the same participant is refused at once, in one line
        second = subprocess.run(
            [
                sys.executable,
                "-m",
                "coassist.cli",
                "study",
                "run",
                str(study.folder),
                "--participant",
                "S01",
                "--simulate",
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert second.returncode == 1
        assert second.stderr.startswith("error: S01: ") and "being written by another coassist run" in second.stderr
        assert len(second.stderr.strip().splitlines()) == 1
        with ParticipantRun(study, "S02", simulate=True) as other:
            assert other.folder.folder != study.participant("S01").folder
            assert other.record["row"] == 1
    table = study.participants()
    assert table["S01"]["number"] == 1 and table["S02"]["number"] == 2
    with pytest.raises(StudyFolderError, match="is a simulated participant"):
        ParticipantRun(study, "S01", page=("127.0.0.1", 0, None))
    with pytest.raises(StudyFolderError, match="--participant must be"):
        ParticipantRun(study, "../etc", simulate=True)


@pytest.mark.parametrize("host, token", [("0.0.0.0", "short"), ("no such host.invalid", None)])
def test_a_refused_page_option_registers_nobody(tmp_path, host, token):
    """`study run` with a --host/--token the page cannot use once registered the participant (and wrote their
    order, which locks the plan) before the page refused to start."""
    from typer.testing import CliRunner

    from coassist.cli import app

    study = init_study(comparison_plan(tmp_path / "plans", per_condition=1, practice=0), tmp_path / "study")
    args = ["study", "run", str(study.folder), "--participant", "P01", "--host", host, "--no-open"]
    res = CliRunner().invoke(app, args + (["--token", token] if token else []))
    assert res.exit_code == 2 and ("--token" in res.output or "--host" in res.output), res.output
    assert "Traceback" not in res.output
    assert not (study.folder / "participants" / "P01").exists() and not study.any_started()


def test_a_taken_page_port_registers_nobody(tmp_path):
    """The page's port in use (a server left running) registered the participant, spent number 1 and row 0 of the
    Latin square and wrote their order, which locks the plan, before the page failed to listen (a review ran it,
    2026-12-07): the port is bound before anyone is registered."""
    import socket

    from typer.testing import CliRunner

    from coassist.cli import app

    study = init_study(comparison_plan(tmp_path / "plans", per_condition=1, practice=0), tmp_path / "study")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        args = ["study", "run", str(study.folder), "--participant", "P01", "--port", str(port), "--no-open"]
        res = CliRunner().invoke(app, args)
        assert res.exit_code != 0 and f"cannot listen on 127.0.0.1:{port}" in res.output, res.output
        assert "Traceback" not in res.output
    assert study.participants() == {} and not study.any_started()
    assert not (study.folder / "participants" / "P01").exists()


def test_a_study_folder_keeps_the_default_intent_it_was_made_with(tmp_path):
    """A cooperative condition that names no intent runs present-held in a study made today; it ran nominal before.
    The folder keeps its plan's bytes and re-reads them on every run, so a folder made before the change once read
    that condition as present-held: its next participant ran another condition than its first, under one name, and
    the report said so of all of them. The default is recorded at init (a folder without it: nominal), and an
    amended plan is read with the folder's."""
    from coassist.study.folder import STUDY_NAME, amend_study

    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    made = init_study(plan, tmp_path / "new")
    assert made.record["default_intent"] == "present-held"
    assert [(c.name, c.intent) for c in made.plan().conditions][0] == ("assistive", "present-held")

    older = init_study(plan, tmp_path / "old")
    record = json.loads((older.folder / STUDY_NAME).read_text())
    del record["default_intent"]  # as a folder made before it was recorded
    (older.folder / STUDY_NAME).write_text(json.dumps(record))
    older = StudyFolder(older.folder)
    assert [(c.name, c.intent) for c in older.plan().conditions][0] == ("assistive", "nominal")
    amended = plan.parent / "amended.toml"
    amended.write_text(plan.read_text().replace("participants = 4", "participants = 5"))
    assert "participants = 5" in amended.read_text()
    amend_study(older.folder, amended, reason="a fifth participant")  # a safe field: the condition is read alike
    again = StudyFolder(older.folder)
    assert again.plan().participants == 5 and again.plan().conditions[0].intent == "nominal"


@pytest.mark.parametrize("realtime", [False, True])
def test_a_simulated_participant_rests_only_when_paced_to_the_wall_clock(tmp_path, realtime):
    """docs/study.md: a simulated participant does not rest unless --realtime paces it to the wall clock (it never
    rested: a paced rehearsal under-counted the session's length by every rest; a review, 2026-12-07)."""
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    plan.write_text(plan.read_text().replace("between_conditions = 30.0", "between_conditions = 0.4"))
    study = init_study(plan, tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True, realtime=realtime) as run:
        k = next(i for i, s in enumerate(run.steps) if s["kind"] == "rest")
        rested = run._rest(k, run.steps[k])["rested_s"]
    if realtime:
        assert 0.4 <= rested < 5.0
    else:
        assert rested < 0.4
