"""calibrate_person with several draws: draw 0 is the one calibration bit for bit, the others are fitted to their
own probe trials (seeds DRAW_SEED_STEP apart), and the run's config refuses a count it cannot seed."""

from dataclasses import replace

import numpy as np
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
    # each draw's paths are its own trials' (the tiny preset's two probe trials a person measure no arm: the typical
    # one in both, since an arm of fewer than three trials has no error to judge it by)
    p0, p1 = (d.paths["user-0"].weights for d in source.draws)
    assert p0.shape[1] == p1.shape[1] and not np.array_equal(p0, p1)
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


def test_a_calibration_asks_for_a_way_shown_too_seldom_and_leaves_it_out_of_the_prior(tmp_path):
    """reproduce.person_calibration_asked: after the chosen-way probe trials (one per operator in tiny: every way shown
    once, too seldom), each operator is asked for that way until FEW_PATHS paths show it, within the budget; the asked
    trials go that way and say so, their paths join the model, the ways' prior counts only the chosen trial."""
    from coassist.data import read_dataset
    from coassist.experiments.source_training import asked_way_seed
    from coassist.scenario.path_model import ASKED_WAY, FEW_PATHS
    from coassist.scenario.person_model import read_person_model

    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=1, threads=1, person_calibration_asked=2)
    assert cfg.person_calibration_trials == 1 and FEW_PATHS == 3
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    source = read_person_model(calibrate_person(ws))
    options = calibration_draw_options(ws)["calibration-probe"]
    users = list(options["users"])
    chosen = {t.meta.user: t for t in read_dataset(tmp_path / "datasets" / "calibration-probe").trials}
    for position, user in enumerate(users):
        model = source.paths[f"user-{user}"]
        (side,) = {int(s) for s in model.sides[:1]}
        assert side in (1, -1) and ASKED_WAY not in chosen[f"user-{user}"].meta.extra
        name = "left" if side > 0 else "right"
        asked = read_dataset(tmp_path / "datasets" / f"calibration-probe-ask-{user}-{name}").trials
        seed = asked_way_seed(options["seed"], len(users), 1, position, side, 2)
        assert [t.meta.seed for t in asked] == [seed, seed + 1]
        assert all(t.meta.extra[ASKED_WAY] == side == t.meta.extra["intent_side"] for t in asked)
        assert model.sides.tolist() == [side] * 3 and model.asked.tolist() == [False, True, True]
        # Laplace's rule over the one chosen trial: 2/3 its way, 1/3 the other, as with that trial alone
        assert model.ways() == pytest.approx({side: 2 / 3, -side: 1 / 3})


def test_the_arm_asks_for_the_same_trials_as_the_point_mass_world(tmp_path):
    # the MuJoCo UR5's calibration (ablation.asked_trials) asks a draw's operators for a thin way on the seeds the
    # point-mass world's calibration gives them: each operator's probe trial, asked that way
    from types import SimpleNamespace

    import numpy as np

    from coassist.experiments.ablation import asked_trials, probe_configs
    from coassist.experiments.source_training import asked_way_seed

    cfg = replace(reproduce_config.REPRODUCE_PRESETS["default"], person_calibration_asked=2)
    for draw in (0, 1):
        probes = probe_configs(cfg, draw)
        users = list(dict.fromkeys(c.user for c in probes))
        assert users == [0, 1, 2] and len(probes) == 3 * cfg.person_calibration_trials
        first = calibration_draw_options(pipeline.Workspace(cfg, tmp_path, progress=False), draws=2)
        seed0 = list(first.values())[draw]["seed"]
        assert min(c.seed for c in probes) == seed0
        fits = {c.who: SimpleNamespace(paths=SimpleNamespace(sides=np.array([-1] + [1] * 7))) for c in probes}
        fits["user-0"] = SimpleNamespace(paths=SimpleNamespace(sides=np.array([1] * 8)))  # nothing thin
        got = asked_trials(probes, fits, 2)
        firsts = {c.user: c for c in reversed(probes)}  # each operator's first probe trial
        want = [
            replace(firsts[u], seed=asked_way_seed(seed0, 3, cfg.person_calibration_trials, u, -1, 2) + i, way=-1)
            for u in (1, 2)
            for i in range(2)
        ]
        assert got == want and len({c.seed for c in got} | {c.seed for c in probes}) == len(got) + len(probes)


def test_the_asked_trials_seeds_follow_the_draws_own_trials_and_never_meet():
    # hand-computed: three operators × eight trials from 1000 take 1000 … 1023; then each operator's left and right
    # asks, two seeds each, in operator order
    from coassist.experiments.source_training import asked_way_seed

    assert [asked_way_seed(1000, 3, 8, p, w, 2) for p in range(3) for w in (1, -1)] == [
        1024,
        1026,
        1028,
        1030,
        1032,
        1034,
    ]
