"""calibrate_person with several draws: draw 0 is the one calibration bit for bit, the others are fitted to their
own probe trials (seeds DRAW_SEED_STEP apart), and the run's config refuses a count it cannot seed."""

from dataclasses import replace

import pytest

from coassist.experiments import pipeline, reproduce_config
from coassist.experiments.source_training import (
    DRAW_SEED_STEP,
    calibrate_person,
    calibration_draw_options,
)
from coassist.scenario.calibration_draws import draw_count, read_draws
from coassist.scenario.person_model import PERSON_MODEL_FILE


def test_draws_are_calibrations_of_their_own_trials(tmp_path):
    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=1, threads=1)
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    one = calibrate_person(ws)
    drawn = calibrate_person(ws, draws=2)
    assert draw_count(one) == 1 and draw_count(drawn) == 2
    # draw 0 is the calibration of draws = 1, to the byte; draw 1 was fitted to other trials
    first = (tmp_path / "models" / "person" / PERSON_MODEL_FILE).read_bytes()
    assert (tmp_path / "models" / "person-draws" / "draw-0" / PERSON_MODEL_FILE).read_bytes() == first
    assert (tmp_path / "models" / "person-draws" / "draw-1" / PERSON_MODEL_FILE).read_bytes() != first
    options = calibration_draw_options(ws, draws=2)
    assert options["calibration-probe-draw1"]["seed"] == options["calibration-probe"]["seed"] + DRAW_SEED_STEP
    source = read_draws(drawn)
    a0, a1 = (d.arms["user-0"].stiffness for d in source.draws)
    assert a0 != a1
    with pytest.raises(ValueError, match="draws must be 1 to 8"):
        calibrate_person(ws, draws=9)


@pytest.mark.parametrize("draws", [0, 9, 1.5])
def test_the_config_refuses_draws_it_cannot_seed(draws):
    with pytest.raises(ValueError, match="calibration_draws"):
        replace(reproduce_config.REPRODUCE_PRESETS["default"], calibration_draws=draws)


def test_the_probe_trials_are_counted_apart_from_the_path_hypotheses(tmp_path):
    """The person model's probe trials per operator are ``person_calibration_trials``, the path hypotheses' MG trials
    ``calibration_trials``; both from the same first seed, so the one that gives fewer gives the other's first."""
    from coassist.experiments.source_training import calibration_options

    cfg = replace(reproduce_config.REPRODUCE_PRESETS["default"], calibration_trials=3, person_calibration_trials=5)
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    mg, probe = calibration_options(ws, "manual"), calibration_options(ws, "manual-probe")
    assert (mg["trials"], probe["trials"]) == (3, 5) and mg["seed"] == probe["seed"]
    assert all(o["trials"] == 5 for o in calibration_draw_options(ws, draws=3).values())
    assert not (tmp_path / "datasets").exists()  # options only: nothing collected


@pytest.mark.parametrize("trials", [0, 2.5])
def test_the_config_refuses_a_probe_count_that_is_no_count(trials):
    with pytest.raises(ValueError, match="person_calibration_trials"):
        replace(reproduce_config.REPRODUCE_PRESETS["default"], person_calibration_trials=trials)
