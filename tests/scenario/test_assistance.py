"""What the person at the handle will get, in one line (coassist.scenario.assistance), and the default source."""

import numpy as np
import pytest
import typer

from coassist.scenario.arm_identification import ASSUMED_ARM, ArmEstimate
from coassist.scenario.assistance import DEFAULT_INTENT, assistance_line, check_person
from coassist.scenario.intent_registry import INTENT_SOURCES, load_intent_source
from coassist.scenario.path_model import fit_path_model
from coassist.scenario.person_model import PersonFit, write_person_model

LINE = np.stack([np.linspace(0.0, 0.4, 81), np.zeros(81)], axis=1)


def _detour(side: int) -> np.ndarray:
    x = np.linspace(0.0, 0.4, 200)
    return np.stack([x, side * 0.05 * np.exp(-(((x - 0.2) / 0.05) ** 2))], axis=1)


@pytest.fixture(scope="module")
def person_model(tmp_path_factory):
    paths = fit_path_model(LINE, [_detour(1), _detour(1), _detour(-1)], noise=0.001)
    measured = ArmEstimate(
        stiffness=650.0, damping=-5.0, stiffness_se=40.0, damping_se=3.0, trials=3, method="probe-iv"
    )
    folder = tmp_path_factory.mktemp("lab") / "cal"
    write_person_model(folder, {"alice": PersonFit(measured, paths), "bob": PersonFit(ASSUMED_ARM, paths)})
    return str(folder)


def test_a_controller_that_does_not_assist_says_so():
    assert assistance_line("manual", "present") == (
        "assistance: none: manual guidance (MG), the robot renders its inertia and damping only"
    )
    probe = assistance_line("manual-probe", DEFAULT_INTENT)
    assert probe.startswith("assistance: none: a calibration trial") and "coassist calibrate" in probe
    assert "pulls the tool back onto the planned path" in assistance_line("impedance", "nominal")


def test_each_source_says_what_it_needs():
    line = assistance_line("cooperative", DEFAULT_INTENT)
    assert (
        line
        == "assistance: cooperative, toward the present estimate from the hand force (no calibration: run coassist calibrate)"
    )
    assert "it pulls toward the plan, through any obstacle on it" in assistance_line("cooperative", "nominal")
    assert "oracle: simulation only" in assistance_line("cooperative-arbitrated", "oracle")
    for name in INTENT_SOURCES:  # every registered source has a line of its own, not the model folder's
        assert "coassist train" not in assistance_line("cooperative", name), name
    # paths: what the robot is told decides what it is
    bare = assistance_line("cooperative", "paths")
    assert "told no obstacle: the present estimate (give --scene FILE)" in bare
    told = assistance_line("cooperative", "paths", obstacles=[((0.5, 0.1), (0.1, 0.1))], scene="s.toml")
    assert told.endswith("round the 1 obstacle of the scene file s.toml (the robot is told the scene)")
    assert "of the simulated task" in assistance_line("cooperative", "paths", obstacles=[((0, 0), (0.1, 0.1))])
    assert (
        assistance_line("cooperative", "runs/m")
        == "assistance: cooperative, toward the trained model runs/m (coassist train)"
    )


def test_a_person_model_says_whose_arm_and_paths(person_model):
    source = load_intent_source(person_model)
    alice = assistance_line("cooperative", person_model, source, user="alice", path=LINE)
    assert alice == (
        f"assistance: cooperative, toward the person model {person_model} "
        "(alice: arm measured, 3 demonstrations (2 left, 1 right; left from 2 paths only, right from 1 path only))"
    )
    bob = assistance_line("cooperative", person_model, source, user="bob", path=LINE)
    assert "bob: arm ASSUMED (the typical arm: their trials measured none usable), 3 demonstrations" in bob
    # another plan: the model serves only the plan it was recorded on (the source's own test)
    moved = LINE + [0.0, 0.05]
    part = LINE[: int(0.6 * len(LINE))]  # its vertices on the model's plan: another plan for the source, and said so
    for other in (moved, part):
        assert "recorded on another plan than this run's: the present estimate held, with their arm" in (
            assistance_line("cooperative", person_model, source, user="alice", path=other)
        )
    check_person(source, "alice", person_model)
    with pytest.raises(ValueError, match=r"holds no calibration of 'carol' \(it holds alice, bob\)"):
        check_person(source, "carol", person_model)
    check_person(load_intent_source("present"), "carol", "present")  # other sources have no person to check


