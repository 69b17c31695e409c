"""A person-model folder: written, read back the same, and refused in one line when edited by hand."""

import json
from dataclasses import replace

import numpy as np
import pytest

from coassist.interfaces import TrialContext
from coassist.scenario.arm_identification import ArmEstimate
from coassist.scenario.path_model import fit_path_model
from coassist.scenario.person_intent import PersonPathsIntent
from coassist.scenario.person_model import (
    PERSON_FILTER,
    PERSON_MODEL_FILE,
    PersonFit,
    read_person_model,
    write_person_model,
)

LINE = np.stack([np.linspace(0.0, 0.4, 81), np.zeros(81)], axis=1)


def _detour(side: int, width: float = 0.05) -> np.ndarray:
    x = np.linspace(0.0, 0.4, 200)
    return np.stack([x, side * 0.05 * np.exp(-(((x - 0.2) / width) ** 2))], axis=1)


@pytest.fixture()
def written(tmp_path):
    paths = fit_path_model(LINE, [_detour(1), _detour(1, 0.06), _detour(-1)], noise=0.001)
    arm = ArmEstimate(stiffness=650.0, damping=-5.0, stiffness_se=40.0, damping_se=3.0, trials=3, method="probe-iv")
    folder = write_person_model(tmp_path / "cal", {"alice": PersonFit(arm, paths)})
    return folder, paths, arm


def _rows(source: PersonPathsIntent) -> np.ndarray:
    ctx = TrialContext(
        dt=0.008,
        horizon=10,
        start=LINE[0],
        target=LINE[-1],
        reference=np.zeros((10, 4)),
        task="z",
        object="handle",
        user="alice",
        path=LINE,
    )
    source.reset(ctx)
    out = []
    for k in range(150):  # along the line, then up the left detour, pushing
        p = np.array([0.002 * k, 0.03 * np.exp(-(((0.002 * k - 0.2) / 0.05) ** 2))])
        row = np.concatenate([p, [0.25, 0.0], [2.0, 1.0], p])[None, :]
        out.append(source.predict(row))
    return np.asarray(out)


def test_a_written_model_is_read_back_the_same(written):
    folder, paths, arm = written
    direct = PersonPathsIntent(10, paths={"alice": paths}, arms={"alice": arm}, settings=PERSON_FILTER)
    loaded = read_person_model(folder, horizon=10)
    assert loaded.arms["alice"] == arm and loaded.settings == PERSON_FILTER
    np.testing.assert_array_equal(_rows(loaded), _rows(direct))  # the JSON round trip keeps every bit


def test_a_file_written_before_a_filter_setting_existed_reads_with_its_default(written):
    # a person model written before min_way_paths (its filter without the field, hashed as it was): the setting's
    # default, the rows of the filter it was written with
    from coassist._io import read_hashed_json, write_hashed_json

    folder, paths, arm = written
    path = folder / PERSON_MODEL_FILE
    fmt = json.loads(path.read_text())["format"]  # the file's own format name
    doc = read_hashed_json(path, format=fmt)
    del doc["filter"]["min_way_paths"]
    write_hashed_json(path, doc, format=fmt)
    loaded = read_person_model(folder, horizon=10)
    assert loaded.settings == PERSON_FILTER and loaded.settings.min_way_paths == 1
    direct = PersonPathsIntent(10, paths={"alice": paths}, arms={"alice": arm}, settings=PERSON_FILTER)
    np.testing.assert_array_equal(_rows(loaded), _rows(direct))


def test_a_hand_edited_or_unhashed_model_is_refused_in_one_line(written):
    folder, _, _ = written
    path = folder / PERSON_MODEL_FILE
    text = path.read_text()
    path.write_text(text.replace('"stiffness": 650.0', '"stiffness": 6500.0'))
    with pytest.raises(ValueError, match="sha256|hash|changed|edited") as err:
        read_person_model(folder)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    doc = json.loads(text)
    del doc["sha256"]
    path.write_text(json.dumps(doc))  # a file of before the hash
    with pytest.raises(ValueError) as err:
        read_person_model(folder)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    path.unlink()
    with pytest.raises(ValueError, match=PERSON_MODEL_FILE):
        read_person_model(folder)


