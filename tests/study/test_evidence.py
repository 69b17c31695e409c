"""The study folder is evidence: a log, a manifest, a trial file or the participant table that was lost,
emptied or edited is one line naming the file and what to do, on every run and report; nothing is run
again, no trial counted twice, no condition or participant dropped without a word."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import read_dataset
from coassist.study.folder import StudyFolder, StudyFolderError
from coassist.study.runner import ParticipantRun

BLOCKS = ("assistive", "impedance", "manual")


def _digests(folder: Path) -> dict[str, str]:
    """SHA-256 of every file under the participant folders (what a re-run would change)."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted((folder / "participants").rglob("*"))
        if p.is_file() and not p.name.startswith(".")
    }


def _one_line_error(args: list[str], *names: str) -> str:
    """Run the CLI; it must fail with one ``error:`` line naming each of ``names``."""
    result = CliRunner().invoke(app, args)
    assert result.exit_code in (1, 2) and not isinstance(result.exception, (KeyError, TypeError)), result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error: ")]
    assert len(errors) == 1 and errors == lines[-1:], result.output
    assert "Traceback" not in result.output
    for name in names:
        assert name in errors[0], errors[0]
    return errors[0]


def _refused_everywhere(folder: Path, *names: str) -> None:
    """A run of S01 and the report both refuse in one line naming ``names``; nothing in the folder changed."""
    before = _digests(folder)
    with pytest.raises(StudyFolderError) as err:
        with ParticipantRun(StudyFolder(folder), "S01", simulate=True) as run:
            run.run()
    assert "\n" not in str(err.value) and all(n in str(err.value) for n in names), str(err.value)
    _one_line_error(["study", "run", str(folder), "--participant", "S01", "--simulate"], *names)
    _one_line_error(["study", "report", str(folder)], *names)
    assert _digests(folder) == before  # nothing run again, nothing rewritten
    assert not (folder / "report").exists()


@pytest.mark.parametrize("keep", [0, 2, 4])
def test_an_emptied_or_truncated_log_is_one_line_never_a_second_run(finished_study, keep):
    """bdc84ed: the run repeated the finished trials and appended them; the report averaged both."""
    log = finished_study / "participants" / "S01" / "progress.jsonl"
    lines = log.read_bytes().splitlines(keepends=True)
    log.write_bytes(b"".join(lines[:keep]))
    _refused_everywhere(finished_study, "progress.jsonl", "restore it from your backup")


def test_a_block_whose_manifest_or_trial_was_lost_is_one_line_never_a_dropped_condition(finished_study):
    """bdc84ed: "already complete", and the report left the condition out for the participant."""
    manifest = finished_study / "participants" / "S01" / "impedance" / "manifest.json"
    kept = manifest.read_bytes()
    manifest.unlink()
    _refused_everywhere(finished_study, "impedance/manifest.json", "missing")
    manifest.write_bytes(kept)
    (finished_study / "participants" / "S01" / "manual" / "trial_00000.parquet").unlink()
    _refused_everywhere(finished_study, "manual/trial_00000.parquet", "missing")


def test_a_lost_or_edited_participant_table_is_one_line_never_a_second_number_1(finished_study):
    """bdc84ed: with participants.json deleted the next participant was number 1, row 0, again, and the report
    listed only them; a table that is not JSON stopped the run without naming the file and the report with a
    traceback."""
    table = finished_study / "participants.json"
    kept = table.read_bytes()
    for damage in (None, b"{}\n", b'{"S01": {"number": 1, "row": 0, "simulated": tr'):
        if damage is None:
            table.unlink()
        else:
            table.write_bytes(damage)
        before = _digests(finished_study)
        with pytest.raises(StudyFolderError, match="participants.json"):
            ParticipantRun(StudyFolder(finished_study), "S02", simulate=True)
        _one_line_error(
            ["study", "run", str(finished_study), "--participant", "S02", "--simulate"], "participants.json"
        )
        _one_line_error(["study", "report", str(finished_study)], "participants.json")
        assert _digests(finished_study) == before and not (finished_study / "participants" / "S02").exists()
    table.write_bytes(kept)
    with ParticipantRun(StudyFolder(finished_study), "S02", simulate=True) as run:
        assert run.record["number"] == 2 and run.record["row"] == 1


