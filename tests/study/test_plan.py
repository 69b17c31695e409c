"""The plan: a valid one reads into its dataclasses; a bad one is one line naming the field (via the CLI too)."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.study.plan import PlanError, load_plan, plan_from_text

from .conftest import COMPARISON


def _plan(**fmt) -> str:
    args = {"world": "play", "per_condition": 2, "practice": 1, "timing": ""}
    args.update(fmt)
    return COMPARISON.format(**args)


def test_a_valid_plan_reads_into_its_fields(comparison_file):
    plan = load_plan(comparison_file)
    assert plan.protocol == "comparison" and plan.world == "play" and plan.participants == 4 and plan.seed == 3
    assert [c.name for c in plan.conditions] == ["assistive", "impedance", "manual"]
    assert [c.controller for c in plan.conditions] == ["cooperative", "impedance", "manual"]
    assert (
        plan.trials.tasks == ("linear", "curved") and plan.trials.per_condition == 2 and plan.trials.motion_time == 3.0
    )
    assert plan.questionnaire.tlx and len(plan.questionnaire.likert) == 4
    assert plan.training is None
    assert plan.population == "thesis"


def test_a_plans_population_is_who_the_simulated_participants_are(comparison_file):
    from coassist.scenario.populations import population_profile
    from coassist.study.participants import simulated_profile

    text = comparison_file.read_text().replace("seed = 3", 'seed = 3\npopulation = "held-out"')
    plan = plan_from_text(text, ".")
    assert plan.population == "held-out"
    assert simulated_profile(2, plan.seed, plan.population) == population_profile("held-out", 2, 3)
    assert simulated_profile(2, plan.seed) == population_profile("thesis", 2, 3)


@pytest.mark.parametrize(
    ("world", "real_arm"), [("play", False), ("mujoco", False), ("ur", True), ("franka", True), (None, False)]
)
def test_every_world_a_plan_names_today_still_reads(world, real_arm):
    """The plan's [study] world keeps its names (coassist.robot.worlds.study_worlds, the one table's
    entries a study runs); none given: play. The page's motion times are the play world's only."""
    from coassist.study.plan import is_real_arm

    timing = "motion_time = 3.0\ndwell = 1.0" if world in ("play", None) else ""
    text = _plan(world=world or "play", timing=timing)
    if world is None:
        text = text.replace('world = "play"\n', "")
    plan = plan_from_text(text, ".")
    assert plan.world == (world or "play") and is_real_arm(plan.world) is real_arm


@pytest.mark.parametrize("world", ["point-mass", "sim", "ros2", "gazebo"])
def test_a_world_no_study_runs_is_refused_naming_those_it_runs(world):
    with pytest.raises(
        PlanError, match=rf"^study.world: '{world}': no such study world.*\(choose from: play, mujoco, ur, franka\)$"
    ):
        plan_from_text(_plan(world=world, timing=""), ".")


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda t: t.replace("per_condition = 2", "per_condition = 0"), "trials.per_condition"),
        (lambda t: t.replace("per_condition = 2", "per_conditon = 2"), "trials.per_conditon"),
        (lambda t: t.replace('controller = "impedance"', 'controller = "imp"'), "condition[1].controller"),
        (lambda t: t.replace('world = "play"', 'world = "gazebo"'), "study.world"),
        (lambda t: t.replace('protocol = "comparison"', 'protocol = "abba"'), "study.protocol"),
        (lambda t: t.replace('tasks = ["linear", "curved"]', 'tasks = ["linear", "spiral"]'), "trials.tasks[1]"),
        (lambda t: t.replace('name = "manual"', 'name = "impedance"'), "condition"),
        (lambda t: t.replace("between_conditions = 30.0", "between_conditions = -1"), "rest.between_conditions"),
        (lambda t: t + "\n[questionnaire]\nlikert_points = 2\n", "questionnaire.likert_points"),
        (lambda t: t.replace('world = "play"', 'world = "mujoco"') + "\n", "trials.motion_time"),
        (lambda t: t.replace("[rest]", "[rests]"), "rests"),
        (lambda t: t + "\n[training]\nepochs = 1\n", "training"),
        (lambda t: t + '\n[[condition]]\nname = "again"\ncontroller = "cooperative"\n', "condition"),
        (lambda t: t.replace('name = "comparison"', 'name = "a b"'), "study.name"),
        (lambda t: t.replace("seed = 3", 'seed = 3\npopulation = "everyone"'), "study.population"),
        (lambda t: t.replace("[study]", "[study]\nparticipants = 1\n"), None),  # duplicate key: TOML's own error
    ],
)
def test_a_bad_plan_is_one_line_naming_the_field(edit, field):
    text = edit(_plan(timing="motion_time = 3.0"))
    with pytest.raises(PlanError) as err:
        plan_from_text(text, ".")
    message = str(err.value)
    assert "\n" not in message
    if field is None:
        assert message.startswith("not TOML")
    else:
        assert message.startswith(field), message


@pytest.mark.parametrize(
    ("edit", "line"),
    [
        (
            lambda t: t.replace('name = "manual"', 'name = "manual\\n"'),
            "condition[2].name must be 1-32 lower-case letters, digits, '-' or '_' (not one of ['adaptation', "
            "'answers', 'calibrated', 'calibration', 'models', 'practice', 'transfer-set'], round-* or calibration-*), "
            "got 'manual\\n'",
        ),
        (
            lambda t: t.replace('name = "comparison"', 'name = "comparison\\n"'),
            "study.name must be 1-64 letters, digits, '-' or '_', got 'comparison\\n'",
        ),
    ],
)
def test_a_name_with_a_trailing_newline_is_refused(edit, line):
    """``$`` matches before a final newline: a name is matched whole (as the participant ids are)."""
    with pytest.raises(PlanError) as err:
        plan_from_text(edit(_plan(timing="motion_time = 3.0")), ".")
    assert str(err.value) == line


@pytest.mark.parametrize("controller", ["manual", "impedance"])
def test_two_conditions_the_person_cannot_tell_apart_are_refused(controller):
    """MG and IMP never read the intent: two conditions of one that differ in intent only move the person the same
    (only the logged prediction and its e_RMS differ), one condition under two names. One such condition with a
    source is accepted: its e_RMS is the source's, measured with no assistance."""
    text = _plan(timing="motion_time = 3.0").replace(
        'controller = "manual"', 'controller = "manual"\nintent = "constant-velocity"'
    )
    # no intent given: the cooperative condition assists with what every arm command does (present-held; nominal,
    # which it was, needs more hand force than MG), the impedance one logs the plan's rows
    assert [c.intent for c in plan_from_text(text, ".").conditions] == ["present-held", "nominal", "constant-velocity"]
    twin = f'\n[[condition]]\nname = "twin"\ncontroller = "{controller}"\nintent = "present"\n'
    at = _plan(timing="motion_time = 3.0").index("[trials]")
    base = _plan(timing="motion_time = 3.0")
    with pytest.raises(PlanError) as err:
        plan_from_text(base[:at] + twin + "\n" + base[at:], ".")
    i = 1 if controller == "impedance" else 2
    assert str(err.value) == (
        f"condition[{i}] and condition[3] give the person the same motion: controller '{controller}' reads no intent "
        "('nominal' and 'present' differ only in the prediction logged); keep one, or use a controller that reads it "
        "(cooperative, cooperative-arbitrated, cooperative-damped)"
    )


