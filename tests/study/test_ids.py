"""Pseudonymous ids by construction: the lab's format, no names, no dates, no two ids that differ in case
only, no name a file system reserves."""

from __future__ import annotations

import pytest

from coassist.study.folder import StudyFolderError, init_study
from coassist.study.ids import DEFAULT_ID_PATTERN, IdError, check_id, looks_like_date, looks_like_name

from .conftest import comparison_plan


@pytest.mark.parametrize(
    ("pid", "why"),
    [
        ("John_Smith", "looks like a name"),  # bdc84ed took it as a folder and every trial's user
        ("JaneDoe", "looks like a name"),
        ("smith", "looks like a name"),
        ("Tom7", "looks like a name"),
        ("Jane-Doe-1987-03-14", "holds a date"),  # bdc84ed took it
        ("P19870314", "holds a date"),
        ("p14-03-1987", "holds a date"),
        ("x3-14-87", "holds a date"),
        ("CON", "reserves for a device"),  # bdc84ed took it
        ("nul", "reserves for a device"),
        ("Com1", "reserves for a device"),
        ("../etc", "1-32 letters"),
        ("P 07", "1-32 letters"),
        ("", "1-32 letters"),
        ("P0007x", "does not match the study's id_pattern"),
        ("AB12", "does not match the study's id_pattern"),
    ],
)
def test_an_id_that_is_not_a_pseudonym_is_refused_saying_why(pid, why):
    with pytest.raises(IdError) as err:
        check_id(pid, DEFAULT_ID_PATTERN)
    assert why in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("pid", ["P07", "S01", "a1234", "Z9"])
def test_the_default_format_is_a_letter_and_digits(pid):
    assert check_id(pid, DEFAULT_ID_PATTERN) == pid


def test_a_lab_format_is_the_plan_s_and_still_no_name_or_date():
    pattern = "SUB-[0-9]{3}|sub_[a-z]"
    assert check_id("SUB-012", pattern) == "SUB-012" and check_id("sub_a", pattern) == "sub_a"
    with pytest.raises(IdError, match="does not match"):
        check_id("P07", pattern)
    assert looks_like_name("pilot_a") is True and looks_like_date("SUB-012") is False
    with pytest.raises(IdError, match="holds a date"):
        check_id("SUB-2001-02-03", "SUB-.*")
    with pytest.raises(IdError, match="looks like a name"):
        check_id("SUB-Mary", "SUB-.*")
    assert check_id("S01", "P[0-9]{2}", simulated=True) == "S01"  # simulated participants: any lab format


def test_dates_are_real_days():
    assert looks_like_date("2001-02-28") and looks_like_date("28-02-2001") and looks_like_date("20010228")
    assert not looks_like_date("2001-02-30") and not looks_like_date("P0230") and not looks_like_date("S1234")


def test_the_study_registers_pseudonyms_only_and_unique_in_any_case(tmp_path):
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    plan.write_text(plan.read_text().replace("seed = 3", 'seed = 3\nid_pattern = "[PS][0-9]{2}"'))
    study = init_study(plan, tmp_path / "study")
    for pid in ("John_Smith", "Jane-Doe-1987-03-14", "CON", "P123"):
        with pytest.raises(StudyFolderError):
            study.register(pid)
    assert study.participants() == {}
    assert study.register("P01")["number"] == 1
    with pytest.raises(StudyFolderError, match="the study has P01, which differs in case only"):
        study.register("p01")  # bdc84ed: a second id that shares P01's folder on a case-insensitive file system
    assert study.register("P01")["number"] == 1 and study.register("P02")["number"] == 2
    assert list(study.participants()) == ["P01", "P02"]


def test_a_study_folder_holds_people_or_simulated_participants_never_both(tmp_path):
    # the review of 3063e1e: a --simulate run in a folder with a person was taken, and the report called its
    # simulated operators people (summary's "simulated" false, the caveat gone)
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    people, rehearsal = init_study(plan, tmp_path / "study"), init_study(plan, tmp_path / "rehearsal")
    people.register("P01")
    with pytest.raises(StudyFolderError, match=r"holds people \(P01\); rehearse with --simulate in a folder"):
        people.register("S02", simulated=True)
    rehearsal.register("S01", simulated=True)
    with pytest.raises(StudyFolderError, match=r"holds simulated participants \(S01\), a rehearsal"):
        rehearsal.register("P02")
    assert list(people.participants()) == ["P01"] and list(rehearsal.participants()) == ["S01"]  # nothing taken
    # registering makes the participant's folder, so a registered participant without one is a loss, named
    assert (tmp_path / "study" / "participants" / "P01").is_dir()
    (tmp_path / "study" / "participants" / "P01").rmdir()
    with pytest.raises(StudyFolderError, match=r"P01: missing, but .*participants.json registers P01 \(number 1\)"):
        people.register("P02")
