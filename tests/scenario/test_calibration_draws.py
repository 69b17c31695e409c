"""Calibration draws: a trial meets draw seed mod K, runs exactly as that draw's person model alone, and the
folder round-trips through the intent registry; its clusters are (person, draw)."""

import numpy as np
import pytest

from coassist.interfaces import TrialContext
from coassist.scenario.arm_identification import ArmEstimate
from coassist.scenario.calibration_draws import (
    DRAWS_FILE,
    CalibrationDraws,
    draw_clusters,
    draw_count,
    draw_of,
    read_draws,
    write_draws,
)
from coassist.scenario.intent_registry import intent_folder_kind, load_intent_source
from coassist.scenario.path_model import fit_path_model
from coassist.scenario.person_model import PersonFit, read_person_model, write_person_model

LINE = np.stack([np.linspace(0.0, 0.4, 81), np.zeros(81)], axis=1)


def _detour(side: int, width: float) -> np.ndarray:
    x = np.linspace(0.0, 0.4, 200)
    return np.stack([x, side * 0.05 * np.exp(-(((x - 0.2) / width) ** 2))], axis=1)


@pytest.fixture()
def folder(tmp_path):
    """Two draws of one person that differ: one calibration saw her go left twice, the other right twice, with
    different arms."""
    root = tmp_path / "draws"
    for k, (side, stiffness) in enumerate(((1, 650.0), (-1, 900.0))):
        paths = fit_path_model(LINE, [_detour(side, 0.05), _detour(side, 0.06), _detour(-side, 0.05)], noise=0.001)
        arm = ArmEstimate(stiffness=stiffness, damping=-5.0, stiffness_se=40.0, damping_se=3.0, trials=3)
        write_person_model(root / f"draw-{k}", {"alice": PersonFit(arm, paths)})
    return write_draws(root, ["draw-0", "draw-1"])


def _rows(source, seed: int | None) -> np.ndarray:
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
        seed=seed,
    )
    source.reset(ctx)
    out = []
    for k in range(150):  # along the line, then up the left detour, pushing
        p = np.array([0.002 * k, 0.03 * np.exp(-(((0.002 * k - 0.2) / 0.05) ** 2))])
        out.append(source.predict(np.concatenate([p, [0.25, 0.0], [2.0, 1.0], p])[None, :]))
    return np.asarray(out)


def test_a_trial_runs_as_the_draw_its_seed_names(folder):
    draws = read_draws(folder, horizon=10)
    alone = [read_person_model(folder / f"draw-{k}", horizon=10) for k in range(2)]
    for seed in (6, 7, None):
        k = draw_of(seed, 2)
        rows = _rows(draws, seed)
        assert draws.active == k
        np.testing.assert_array_equal(rows, _rows(alone[k], seed))  # bit for bit that draw's source
    assert not np.allclose(_rows(alone[0], 0), _rows(alone[1], 0))  # and the draws differ: the test can fail


def test_draw_of_and_clusters():
    assert [draw_of(s, 4) for s in (900_000, 900_001, 900_005, None)] == [0, 1, 1, 0]
    pairs = [("u0", 900_000), ("u0", 900_001), ("u0", 900_002), ("u1", 900_003), ("u1", -1)]
    assert draw_clusters(pairs, 2) == [("u0", 0), ("u0", 1), ("u0", 0), ("u1", 1), ("u1", 0)]
    with pytest.raises(ValueError, match="draws"):
        draw_of(3, 0)


def test_the_registry_loads_a_draws_folder(folder, tmp_path):
    assert intent_folder_kind(str(folder)) == "calibration-draws"
    assert isinstance(load_intent_source(str(folder), horizon=10), CalibrationDraws)
    assert draw_count(folder) == 2
    assert draw_count(folder / "draw-0") == 1  # a person-model folder: one calibration
    assert draw_count("present") == 1


