"""The intent sources by name (coassist.scenario.intent_registry): one table the loop, collect,
drive, play and the command line's help all read, and the recipe that adds a source."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.interfaces import IntentSource, TrialContext
from coassist.scenario.constant_velocity import ConstantVelocityIntent
from coassist.scenario.intent_registry import (
    INTENT_FOLDERS,
    INTENT_SOURCES,
    NAMED_INTENTS,
    check_intent,
    intent_choices,
    intent_folder_kind,
    is_path_hypotheses,
    load_intent_source,
    needs_network,
)
from coassist.scenario.path_hypotheses import PathHypothesesIntent, write_calibration
from coassist.scenario.person_intent import PersonPathsIntent
from coassist.scenario.reference_intents import NominalIntent, OracleIntent

ROOT = Path(__file__).resolve().parents[2]

#: What each name built before the registry (the if-chain of load_intent_source): class and model_id.
BEFORE = {
    "nominal": (NominalIntent, None),
    "constant-velocity": (ConstantVelocityIntent, "constant-velocity"),
    "oracle": (OracleIntent, "oracle"),
    "present": (PersonPathsIntent, "present"),
    "paths": (PathHypothesesIntent, "paths"),
}
#: Registered since (issue 40): the present estimate held, or half extrapolated, over the horizon.
SINCE = {
    "present-held": (PersonPathsIntent, "present-held"),
    "present-half": (PersonPathsIntent, "present-half"),
}


def test_the_names_are_the_ones_the_loop_knew():
    assert (
        NAMED_INTENTS
        == tuple(INTENT_SOURCES)
        == ("nominal", "constant-velocity", "oracle", "present", "present-held", "present-half", "paths")
    )
    assert [name for name, e in INTENT_SOURCES.items() if e.simulation_only] == ["oracle"]


@pytest.mark.parametrize("name", [*BEFORE, *SINCE])
def test_each_name_builds_its_source_for_the_horizon(name):
    cls, model_id = {**BEFORE, **SINCE}[name]
    source = load_intent_source(name, horizon=17)
    assert type(source) is cls and source.horizon == 17 and source.model_id == model_id
    assert isinstance(source, IntentSource)
    if cls is PathHypothesesIntent:
        assert source.use_obstacles == (name == "paths")


@pytest.mark.parametrize(("name", "share"), [("present", 1.0), ("present-held", 0.0), ("present-half", 0.5)])
def test_the_present_estimates_are_the_path_hypotheses_without_an_obstacle_bit_for_bit(name, share):
    """The named present estimates are the person model's source knowing nobody; before, they were the path
    hypotheses told no obstacle: the same rows, bit for bit, on a scripted hand (inertia included)."""
    ctx = TrialContext(
        dt=0.008,
        horizon=12,
        start=np.zeros(2),
        target=np.array([0.3, 0.1]),
        reference=np.zeros((10, 4)),
        task="z",
        user="user-0",
        object="board",
    )
    old = PathHypothesesIntent(12, use_obstacles=False, extrapolation=share)
    new = load_intent_source(name, horizon=12)
    old.reset(ctx)
    new.reset(ctx)
    rng = np.random.default_rng(4)
    t = 0.008 * np.arange(200)
    p = np.stack([0.3 * np.sin(t), 0.1 * (1 - np.cos(2 * t))], axis=1)
    v = np.gradient(p, 0.008, axis=0)
    w = rng.normal(0.0, 2.0, (200, 2))
    for k in range(200):
        row = np.concatenate([p[k], v[k], w[k], p[k]])[None, :]
        np.testing.assert_array_equal(new.predict(row), old.predict(row))


def test_a_registered_source_predicts_what_its_class_does():
    # constant velocity through the registry against the closed form x(k) + i·dt·ẋ(k)
    ctx = TrialContext(
        dt=0.008,
        horizon=4,
        start=np.zeros(2),
        target=np.ones(2),
        reference=np.zeros((10, 4)),
        task="linear",
        user="u",
        object="handle",
    )
    src = load_intent_source("constant-velocity", horizon=4)
    src.reset(ctx)
    row = np.array([[0.1, 0.2, 0.5, -1.0, 0, 0, 0, 0]])
    want = np.array([[0.1 + i * 0.008 * 0.5, 0.2 - i * 0.008] for i in range(1, 5)])
    np.testing.assert_allclose(src.predict(row), want, rtol=0, atol=1e-15)


def test_folders_by_their_marker(tmp_path):
    calib = tmp_path / "calib"
    write_calibration(calib, {})
    model = tmp_path / "model"
    model.mkdir()
    (model / INTENT_FOLDERS["model"].marker).write_text("{}")
    assert intent_folder_kind(str(calib)) == "path-hypotheses" and is_path_hypotheses(str(calib))
    assert intent_folder_kind(str(model)) == "model" and not is_path_hypotheses(str(model))
    assert intent_folder_kind(str(tmp_path / "nothing")) is None and intent_folder_kind("paths") is None
    loaded = load_intent_source(str(calib), horizon=9)
    assert type(loaded) is PathHypothesesIntent and loaded.horizon == 9
    assert [needs_network(s) for s in ("nominal", "paths", str(calib), str(model), "elsewhere")] == [
        False,
        False,
        False,
        True,
        True,
    ]


def test_the_model_marker_is_the_sidecar_the_intent_package_writes():
    pytest.importorskip("torch", reason="coassist.intent needs the learn extra")
    from coassist.intent.model import SIDECAR

    assert INTENT_FOLDERS["model"].marker == SIDECAR


def test_any_other_folder_is_tried_as_a_model_and_refused_in_one_line(tmp_path):
    pytest.importorskip("torch", reason="coassist.intent needs the learn extra")
    with pytest.raises(ValueError, match=r"could not be loaded as a model") as info:
        load_intent_source(str(tmp_path))  # a folder, but no model in it
    assert "\n" not in str(info.value)
    with pytest.raises(
        ValueError,
        match=r"intent must be one of nominal, constant-velocity, oracle, present, present-held, present-half, paths",
    ):
        load_intent_source("")
    with pytest.raises(ValueError, match="network must be one of"):
        load_intent_source("nominal", network="gpu")


def test_a_string_that_is_neither_a_name_nor_a_folder_says_so_and_names_the_sources(tmp_path):
    # issue 42: a typo of "paths" said "could not be loaded as a model: pahts/model.json: not found"
    names = "nominal, constant-velocity, oracle, present, present-held, present-half, paths"
    with pytest.raises(ValueError) as info:
        load_intent_source("pahts")
    assert str(info.value) == (
        f"intent 'pahts' is neither a source name ({names}) nor an existing folder; did you mean 'paths'?"
    )
    missing = str(tmp_path / "models" / "m1")
    with pytest.raises(ValueError) as info:
        load_intent_source(missing)
    assert str(info.value) == f"intent {missing!r} is neither a source name ({names}) nor an existing folder"
    with pytest.raises(ValueError, match=r"not one of nominal, .*; did you mean 'constant-velocity'\?$"):
        check_intent("constant-velocty")


def test_check_intent_names_the_choices(tmp_path):
    check_intent("present")
    check_intent("oracle")
    with pytest.raises(ValueError) as info:
        check_intent(str(tmp_path / "nomodel"))
    assert str(info.value) == (
        f"{str(tmp_path / 'nomodel')!r}: not one of nominal, constant-velocity, oracle, present, present-held, present-half, paths, "
        "a path-hypotheses calibration folder (path-hypotheses.json) or a person model folder (coassist "
        "calibrate) (person-model.json) or a calibration-draws folder (person models of several calibrations) "
        "(calibration-draws.json) or a model folder (coassist train) (model.json)"
    )
    with pytest.raises(ValueError, match="a simulation alone knows it"):
        check_intent("oracle", simulation=False)
    with pytest.raises(
        ValueError, match=r"not one of nominal, constant-velocity, present, present-held, present-half, paths, a path"
    ):
        check_intent("oracle-ish", simulation=False)


def test_the_help_lists_every_source_and_only_what_a_person_can_run():
    assert intent_choices().split(" | ")[: len(NAMED_INTENTS)] == list(NAMED_INTENTS)
    assert "oracle" not in intent_choices(simulation=False).split(" | ")
    runner = CliRunner()
    for command, simulation in (("collect", True), ("drive", True), ("ros2", False), ("play", False)):
        text = " ".join(runner.invoke(app, [command, "--help"], terminal_width=400).output.split())
        assert intent_choices(simulation=simulation) in text, command