@pytest.mark.parametrize("value", [999, "lots", 2.5, None])
def test_answers_are_checked_when_read(finished_study, value):
    """bdc84ed: an answer edited to 999 was averaged (a raw TLX of 279); a word made the report trace back."""
    log = finished_study / "participants" / "S01" / "progress.jsonl"
    records = [json.loads(line) for line in log.read_text().splitlines()]
    i = next(i for i, r in enumerate(records) if r["kind"] == "questionnaire")
    records[i]["answers"]["tlx_mental"] = value
    log.write_text("".join(json.dumps(r) + "\n" for r in records))
    error = _one_line_error(["study", "report", str(finished_study)], "progress.jsonl", f"line {i + 1}", "tlx_mental")
    assert "answers off the questionnaire" in error


def _flipped(data: bytearray) -> bytearray:
    """The file with one byte flipped, the first from a third of the way in that damages what it holds
    (pyarrow, not coassist, reads another table or fails). Not every byte does: the fixed len/3 once
    landed 43 bytes into wrench_x's column chunk, in its page header, and the trial read back equal
    (where len/3 lands moves with the file's length); that flip is the ``flipped`` case, which only the
    file's SHA-256 in its progress line catches."""
    import io

    import pyarrow.parquet as pq

    table = pq.read_table(io.BytesIO(bytes(data)))
    for at in range(len(data) // 3, len(data)):
        flipped = bytearray(data)
        flipped[at] ^= 0xFF
        try:
            if not pq.read_table(io.BytesIO(bytes(flipped))).equals(table):
                return flipped
        except Exception:  # noqa: BLE001 - any failure to read is damage
            return flipped
    raise AssertionError("no byte of the file changes what it holds")


@pytest.mark.parametrize("damage", ["truncated", "flipped", "flipped-value", "emptied", "edited"])
def test_a_damaged_trial_file_is_one_line_in_the_report(finished_study, damage):
    """bdc84ed: the report traced back on a truncated or flipped trial parquet. A value edited and the file
    written again is refused by the trial's own checksum of its values. A flipped byte that changes no
    decoded value (a page header's statistics, say) passed both before (a full suite on 2026-12-02: the
    flip at a third of the file reported as if sound); the file's SHA-256 in its progress line catches
    every changed byte."""
    import pyarrow.parquet as pq

    path = finished_study / "participants" / "S01" / "assistive" / "trial_00000.parquet"
    data = bytearray(path.read_bytes())
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "flipped":
        data[len(data) // 3] ^= 0xFF
    elif damage == "flipped-value":
        data = _flipped(data)
    elif damage == "edited":
        table = pq.read_table(path)
        column = table.column_names[-1]
        values = table.column(column).to_pylist()
        values[0] = values[0] + 1 if isinstance(values[0], (int, float)) else values[0]
        table = table.set_column(table.column_names.index(column), column, [values])
        pq.write_table(table, path)
        data = bytearray(path.read_bytes())
        assert pq.read_table(path).num_rows == table.num_rows  # a sound parquet file, changed values
    else:
        data = bytearray()
    path.write_bytes(bytes(data))
    _one_line_error(["study", "report", str(finished_study)], "assistive/trial_00000.parquet")


def test_the_intact_folder_still_reports_and_resumes(finished_study):
    """The checks above take nothing from a sound folder: the report counts each trial once."""
    with ParticipantRun(StudyFolder(finished_study), "S01", simulate=True) as run:
        assert run.complete
    result = CliRunner().invoke(app, ["study", "report", str(finished_study)])
    assert result.exit_code == 0, result.output
    summary = json.loads((finished_study / "report" / "summary.json").read_text())
    assert summary["n_complete"] == 1 and set(summary["participants"]["S01"]["means"]) == set(BLOCKS)
    for b in BLOCKS:
        assert len(read_dataset(finished_study / "participants" / "S01" / b).trials) == 1


def test_a_non_finite_value_never_reaches_a_json_file(finished_study):
    """bdc84ed: a NaN in a step's record raised "Out of range float values are not JSON compliant" at every
    re-run; it is written as null."""
    pf = StudyFolder(finished_study).participant("S01")
    n = len(pf.progress())
    pf.append({"step": n, "kind": "check", "key": "x", "e_rms": math.nan, "delta": [math.inf, 1.0]})
    last = json.loads(pf.progress_file.read_text().splitlines()[-1])
    assert last["e_rms"] is None and last["delta"] == [None, 1.0]


def test_a_blinding_key_edited_after_the_trials_is_one_line_in_the_report(finished_study):
    """The review of 3063e1e: study.json's labels edited by hand were taken, and the report named condition A what
    the page had shown as B."""
    record = json.loads((finished_study / "study.json").read_text())
    shown = dict(record["labels"])
    swapped = dict(zip(shown, [shown[c] for c in ("impedance", "manual", "assistive")], strict=True))
    record["labels"] = swapped
    (finished_study / "study.json").write_text(json.dumps(record))
    line = _one_line_error(["study", "report", str(finished_study)], "study.json", "order.json", "S01")
    assert f"the label {swapped['assistive']!r}" in line and f"S01 {shown['assistive']!r}" in line
    assert not (finished_study / "report").exists()
    record["labels"] = shown  # put back, it reports
    (finished_study / "study.json").write_text(json.dumps(record))
    assert CliRunner().invoke(app, ["study", "report", str(finished_study)]).exit_code == 0


def test_a_registered_participant_whose_folder_was_lost_is_one_line_never_a_participant_who_never_started(
    finished_study,
):
    """The review of 3063e1e: with participants/S01 deleted, the report showed S01 with 0 of 0 steps done, as if
    they had registered and never started, and a run went on to the next participant."""
    import shutil

    shutil.rmtree(finished_study / "participants" / "S01")
    _refused_everywhere(finished_study, "participants/S01", "participants.json", "(number 1)", "withdrawn")


def _second_participant(folder: Path) -> None:
    with ParticipantRun(StudyFolder(folder), "S02", simulate=True) as run:
        run.run()


def test_a_withdrawn_participant_is_named_by_number_and_the_square_left_unbalanced_is_said(finished_study):
    """The review of 3063e1e: a participant taken out of the table and their folder deleted (withdrawn) left the
    numbers 2, 3, … and an unbalanced Latin square without a word."""
    import shutil

    _second_participant(finished_study)
    result = CliRunner().invoke(app, ["study", "report", str(finished_study), "--out", str(finished_study / "r2")])
    assert result.exit_code == 0, result.output
    limits = json.loads((finished_study / "r2" / "summary.json").read_text())["limits"]
    # two of the six rows of three conditions' square (n odd: the square and its mirror) taken once each
    assert (
        "The order of conditions is not counterbalanced over the 2 participants with every block: rows 0–5 of the "
        "Latin square were taken by 1, 1, 0, 0, 0, 0 of them; order and condition are balanced only when every "
        "row is taken equally often." in limits
    )
    table = json.loads((finished_study / "participants.json").read_text())
    del table["S01"]
    (finished_study / "participants.json").write_text(json.dumps(table))
    shutil.rmtree(finished_study / "participants" / "S01")
    result = CliRunner().invoke(app, ["study", "report", str(finished_study), "--out", str(finished_study / "r1")])
    assert result.exit_code == 0, result.output
    summary = json.loads((finished_study / "r1" / "summary.json").read_text())
    assert list(summary["participants"]) == ["S02"] and summary["participants"]["S02"]["number"] == 2
    assert (
        "Number 1 is in no participant's record: taken out of the study (withdrawn?), with their row of the Latin "
        "square (0)." in summary["limits"]
    )
    assert any("rows 0–5 of the Latin square were taken by 0, 1, 0, 0, 0, 0" in line for line in summary["limits"])


def test_simulated_participants_beside_a_person_keep_the_reports_caveat(finished_study):
    """The review of 3063e1e: one person in a folder of simulated operators (study run now refuses it; a folder of
    an older version may hold both) turned the summary's "simulated" off and dropped the caveat, while every
    pooled number was the simulated operators'."""
    _second_participant(finished_study)
    table = json.loads((finished_study / "participants.json").read_text())
    table["S02"]["simulated"] = False  # as an older version registered a person after a rehearsal
    (finished_study / "participants.json").write_text(json.dumps(table))
    result = CliRunner().invoke(app, ["study", "report", str(finished_study)])
    assert result.exit_code == 0, result.output
    summary = json.loads((finished_study / "report" / "summary.json").read_text())
    assert summary["simulated"] is True
    assert any(line.startswith("These participants are simulated operators") for line in summary["limits"])
    assert (
        "1 of 2 participants are simulated operators (S01), pooled here with people: nothing of this report is "
        "evidence about people until they are reported apart." in summary["limits"]
    )
    assert "simulated participants" in (finished_study / "report" / "report.html").read_text()


def test_a_participant_beyond_the_planned_number_is_warned_of_the_square_they_repeat(finished_study):
    """The review of 3063e1e: participants beyond the planned number were taken without a word (a seventh of six
    planned repeated row 0's order, unbalancing the square); here four are planned and the square has six rows."""
    said: list[str] = []
    for k in range(2, 9):
        with ParticipantRun(StudyFolder(finished_study), f"S{k:02d}", simulate=True, say=said.append) as run:
            assert run.record["number"] == k
    warned = [line for line in said if line.startswith("warning:")]
    assert warned == [
        f"warning: S{k:02d} is participant {k} of 4 planned (row {k - 1} of the Latin square's 6): the order of "
        "conditions stays balanced only if the participants who finish fill whole squares of 6 rows"
        for k in (5, 6)
    ] + [
        "warning: S07 is participant 7 of 4 planned (row 0 of the Latin square's 6): the order of conditions stays "
        "balanced only if the participants who finish fill whole squares of 6 rows",
        "warning: S08 is participant 8 of 4 planned (row 1 of the Latin square's 6): the order of conditions stays "
        "balanced only if the participants who finish fill whole squares of 6 rows",
    ]


def test_the_highest_numbered_participant_withdrawn_is_named_and_their_number_never_given_again(finished_study):
    """The review of the fix: withdrawing the last-numbered participant left no line, and the next participant took
    their number and row. The study keeps the highest number it gave (numbers.json); a withdrawn number's row is
    the Latin square's (mod its 6 rows here)."""
    import shutil

    for k in range(2, 9):  # registered, order written, no trial run: numbers 2 … 8
        with ParticipantRun(StudyFolder(finished_study), f"S{k:02d}", simulate=True):
            pass
    table = json.loads((finished_study / "participants.json").read_text())
    for pid in ("S07", "S08"):  # numbers 7 and 8, the highest
        del table[pid]
        shutil.rmtree(finished_study / "participants" / pid)
    (finished_study / "participants.json").write_text(json.dumps(table))
    result = CliRunner().invoke(app, ["study", "report", str(finished_study)])
    assert result.exit_code == 0, result.output
    limits = json.loads((finished_study / "report" / "summary.json").read_text())["limits"]
    assert (
        "Numbers 7, 8 are in no participant's record: taken out of the study (withdrawn?), with their row of the "
        "Latin square (0, 1)." in limits
    )
    with ParticipantRun(StudyFolder(finished_study), "S09", simulate=True) as run:
        assert (run.record["number"], run.record["row"]) == (9, 8)