def test_a_model_the_plan_names_must_exist(tmp_path):
    text = _plan().replace('controller = "cooperative"', 'controller = "cooperative"\nintent = "models/M9"')
    with pytest.raises(PlanError, match=r"^condition\[0\]\.intent: 'models/M9' is not a source a person can run"):
        plan_from_text(text, tmp_path)


ITERATIVE = """
[study]
name = "iter"
protocol = "iterative"

[iterative]
rounds = 2
trials_per_round = 2

[trials]
tasks = ["linear"]
practice = 0
motion_time = 3.0
dwell = 1.0

[rest]
between_conditions = 30.0

[training]
epochs = 1
"""


def _set(text: str, table: str, line: str) -> str:
    """``text`` with ``line`` added at the top of ``[table]`` (a key set twice would be TOML's own error)."""
    key = line.split("=")[0].strip()
    lines = text.splitlines()
    start = lines.index(f"[{table}]")
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
    kept = [x for x in lines[start + 1 : end] if x.split("=")[0].strip() != key]
    return "\n".join([*lines[: start + 1], line, *kept, *lines[end:]]) + "\n"


@pytest.mark.parametrize(
    ("table", "line", "field"),
    [
        # each of these passed study init on bdc84ed and failed, or blocked, only after a participant's trials
        ("trials", "time_limit = 1e300", "trials.time_limit"),  # "Maximum allowed size exceeded" at run time
        ("trials", "time_limit = 1e-9", "trials.time_limit"),  # refused only by the first trial
        ("trials", "time_limit = 4.0", "trials.time_limit"),  # 3.9 s of planned motion + 1 s dwell: never in time
        ("trials", "motion_time = 1e7", "trials.motion_time"),  # MemoryError (18.6 GiB) in the first trial
        ("trials", "dwell = 1e300", "trials.dwell"),
        ("trials", "dwell = 20.0", "trials.dwell"),  # longer than the default time limit leaves after the motion
        ("trials", 'arrive_radius = "0.03"', "trials.arrive_radius"),  # a string is not a number
        ("trials", "arrive_radius = 0.5", "trials.arrive_radius"),  # every task's start is 0.5 m from its target
        ("trials", "motion_time = nan", "trials.motion_time"),
        ("rest", "between_conditions = 1e300", "rest.between_conditions"),
        ("rest", "between_trials = inf", "rest.between_trials"),
        ("study", "seed = 1_000_000_000_000", "study.seed"),
        ("iterative", "tolerance = 1e300", "iterative.tolerance"),
        ("iterative", "criterion_horizon = 1_000_000", "iterative.criterion_horizon"),
        ("training", "epochs = 1_000_000_000", "training.epochs"),
        ("training", "hidden = 100_000_000", "training.hidden"),
        ("training", "layers = 1000", "training.layers"),
        ("training", "fc = [100_000_000]", "training.fc"),
        ("training", "batch_size = 1e9", "training.batch_size"),
        ("training", "lr = 1e300", "training.lr"),
        ("study", 'id_pattern = "P[0-9"', "study.id_pattern"),
    ],
)
def test_every_number_has_a_range_a_study_can_use_named_in_one_line(table, line, field):
    pytest.importorskip("torch", reason="a plan with [training] needs the learn extra")
    with pytest.raises(PlanError) as err:
        plan_from_text(_set(ITERATIVE, table, line), ".")
    assert "\n" not in str(err.value) and str(err.value).startswith(field), str(err.value)


