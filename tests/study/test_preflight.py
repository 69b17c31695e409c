"""``study init`` checks a plan whole: the models and calibrations it names for what the protocol asks
of them, the study's own networks, the session's time and memory (shown before the first trial); a
condition may name every intent source a person can run, read from the registries."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import read_dataset
from coassist.registry import Registry
from coassist.scenario import intent_registry
from coassist.study.folder import StudyFolder, init_study
from coassist.study.plan import PlanError, person_intents, plan_from_text
from coassist.study.preflight import bytes_per_tick, training_windows
from coassist.study.runner import ParticipantRun

from .conftest import comparison_plan

TRIALS = """
[trials]
tasks = ["linear"]
per_condition = 1
practice = 0
motion_time = 3.0
dwell = 1.0

[rest]
between_conditions = 0.0

[questionnaire]
tlx = false
likert = []
"""
TRAINING = '\n[training]\npreset = "default"\nepochs = 1\nthreads = 1\nlayers = 1\nhidden = 8\nfc = [8]\n'


def _model(folder: Path, *, label: str = "tool", horizon: int = 50) -> Path:
    """A tiny model of the loop's features and dt (one epoch on synthetic trials); ``label`` what it learned."""
    pytest.importorskip("torch", reason="a model needs the learn extra")
    from coassist.intent.training import train_model, write_model

    from ..intent.conftest import TINY, labeled

    trials = [lt._replace(trial=replace(lt.trial, intent=lt.trial.pose + 1e-3)) for lt in labeled(3)]
    preset = replace(TINY, window=replace(TINY.window, horizon=horizon, label=label))
    write_model(train_model(trials, preset, replace(TINY.train, epochs=1)), folder)
    return folder


@pytest.fixture(scope="module")
def tool_model(tmp_path_factory) -> Path:
    """A tiny model of the tool label and the controller's horizon, shared (never edited)."""
    return _model(tmp_path_factory.mktemp("tool") / "model")


def _write(folder: Path, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "plan.toml").write_text(text)
    return folder / "plan.toml"


def _comparison(intents: list[str]) -> str:
    conditions = "".join(
        f'[[condition]]\nname = "c{i}"\ncontroller = "cooperative"\nintent = "{intent}"\n'
        for i, intent in enumerate(intents)
    )
    return '[study]\nname = "sources"\nparticipants = 1\n\n' + conditions + TRIALS


def _refused(plan: Path, out: Path, field: str) -> str:
    with pytest.raises(PlanError) as err:
        init_study(plan, out)
    message = str(err.value)
    assert "\n" not in message and message.startswith(field), message
    assert not (out / "study.json").exists()  # nothing made: refused before anyone sits down
    return message


def test_a_stop_criterion_beyond_the_logged_predictions_is_refused_at_init(tmp_path):
    """bdc84ed: criterion_horizon 60 against the models' 50 passed init; round 1's check then wrote NaN
    ("Out of range float values are not JSON compliant") and every re-run stopped there."""
    pytest.importorskip("torch", reason="an iterative study needs the learn extra")
    text = '[study]\nname = "iter"\nprotocol = "iterative"\n\n[iterative]\nrounds = 2\ntrials_per_round = 2\n'
    plan = _write(tmp_path / "plans", text + "criterion_horizon = 60\n" + TRIALS + TRAINING)
    message = _refused(plan, tmp_path / "study", "iterative.criterion_horizon")
    assert "give at most 50" in message
    plan.write_text(text + "criterion_horizon = 50\n" + TRIALS + TRAINING)
    assert init_study(plan, tmp_path / "study").plan().iterative.criterion_horizon == 50
    # the training preset of the intent label trains on what a person's trials do not have
    plan.write_text(text + TRIALS + TRAINING.replace('preset = "default"', 'preset = "intent"'))
    _refused(plan, tmp_path / "other", "training.preset")


