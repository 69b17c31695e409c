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
from coassist.scenario.reference_intents import NominalIntent, OracleIntent

ROOT = Path(__file__).resolve().parents[2]

#: What each name built before the registry (the if-chain of load_intent_source): class and model_id.
BEFORE = {
    "nominal": (NominalIntent, None),
    "constant-velocity": (ConstantVelocityIntent, "constant-velocity"),
    "oracle": (OracleIntent, "oracle"),
    "present": (PathHypothesesIntent, "present"),
    "paths": (PathHypothesesIntent, "paths"),
}


def test_the_names_are_the_ones_the_loop_knew():
    assert NAMED_INTENTS == tuple(INTENT_SOURCES) == ("nominal", "constant-velocity", "oracle", "present", "paths")
    assert [name for name, e in INTENT_SOURCES.items() if e.simulation_only] == ["oracle"]


@pytest.mark.parametrize("name", list(BEFORE))
def test_each_name_builds_its_source_for_the_horizon(name):
    cls, model_id = BEFORE[name]
    source = load_intent_source(name, horizon=17)
    assert type(source) is cls and source.horizon == 17 and source.model_id == model_id
    assert isinstance(source, IntentSource)
    if cls is PathHypothesesIntent:
        assert source.use_obstacles == (name == "paths")


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


def test_anything_else_is_tried_as_a_model_and_refused_in_one_line(tmp_path):
    pytest.importorskip("torch", reason="coassist.intent needs the learn extra")
    with pytest.raises(ValueError, match=r"could not be loaded as a model") as info:
        load_intent_source(str(tmp_path / "missing"))
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match=r"intent must be one of nominal, constant-velocity, oracle, present, paths"):
        load_intent_source("")
    with pytest.raises(ValueError, match="network must be one of"):
        load_intent_source("nominal", network="gpu")


def test_check_intent_names_the_choices(tmp_path):
    check_intent("present")
    check_intent("oracle")
    with pytest.raises(ValueError) as info:
        check_intent(str(tmp_path / "nomodel"))
    assert str(info.value) == (
        f"{str(tmp_path / 'nomodel')!r}: not one of nominal, constant-velocity, oracle, present, paths, "
        "a path-hypotheses calibration folder (path-hypotheses.json) or a person model folder (coassist "
        "calibrate) (person-model.json) or a model folder (coassist train) (model.json)"
    )
    with pytest.raises(ValueError, match="a simulation alone knows it"):
        check_intent("oracle", simulation=False)
    with pytest.raises(ValueError, match=r"not one of nominal, constant-velocity, present, paths, a path"):
        check_intent("oracle-ish", simulation=False)


def test_the_help_lists_every_source_and_only_what_a_person_can_run():
    assert intent_choices().split(" | ")[:5] == list(NAMED_INTENTS)
    assert "oracle" not in intent_choices(simulation=False).split(" | ")
    runner = CliRunner()
    for command, simulation in (("collect", True), ("drive", True), ("ros2", False), ("play", False)):
        text = " ".join(runner.invoke(app, [command, "--help"], terminal_width=400).output.split())
        assert intent_choices(simulation=simulation) in text, command