def test_the_edges_of_the_ranges_are_accepted():
    pytest.importorskip("torch", reason="a plan with [training] needs the learn extra")
    text = ITERATIVE
    for table, line in [
        ("trials", "time_limit = 4.9"),  # exactly the planned motion (3.9 s) and the dwell (1 s)
        ("rest", "between_conditions = 3600.0"),
        ("training", "epochs = 1000"),
        ("training", "hidden = 4096"),
        ("iterative", "tolerance = 1.0"),
    ]:
        text = _set(text, table, line)
    plan = plan_from_text(text, ".")
    assert plan.trials.time_limit == 4.9 and plan.training.hidden == 4096 and plan.rest.between_conditions == 3600.0


def test_the_cli_prints_the_plan_error_on_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(_plan().replace("per_condition = 2", "per_condition = 0"))
    result = CliRunner().invoke(app, ["study", "init", str(bad), "--out", str(tmp_path / "s")])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert lines == [f"error: {bad}: trials.per_condition must be an integer in 1 … 1000, got 0"]
    assert not (tmp_path / "s" / "study.json").exists()


@pytest.mark.parametrize("source", ["network", "calibrated"])
def test_each_round_is_rated_before_its_stop_check(source):
    # A check whose criterion is met ends the protocol (runner: the participant is complete): asked after it, the
    # questionnaire of the converged round, the best model's, was never asked (a review ran it, 2026-12-07)
    from coassist.study.protocols import participant_steps

    text = (
        '[study]\nname = "it"\nprotocol = "iterative"\n\n'
        + ("[calibration]\ntrials = 2\n\n" if source == "calibrated" else "")
        + "[iterative]\nrounds = 3\ntrials_per_round = 1\n"
        + ('source = "calibrated"\n' if source == "calibrated" else "")
        + '\n[trials]\ntasks = ["curved"]\nmotion_time = 3.0\ndwell = 1.0\n\n[questionnaire]\ntlx = true\n'
        + ("\n[training]\nepochs = 1\n" if source == "network" else "")
    )
    steps = participant_steps(plan_from_text(text, "."), {}, 1, 0)
    ends = [(s["kind"], s["block"]) for s in steps if s["kind"] in ("questionnaire", "check")]
    assert ends == [
        ("questionnaire", "round-0"),
        ("questionnaire", "round-1"),
        ("check", "round-1"),
        ("questionnaire", "round-2"),
        ("check", "round-2"),
    ]