def test_a_model_is_checked_for_what_the_protocol_asks_of_it(tmp_path, tool_model):
    """bdc84ed: a transfer whose source was trained on the intent label passed init and failed after the
    participant's transfer trials; a model of a horizon shorter than the controller's failed at its first trial."""
    intent_model = _model(tmp_path / "intent-model", label="intent")
    short_model = _model(tmp_path / "short-model", horizon=10)
    text = '[study]\nname = "tl"\nprotocol = "transfer"\n\n[transfer]\ntrials = 2\nsource_model = "{}"\n'
    plan = _write(tmp_path / "plans", text.format(intent_model) + TRIALS + TRAINING)
    message = _refused(plan, tmp_path / "study", "transfer.source_model")
    assert "'intent' label" in message
    plan.write_text(text.format(tool_model) + TRIALS + TRAINING)
    study = init_study(plan, tmp_path / "study")
    assert study.estimate().models.keys() == {"transferred"}  # its training estimated
    plan.write_text(_comparison(["nominal", str(short_model)]))
    message = _refused(plan, tmp_path / "short", "condition[1].intent")
    assert "predicts 10 steps; the controller needs 50" in message


def test_a_network_too_large_to_train_in_a_rest_is_refused_without_building_it(tmp_path):
    """bdc84ed: [training] hidden = 100000000 passed init and failed with an allocation error after round 0.
    The largest sizes the fields allow (8 × 4096) count 1.1e9 parameters on torch's meta device: refused,
    nothing allocated (4.5 GB as float32)."""
    torch = pytest.importorskip("torch", reason="an iterative study needs the learn extra")
    from coassist.intent.network import IntentNet, NetworkConfig
    from coassist.study.preflight import MAX_PARAMETERS

    big = TRAINING.replace("layers = 1", "layers = 8").replace("hidden = 8", "hidden = 4096")
    text = '[study]\nname = "iter"\nprotocol = "iterative"\n\n[iterative]\nrounds = 2\ntrials_per_round = 2\n'
    message = _refused(_write(tmp_path / "plans", text + TRIALS + big), tmp_path / "study", "training")
    assert "more than the 100,000,000 a model may have" in message  # any model's bound (NetworkConfig)
    # 2 × 2048: 50 million, under any model's bound and over a study's
    big = TRAINING.replace("layers = 1", "layers = 2").replace("hidden = 8", "hidden = 2048")
    message = _refused(_write(tmp_path / "plans2", text + TRIALS + big), tmp_path / "study2", "training")
    assert f"{MAX_PARAMETERS:,}" in message
    # the count on the meta device is the parameters of a network built for real (an independent count)
    from coassist.study import preflight

    cfg = NetworkConfig(8, 100, 2, 16, (12,))
    real = sum(p.numel() for p in IntentNet(cfg, generator=torch.Generator().manual_seed(0)).parameters())
    hand = 4 * 16 * (8 + 16) + 8 * 16 + 4 * 16 * (16 + 16) + 8 * 16 + (16 * 12 + 12) + (12 * 100 + 100)
    assert preflight._n_parameters(cfg) == real == hand


def test_a_plan_whose_trials_would_share_seeds_is_refused(tmp_path):
    """Each participant's trials draw from the 10 000 seeds past their base: 11 rounds of 1 000 trials gave
    participant 1's round 10 the seeds of participant 2's round 0 (the same paths and obstacles), and init took it."""
    pytest.importorskip("torch", reason="an iterative study needs the learn extra")
    text = '[study]\nname = "iter"\nprotocol = "iterative"\nparticipants = 2\n\n[iterative]\n'
    plan = _write(tmp_path / "plans", text + "rounds = 11\ntrials_per_round = 1000\n" + TRIALS + TRAINING)
    message = _refused(plan, tmp_path / "study", "iterative.rounds × iterative.trials_per_round")
    assert "round-10 trial 1 would take seed base + 10000, outside the participant's 10 000 seeds" in message
    # a comparison's conditions share measured trial j's seed on purpose (paired), and pass (once refused)
    comparison = comparison_plan(tmp_path / "pairs", per_condition=2, practice=1)
    assert init_study(comparison, tmp_path / "paired").plan().trials.per_condition == 2