def test_a_folder_read_again_shares_its_models_and_an_edit_or_a_rewrite_is_read_anew(written):
    # a run builds a source per trial from the same folder: the file's version is read once per process (issue 44),
    # the sources' states are their own and their rows the same; a file edited after it was read is still refused,
    # and one written again is what the next read gives
    folder, paths, arm = written
    first, second = read_person_model(folder, horizon=10), read_person_model(folder, horizon=10)
    assert first is not second and first.paths["alice"] is second.paths["alice"]
    np.testing.assert_array_equal(_rows(first), _rows(second))
    path = folder / PERSON_MODEL_FILE
    text = path.read_text()
    path.write_text(text.replace('"stiffness": 650.0', '"stiffness": 6500.0'))
    with pytest.raises(ValueError, match="sha256|hash|changed|edited"):
        read_person_model(folder)
    other = replace(PERSON_FILTER, row_smoothing=0.08)
    write_person_model(folder, {"alice": PersonFit(arm, paths)}, settings=other)
    assert read_person_model(folder).settings == other


def test_the_asked_ways_are_written_and_read_back_and_a_model_without_them_is_written_as_before(written, tmp_path):
    folder, paths, arm = written
    assert "asked" not in (folder / PERSON_MODEL_FILE).read_text()  # none asked: the file as before
    asked = fit_path_model(LINE, [_detour(1), _detour(1, 0.06), _detour(-1)], noise=0.001, asked=[False, False, True])
    other = write_person_model(tmp_path / "asked", {"alice": PersonFit(arm, asked)})
    loaded = read_person_model(other, horizon=10)
    assert loaded.paths["alice"].asked.tolist() == [False, False, True]
    assert loaded.paths["alice"].ways() == asked.ways() == pytest.approx({1: 3 / 4, -1: 1 / 4})
    direct = PersonPathsIntent(10, paths={"alice": asked}, arms={"alice": arm}, settings=PERSON_FILTER)
    np.testing.assert_array_equal(_rows(loaded), _rows(direct))


def test_a_trials_asked_way_is_read_from_its_meta():
    # the trials' meta says which way was asked for; a value that is no way is refused naming the trial
    from types import SimpleNamespace

    from coassist.scenario import person_model
    from coassist.scenario.path_model import ASKED_WAY

    def trial(extra):
        return SimpleNamespace(meta=SimpleNamespace(extra=extra, user="alice", seed=7))

    assert person_model.asked_way(trial({})) == 0
    assert person_model.asked_way(trial({ASKED_WAY: -1})) == -1
    for bad in (2, True, "left"):
        with pytest.raises(ValueError, match="alice seed 7: meta.extra\\['asked_way'\\]"):
            person_model.asked_way(trial({ASKED_WAY: bad}))


def test_a_file_of_the_previous_format_reads_with_its_checks_count_unknown(tmp_path):
    # coassist-person-model-1 (before the lead check kept how many trials the lead was worse in) still reads, its check
    # with worse None; the current format is -2, which a reader of -1 alone refuses by its format in one line
    from coassist._io import HashedJsonError, read_hashed_json, write_hashed_json
    from coassist.scenario.person_model import LeadCheck

    paths = fit_path_model(LINE, [_detour(1), _detour(-1)], noise=0.001)
    check = LeadCheck(follow=False, folds=8, person_mm=6.0, mg_mm=2.9, low_mm=-1.2, worse=7)
    folder = write_person_model(tmp_path / "cal", {"bob": PersonFit(ArmEstimate(), paths, check)})
    path = folder / PERSON_MODEL_FILE
    assert json.loads(path.read_text())["format"] == "coassist-person-model-2"
    assert read_person_model(folder).held == {"bob"}
    with pytest.raises(HashedJsonError, match="expected 'coassist-person-model-1'") as err:
        read_hashed_json(path, format="coassist-person-model-1")
    assert "\n" not in str(err.value)
    doc = read_hashed_json(path, format="coassist-person-model-2")
    del doc["people"]["bob"]["lead"]["worse"]
    write_hashed_json(path, doc, format="coassist-person-model-1")
    assert read_person_model(folder).held == {"bob"}  # the verdict is what was written
    write_hashed_json(path, doc, format="coassist-person-model-0")  # any other format: refused, naming both
    with pytest.raises(HashedJsonError, match="expected 'coassist-person-model-2' or 'coassist-person-model-1'"):
        read_person_model(folder)
