"""Each command's default control preset is named once (config.py), and the ones that can
have a learned predictor in the loop agree with the main job's application stage."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import typer

from coassist.cli import app
from coassist.config import APPLICATION_PRESET, COLLECTION_PRESET, CONTROL_PRESETS
from coassist.experiments.reproduce_config import ReproduceConfig
from coassist.play.session import PlayConfig
from coassist.robot.drive import DriveConfig


def _cli_default(command: str, option: str = "preset") -> object:
    group = typer.main.get_command(app)
    cmd = group.commands[command]  # type: ignore[attr-defined]  (a group: the app has several commands)
    return next(p.default for p in cmd.params if p.name == option)


def test_drive_play_and_the_main_job_agree_on_the_application_preset():
    main_job = ReproduceConfig().application_preset
    assert main_job == APPLICATION_PRESET == "thesis-application-damped"
    assert DriveConfig().preset == main_job
    assert PlayConfig(user="me", out=Path("unused")).preset == main_job
    assert _cli_default("drive") == main_job
    assert _cli_default("play") == main_job
    assert _cli_default("ros2") == main_job  # the ROS 2 node drives a real arm, a model possibly in the loop


def test_collect_defaults_to_the_main_jobs_collection_preset():
    assert ReproduceConfig().control_preset == COLLECTION_PRESET == _cli_default("collect")


def test_the_default_presets_exist_and_the_application_one_is_not_the_ringing_dm():
    # The "-dm" application weights remove 2/3 of the plant's damping with a learned
    # predictor in the loop (tests/control/test_game.py measures it); the default is not them.
    assert APPLICATION_PRESET in CONTROL_PRESETS and COLLECTION_PRESET in CONTROL_PRESETS
    assert APPLICATION_PRESET != "thesis-application-dm"


@pytest.mark.parametrize(
    "field, value, says",
    [
        ("control_preset", "thesis-evalution-dm", "did you mean 'thesis-evaluation-dm'"),
        ("application_task", "spiral", "no such task"),
        ("device", "gpu0", "cpu, cuda, cuda:<n> or mps"),
        ("tol", "x", "must be > 0"),
        ("tol", float("inf"), "finite"),
        ("new_users", -1, "user indices"),
        ("sweep_duration", -1.0, "> 0"),
        ("name", float("nan"), "non-empty string"),
        ("real_data", -1, "a folder"),
        ("intent_preset", "lsmt", "did you mean 'lstm'"),
        ("real_intent_preset", "defualt", "did you mean 'default'"),
    ],
)
def test_a_reproduce_config_refuses_what_a_stage_would_fail_on_late(field, value, says):
    """A name or number read late (a control preset, the application's task, the device) failed minutes into a run,
    or raised a TypeError (review, 2026-12-06): each is a ValueError naming the field when the config is made."""
    from dataclasses import replace

    from coassist.experiments.reproduce_config import REPRODUCE_PRESETS

    with pytest.raises(ValueError, match=rf"reproduce\.{field} .*{re.escape(says)}"):
        replace(REPRODUCE_PRESETS["tiny"], **{field: value})