def test_a_session_longer_than_a_person_can_sit_is_refused(tmp_path):
    plan = comparison_plan(tmp_path / "plans", per_condition=1000, timing="motion_time = 10.0")
    message = _refused(plan, tmp_path / "study", "a participant's session would take about")
    assert "more than 8 h" in message


def test_the_estimate_is_what_a_dry_run_takes(_finished_study):
    """The estimate recorded at init against the simulated participant's trials: their durations (the
    operator arrives as planned, then dwells) and their arrays' bytes a tick."""
    study = StudyFolder(_finished_study)
    estimate = study.estimate()
    trials = [
        t for b in ("assistive", "impedance", "manual") for t in read_dataset(study.participant("S01").block(b)).trials
    ]
    assert estimate.n_trials == len(trials) == 3
    took = sum(t.n_samples * t.meta.dt for t in trials)
    assert estimate.trials_s == pytest.approx(took, rel=0.15), (estimate.trials_s, took)
    arrays = sum(v.nbytes for t in trials for v in vars(t).values() if hasattr(v, "nbytes"))
    without_alpha = sum(t.n_samples for t in trials if t.alpha is None)  # IMP and MG: no game, no α
    assert without_alpha == sum(t.n_samples for t in trials[1:])
    assert bytes_per_tick(50) * sum(t.n_samples for t in trials) - 8 * without_alpha == arrays  # 920 B a tick, exactly
    limit = 2.0 * 3.9 + 10.0  # the default time limit of a 3 s motion (ending at 3.9 s)
    assert estimate.trial_bytes == 2 * math.ceil(limit / 0.008) * 920
    # questionnaires (ten items, ten seconds each) and the two rests of 30 s make up the rest of the session
    assert estimate.expected_s == pytest.approx(estimate.trials_s + 3 * 10 * 10.0 + 2 * 30.0)


def test_training_windows_are_those_a_model_trains_on():
    # WindowSet: windows end at k = history−1 … T−1−H every stride ticks (coassist.intent.features)
    history, horizon, stride = 125, 50, 4
    for ticks in ([613], [613, 400, 175, 174], [300] * 5):
        by_hand = sum(len(range(history - 1, t - 1 - horizon + 1, stride)) for t in ticks)
        assert training_windows(ticks, history, horizon, stride, 0.0) == by_hand
    assert training_windows([613, 613], history, horizon, stride, 0.2) == training_windows(
        [613], history, horizon, stride, 0.0
    )