def test_bad_draws_are_refused_naming_them(folder, tmp_path):
    with pytest.raises(ValueError, match="directly inside"):
        write_draws(folder, ["../draw-0"])
    with pytest.raises(ValueError, match="no folder"):
        write_draws(folder, ["draw-0", "draw-9"])
    with pytest.raises(ValueError, match="named twice"):
        write_draws(folder, ["draw-0", "draw-0"])
    text = (folder / DRAWS_FILE).read_text()
    (folder / DRAWS_FILE).write_text(text.replace("draw-1", "draw-2"))  # an edit by hand: the digest refuses it
    with pytest.raises(ValueError, match=DRAWS_FILE):
        read_draws(folder)
    with pytest.raises(RuntimeError, match="before reset"):
        CalibrationDraws([read_person_model(folder / "draw-0")]).predict(np.zeros((1, 8)))


def test_the_paths_asked_for_are_counted_per_fit(folder, tmp_path):
    # none asked in the fixture's two draws; a draw with one fit that asked for two paths, one that asked for none
    from coassist.scenario.calibration_draws import asked_paths
    from coassist.scenario.path_model import fit_path_model

    assert asked_paths(folder) == (0, 0, 2)
    root = tmp_path / "asked"
    arm = ArmEstimate(stiffness=650.0, damping=-5.0, stiffness_se=40.0, damping_se=3.0, trials=3)
    demos = [_detour(1, 0.05), _detour(-1, 0.05), _detour(-1, 0.06), _detour(-1, 0.07)]
    people = {
        "alice": PersonFit(arm, fit_path_model(LINE, demos, noise=0.001, asked=[False, False, True, True])),
        "bob": PersonFit(arm, fit_path_model(LINE, demos, noise=0.001)),
    }
    write_person_model(root / "draw-0", people)
    write_person_model(root / "draw-1", {"alice": people["bob"], "bob": people["bob"]})
    assert asked_paths(write_draws(root, ["draw-0", "draw-1"])) == (1, 2, 4)
    assert asked_paths(root / "draw-0") == (1, 2, 2)  # a person-model folder: its fits alone


def test_the_report_says_where_the_calibrations_asked(tmp_path):
    from coassist.experiments.ablation import MUJOCO_PERSON
    from coassist.experiments.ablation_report import asked_in_calibrations

    arm = ArmEstimate(stiffness=650.0, damping=-5.0, stiffness_se=40.0, damping_se=3.0, trials=3)
    demos = [_detour(1, 0.05), _detour(-1, 0.05), _detour(-1, 0.06)]
    asked = write_person_model(
        tmp_path / "a", {"alice": PersonFit(arm, fit_path_model(LINE, demos, noise=0.001, asked=[False, True, True]))}
    )
    chosen = write_person_model(tmp_path / "c", {"alice": PersonFit(arm, fit_path_model(LINE, demos, noise=0.001))})
    models = {"person": str(asked), MUJOCO_PERSON: str(chosen), "ridge": str(tmp_path / "ridge")}
    assert asked_in_calibrations(models) == {"point-mass world": (1, 2, 1)}
    assert asked_in_calibrations({"person": str(tmp_path / "gone")}) == {}
    # the held-out population's calibrations too (the report left them out)
    from coassist.experiments.ablation import HELD_OUT_PERSON

    both = {**models, HELD_OUT_PERSON: str(asked)}
    assert asked_in_calibrations(both) == {"point-mass world": (1, 2, 1), "held-out population": (1, 2, 1)}
    # and the ablation's section says it, for the world whose calibrations asked
    from coassist.experiments.ablation_cells import AblationResult
    from coassist.experiments.ablation_report import ablation_section

    section = ablation_section(AblationResult({}, {}, {}, models, {}, "default", {}))
    (said,) = [p for p in section.paragraphs if "asked" in p]
    assert said.endswith("point-mass world, 1 of 1 (operator, calibration) fits, 2 trials asked.")
    quiet = ablation_section(AblationResult({}, {}, {}, {"person": str(chosen)}, {}, "default", {}))
    assert not [p for p in quiet.paragraphs if "asked" in p]