def test_another_person_given_the_default_model_is_told_whose_it_is(tmp_path):
    """A study's own fit names its participant the model's default (anyone else at the handle gets it): the line named
    the person at the handle as though it were their calibration (review, 2026-12-06)."""
    paths = fit_path_model(LINE, [_detour(1), _detour(1), _detour(-1)], noise=0.001)
    folder = str(write_person_model(tmp_path / "S01", {"S01": PersonFit(ASSUMED_ARM, paths)}, default="S01"))
    source = load_intent_source(folder)
    line = assistance_line("cooperative", folder, source, user="user-0", path=LINE)
    assert "(user-0: S01's calibration, the model's default person: arm ASSUMED" in line, line
    own = assistance_line("cooperative", folder, source, user="S01", path=LINE)
    assert "(S01: arm ASSUMED" in own and "default person" not in own


def test_a_person_the_twin_check_turned_away_is_told_what_they_get(tmp_path):
    from coassist.scenario.person_model import LeadCheck

    paths = fit_path_model(LINE, [_detour(1), _detour(1), _detour(-1)], noise=0.001)
    held = LeadCheck(follow=False, folds=3, person_mm=6.0, mg_mm=2.0, low_mm=1.5)
    folder = str(write_person_model(tmp_path / "cal", {"carol": PersonFit(ASSUMED_ARM, paths, lead=held)}))
    line = assistance_line("cooperative", folder, load_intent_source(folder), user="carol", path=LINE)
    assert line.endswith(
        "not led along their paths: their calibration's twin overshot more with the lead than under MG: present-held, "
        "every world's default)"
    )


def test_no_world_defaults_to_the_plan():
    from coassist.cli import app
    from coassist.play.session import PlayConfig
    from coassist.robot.drive import DriveConfig

    assert DEFAULT_INTENT in INTENT_SOURCES and DEFAULT_INTENT != "nominal"
    assert not INTENT_SOURCES[DEFAULT_INTENT].simulation_only
    assert DriveConfig().intent == DEFAULT_INTENT
    assert PlayConfig(user="me", out=".").intent == DEFAULT_INTENT
    command = typer.main.get_command(app)
    for name in ("collect", "drive", "ros2", "play"):
        (intent,) = [p for p in command.commands[name].params if p.name == "intent"]
        assert intent.default == DEFAULT_INTENT, name


def test_present_held_holds_the_present_estimate():
    # the registered variants differ only in the velocity they extrapolate: p̂ + e·i·dt·v, e = 1, 0.5, 0
    from coassist.interfaces import TrialContext

    ctx = TrialContext(
        dt=0.008,
        horizon=5,
        start=np.zeros(2),
        target=np.ones(2),
        reference=np.zeros((10, 4)),
        task="linear",
        user="u",
        object="unknown",
    )
    row = np.array([[0.1, 0.2, 0.3, -0.1, 4.0, 8.0, 0.0, 0.0]])  # p, v, w, …
    rows = {}
    for name in ("present", "present-half", "present-held"):
        src = load_intent_source(name, horizon=5)
        src.reset(ctx)
        rows[name] = src.predict(row)
    present = np.array([0.1, 0.2]) + (np.array([4.0, 8.0]) + 10.0 * np.array([0.3, -0.1])) / 800.0
    steps = 0.008 * np.arange(1, 6)[:, None] * np.array([0.3, -0.1])
    np.testing.assert_allclose(rows["present-held"], np.tile(present, (5, 1)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(rows["present-half"], present + 0.5 * steps, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rows["present"], present + steps, rtol=0, atol=1e-15)
    assert load_intent_source("present-held").model_id == "present-held"