def test_init_shows_the_estimate_and_recommends_a_dry_run(tmp_path):
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    out = tmp_path / "study"
    result = CliRunner().invoke(app, ["study", "init", str(plan), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "a participant's session: about" in result.output and "memory: about" in result.output
    rehearsal = tmp_path / "study-rehearsal"
    assert f"coassist study run {rehearsal} --simulate --participant S01" in result.output
    said: list[str] = []
    with ParticipantRun(StudyFolder(out), "S01", simulate=True, say=said.append) as run:
        run.run()
    assert said[0].startswith("S01: a participant's session: about")  # before the first trial


def test_a_plan_takes_every_intent_source_a_person_can_run_and_the_dry_run_runs_them(tmp_path, tool_model):
    """The named sources (those of the registry that are not simulation-only) and the folder kinds (a
    calibration, a model), every one a condition; the oracle refused; each condition's trial runs it."""
    from coassist.scenario.path_hypotheses import write_calibration

    names = list(person_intents())
    assert names == [n for n, e in intent_registry.INTENT_SOURCES.items() if not e.simulation_only]
    assert {"nominal", "constant-velocity", "present", "paths"} <= set(names) and "oracle" not in names
    calibration = write_calibration(tmp_path / "calibration", {})
    model = tool_model
    intents = [*names, str(calibration), str(model)]
    plan = _write(tmp_path / "plans", _comparison(intents))
    parsed = plan_from_text(plan.read_text(), plan.parent)
    assert [c.intent for c in parsed.conditions] == intents
    with pytest.raises(PlanError, match=r"^condition\[1\]\.intent: 'oracle' is the simulated operator's true intent"):
        plan_from_text(_comparison(["nominal", "oracle"]), ".")
    study = init_study(plan, tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    ids = {}
    for i, intent in enumerate(intents):
        (trial,) = read_dataset(study.participant("S01").block(f"c{i}")).trials
        assert trial.meta.extra["ended"] == "target"
        ids[intent] = trial.meta.model_id
    assert ids["nominal"] is None and ids["paths"] == "paths" and ids[str(model)].startswith("model@")
    assert ids[str(calibration)].startswith("paths:calibration@")  # the calibrated source, not the named one


def test_a_source_registered_later_is_a_condition_with_nothing_changed_in_the_study(tmp_path, monkeypatch):
    extended = Registry(
        "intent source",
        {
            **intent_registry.INTENT_SOURCES,
            "my-guess": intent_registry.IntentSourceEntry(
                "coassist.scenario.constant_velocity:ConstantVelocityIntent", "a test's own guess"
            ),
            "my-oracle": intent_registry.IntentSourceEntry(
                "coassist.scenario.reference_intents:OracleIntent", "a test's own oracle", simulation_only=True
            ),
        },
    )
    monkeypatch.setattr(intent_registry, "INTENT_SOURCES", extended)
    assert person_intents()[-1] == "my-guess"
    with pytest.raises(PlanError, match=r"^condition\[1\]\.intent: 'my-oracle'"):
        plan_from_text(_comparison(["nominal", "my-oracle"]), ".")
    study = init_study(_write(tmp_path / "plans", _comparison(["nominal", "my-guess"])), tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    (trial,) = read_dataset(study.participant("S01").block("c1")).trials
    assert trial.meta.model_id == "constant-velocity" and trial.meta.extra["ended"] == "target"  # its class's id


@pytest.mark.parametrize(
    ("participants", "conditions", "line"),
    [
        (
            4,
            3,
            "warning: study.participants = 4 is not a multiple of 6, the rows of the balanced Latin square of 3 "
            "conditions (3 rows and their mirror, 3 being odd): their order is not counterbalanced (every condition "
            "equally often in every position, every pair next to each other equally often) unless the number of "
            "participants who finish is a multiple of 6; plan 6",
        ),
        (
            9,
            4,
            "warning: study.participants = 9 is not a multiple of 4, the rows of the balanced Latin square of 4 "
            "conditions (4 rows, 4 being even): their order is not counterbalanced (every condition equally often in "
            "every position, every pair next to each other equally often) unless the number of participants who "
            "finish is a multiple of 4; plan 8 or 12",
        ),
        (12, 3, None),
        (4, 2, None),
    ],
)
def test_init_warns_of_participants_that_fill_no_whole_latin_square(tmp_path, participants, conditions, line):
    """Participants take the Latin square's rows in turn: a count that is not a multiple of its rows leaves the
    order unbalanced. study init says so (a warning, not an error: the folder is made), as the estimate's lines."""
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    extra = '[[condition]]\nname = "arbitrated"\ncontroller = "cooperative-arbitrated"\n\n[trials]'
    text = plan.read_text().replace("participants = 4", f"participants = {participants}")
    if conditions == 4:
        text = text.replace("[trials]", extra)
    elif conditions == 2:
        text = text.replace('[[condition]]\nname = "manual"\ncontroller = "manual"\n', "")
    plan.write_text(text)
    out = tmp_path / "study"
    result = CliRunner().invoke(app, ["study", "init", str(plan), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert len(StudyFolder(out).labels) == conditions
    warnings = [w for w in result.output.splitlines() if w.startswith("warning: ")]
    assert warnings == ([line] if line else [])
    estimate = StudyFolder(out).estimate()
    lines = estimate.lines()  # what study run shows before the first trial too
    assert [f"warning: {w}" for w in estimate.warnings] == warnings == lines[len(lines) - len(warnings) :]
