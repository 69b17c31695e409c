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
