"""DriveConfig's checks (coassist.robot.drive): every wrong field is a one-line ValueError naming
``DriveConfig.<field>``, before anything is built (no MuJoCo needed)."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.robot.drive import DriveConfig

PERSON_ID = "1-32 letters, digits, '-' or '_' (a pseudonymous id, e.g. P07)"


def refused(**kwargs) -> str:
    with pytest.raises(ValueError) as info:
        DriveConfig(**kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize(
    "kwargs, message",
    [
        # a string meant as "off" is truthy: it switched the field on
        ({"full_pose": "no"}, "DriveConfig.full_pose must be True or False, got 'no'"),
        ({"full_pose": 2}, "DriveConfig.full_pose must be True or False, got 2"),
        (
            {"realtime_intent": "off"},
            "DriveConfig.realtime_intent must be True, False or None (the world's default), got 'off'",
        ),
        # True is an int: it was taken as 1 s
        ({"time_limit": True}, "DriveConfig.time_limit must be a number of seconds in (0, 600] or None, got True"),
        # 125.0 == 125 passed `in (125, 500)`
        ({"rate_hz": 125.0}, "DriveConfig.rate_hz must be 125 or 500 (an int), got 125.0"),
        ({"rate_hz": True}, "DriveConfig.rate_hz must be 125 or 500 (an int), got True"),
        # unhashable: `in` on a dict raised TypeError naming nothing
        ({"obstacle": ["small"]}, "DriveConfig.obstacle must be one of ('small', 'large'), got ['small']"),
        (
            {"world": ["mujoco"]},
            "DriveConfig.world must be one of ('mujoco', 'ur', 'franka', 'ros2'), got ['mujoco']",
        ),
        ({"object": "plate"}, "DriveConfig.object must be one of ('handle', 'board', 'heavy'), got 'plate'"),
        ({"object": ["handle"]}, "DriveConfig.object must be one of ('handle', 'board', 'heavy'), got ['handle']"),
        ({"preset": ["x"]}, "DriveConfig.preset must be a control preset's name, got ['x']"),
        # "$" matched before a trailing newline
        ({"person": "P07\n"}, f"DriveConfig.person must be {PERSON_ID}, got 'P07\\n'"),
    ],
)
def test_a_wrong_field_is_a_value_error_naming_it(kwargs, message):
    assert refused(**kwargs) == message


def test_an_unknown_preset_is_named_as_the_field():
    message = refused(preset="nope")
    assert message.startswith("DriveConfig.preset 'nope': no such control preset (choose from: thesis-evaluation, ")


@pytest.mark.parametrize("intent", ["", "  ", "\t\n"])
def test_a_blank_intent_is_refused_at_once(intent):
    assert refused(intent=intent).startswith("DriveConfig.intent must be one of nominal, ")


def test_real_bools_numbers_and_ints_still_pass():
    config = DriveConfig(full_pose=True, realtime_intent=False, time_limit=2, rate_hz=np.int64(500), person="P07")
    assert (config.full_pose, config.realtime_intent, config.time_limit, config.dt) == (True, False, 2, 0.002)
    assert config.who == "P07"
    assert DriveConfig(time_limit=0.5).time_limit == 0.5


def test_a_predictor_backend_needs_a_network_run_off_the_control_thread(tmp_path):
    """predictor_backend is where a model runs off the control thread: with an intent computed in the tick (a named
    source, a person model; a model with realtime_intent off) another backend changed nothing, so it is refused."""
    person = tmp_path / "person"
    person.mkdir()
    (person / "person-model.json").write_text("{}")  # the marker: a person-model folder, no network in it
    for intent in ("paths", "present-held", str(person)):
        for world, realtime in (("ur", None), ("mujoco", True)):
            message = refused(intent=intent, world=world, realtime_intent=realtime, predictor_backend="onnx")
            assert message == (
                f"DriveConfig.predictor_backend must be 'process' (the default) with intent {intent!r} "
                "(it has no network to run), got 'onnx'"
            )
    model = str(tmp_path / "M0")  # no such kind of folder: tried as a model (its loader says what is wrong)
    for world, realtime in (("mujoco", None), ("ur", False)):
        assert refused(intent=model, world=world, realtime_intent=realtime, predictor_backend="torch") == (
            f"DriveConfig.predictor_backend must be 'process' (the default) with intent {model!r} "
            "(realtime_intent is off: the model runs in the tick), got 'torch'"
        )
    # a model off the control thread: asked for in a simulated world, the real arm's default
    assert DriveConfig(intent=model, realtime_intent=True, predictor_backend="onnx").predictor_backend == "onnx"
    assert DriveConfig(world="ur", intent=model, predictor_backend="torch").predictor_backend == "torch"
    # realtime_intent without a network stays allowed (it paces a simulated world: the live view's use), and the
    # defaults stay valid in both kinds of world
    assert DriveConfig(intent="paths", realtime_intent=True).realtime_intent is True
    for world in ("mujoco", "ur"):
        assert DriveConfig(world=world, intent="paths").realtime_intent is None


def test_the_cli_names_the_option_of_a_backend_without_a_network(tmp_path):
    from coassist.cli import app

    out = tmp_path / "t.parquet"
    result = CliRunner().invoke(
        app, ["drive", "--intent", "paths", "--predictor-backend", "onnx", "--no-plot", "--out", str(out)]
    )
    assert result.exit_code == 2 and not out.exists()
    assert (
        "error: --predictor-backend must be 'process' (the default) with intent 'paths' (it has no network to run), "
        "got 'onnx'"
    ) in result.output


def test_a_joint_acceleration_beyond_the_arms_own_is_refused_and_the_smallest_holds():
    from coassist.robot.arm_descriptions import get_arm
    from coassist.robot.drive import arm_limits
    from coassist.runtime.safety_limits import SafetyLimits

    for robot in ("panda", "fr3"):  # 1000 rad/s² limited nothing (the review's DriveConfig was accepted)
        message = refused(world="franka", robot=robot, limits=SafetyLimits(joint_acceleration=1000.0))
        assert f"SafetyLimits.joint_acceleration must be at most the {robot}'s own joint accelerations" in message
    # the layer's one bound holds every joint: at most the arm's smallest (the Panda's joint 2)
    assert arm_limits(SafetyLimits(), "panda").joint_acceleration == 7.5
    assert arm_limits(SafetyLimits(joint_acceleration=5.0), "panda").joint_acceleration == 5.0
    assert arm_limits(SafetyLimits(joint_acceleration=20.0), "ur5").joint_acceleration == 20.0  # no datasheet figure
    # the FR3: Franka's FCI table, 10 rad/s² on every joint (the Panda's 15 and 20 abort an FR3's motion): 12 is
    # refused for it and not for the Panda, and the default 8 holds on it as it is
    assert get_arm("fr3").joint_acceleration_limit == (10.0,) * 7
    message = refused(world="franka", robot="fr3", limits=SafetyLimits(joint_acceleration=12.0))
    assert "SafetyLimits.joint_acceleration must be at most the fr3's own joint accelerations" in message
    assert arm_limits(SafetyLimits(joint_acceleration=12.0), "panda").joint_acceleration == 7.5
    assert arm_limits(SafetyLimits(), "fr3").joint_acceleration == SafetyLimits().joint_acceleration == 8.0
    # through franky, whose own motion generator holds joint 2 of either arm to 7.5 (franky-sim's FR3 reports it),
    # the FR3's bound is that: the layer's steps are what franky follows
    assert arm_limits(SafetyLimits(), "fr3", "franka").joint_acceleration == 7.5
    assert arm_limits(SafetyLimits(joint_acceleration=5.0), "fr3", "franka").joint_acceleration == 5.0
