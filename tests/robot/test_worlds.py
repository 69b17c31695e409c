"""The worlds as a registry (coassist.robot.worlds): one entry per world, the point mass's and
the page's too, that DriveConfig, drive, play --drive, a study plan and the command line's help
read; the ArmWorld protocol drive asks for instead of probing attributes; and the recipe that
adds a world."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.registry import load_entry_point
from coassist.robot.arms import ARMS
from coassist.robot.worlds import (
    PLAY,
    POINT_MASS,
    WORLDS,
    ArmWorld,
    HandWorld,
    WorldEntry,
    WorldRequest,
    arm_choices,
    arm_worlds,
    build_world,
    study_worlds,
    world_choices,
)

ROOT = Path(__file__).resolve().parents[2]
REQUEST = WorldRequest(robot="ur5", object="handle", rate_hz=125, seed=0, start=(-0.10, -0.615, 0.20))


def test_one_entry_per_world_with_its_arms_and_needs():
    assert tuple(WORLDS) == ("point-mass", "play", "mujoco", "ur", "franka", "ros2")
    assert {name: e.arms for name, e in WORLDS.items()} == {
        "point-mass": (),
        "play": (),
        "mujoco": ("ur5", "panda"),
        "ur": ("ur5",),
        "franka": ("panda", "fr3"),
        "ros2": ("ur5",),
    }
    assert tuple(arm_worlds()) == ("mujoco", "ur", "franka", "ros2")
    assert [name for name, e in WORLDS.items() if e.simulated] == ["point-mass", "mujoco"]
    assert [name for name, e in WORLDS.items() if e.host] == ["ur", "franka"]
    assert study_worlds() == ("play", "mujoco", "ur", "franka")
    for name, entry in arm_worlds().items():
        assert set(entry.arms) <= set(ARMS), name
        assert entry.extras, name


def test_the_point_mass_has_one_name_and_its_trials_origin():
    """The point mass is the world "point-mass" (the simulator) and "play" (the page on it); the trials
    of both record origin "sim" (TrialMeta.origin, one of ORIGINS), as the simulator and the page write it."""
    import inspect

    from coassist.data.trial import ORIGINS
    from coassist.experiments.ablation_cells import ABLATION_CELLS
    from coassist.experiments.reproduce_config import MUJOCO_PERSON_CALIBRATIONS
    from coassist.play import session as play_session
    from coassist.sim import trial_runner

    assert (POINT_MASS, PLAY) == ("point-mass", "play")
    assert WORLDS[POINT_MASS].origin == WORLDS[PLAY].origin == "sim" and "sim" in ORIGINS
    for module in (trial_runner, play_session):  # where the point mass's trials get their origin
        assert 'origin="sim"' in inspect.getsource(module), module.__name__
    assert not WORLDS[POINT_MASS].is_arm and not WORLDS[PLAY].is_arm
    # the names other tables use for worlds are the table's (the ablation's third cell is a population)
    assert set(MUJOCO_PERSON_CALIBRATIONS) <= set(WORLDS)
    assert ABLATION_CELLS[:2] == (POINT_MASS, "mujoco") and ABLATION_CELLS[2] not in WORLDS
    with pytest.raises(ValueError, match=r"^the play world is not an arm world: the drive builds mujoco, ur, franka"):
        build_world(PLAY, REQUEST)
    with pytest.raises(ValueError, match="WorldEntry without a builder .* takes no arms"):
        WorldEntry(None, ("ur5",), "x", simulated=True, host=None, extras=(), origin="sim")
    # a world's trials record its origin: one outside TrialMeta's lost the run at its end; "False" is truthy (a real
    # arm taken for a simulator: its guards off). Refused when the entry is made (review, 2026-12-06)
    arm = ("coassist.robot.mujoco_world:build_world", ("ur5",), "x")
    with pytest.raises(ValueError, match=r"WorldEntry.origin must be one of \('sim'.*got 'mylab'"):
        WorldEntry(*arm, simulated=True, host=None, extras=(), origin="mylab")
    with pytest.raises(ValueError, match=r"WorldEntry.simulated must be True or False, got 'False'"):
        WorldEntry(*arm, simulated="False", host=None, extras=(), origin="ur5")  # type: ignore[arg-type]
    from coassist.scenario.intent_registry import IntentSourceEntry

    with pytest.raises(ValueError, match=r"IntentSourceEntry.simulation_only must be True or False"):
        IntentSourceEntry("coassist.scenario.reference_intents:NominalIntent", "x", simulation_only="False")  # type: ignore[arg-type]


@pytest.mark.parametrize("name", list(arm_worlds()))
def test_each_builder_is_importable(name):
    entry = WORLDS[name]
    try:
        builder = load_entry_point(entry.build)
    except ImportError as exc:  # the world's extra is not installed here
        pytest.skip(f"{name} needs {exc.name!r} ({entry.extras})")
    assert callable(builder)


def test_a_world_that_needs_a_host_or_another_arm_is_refused_before_anything_is_imported():
    with pytest.raises(ValueError, match=r"^the ur world needs --host \(the robot's IP address\)$"):
        build_world("ur", REQUEST)
    with pytest.raises(ValueError, match=r"^the franka world needs --host \(the robot's FCI address\)$"):
        build_world("franka", WorldRequest("panda", "handle", 125, 0, (0.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match=r"^the ur world drives ur5, not 'panda'$"):
        build_world("ur", WorldRequest("panda", "handle", 125, 0, (0.0, 0.0, 0.0), host="192.0.2.1"))
    with pytest.raises(ValueError, match=r"no such world; did you mean 'ros2'"):
        build_world("ros", REQUEST)


def test_the_simulated_world_is_an_arm_world_with_a_handle():
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    from coassist.robot.mujoco_world import FTSensorModel, MujocoUR5World

    world = build_world("mujoco", REQUEST)
    try:
        assert type(world) is MujocoUR5World and isinstance(world, ArmWorld) and isinstance(world, HandWorld)
        assert world.dt == 1 / 125 and not world.realtime and not world.noise_free_sensor
    finally:
        world.close()
    quiet = MujocoUR5World("handle", sensor=FTSensorModel(noise_force=0.0, noise_torque=0.0))
    assert quiet.noise_free_sensor
    quiet.close()


def test_the_real_ur_world_is_an_arm_world_without_a_handle():
    pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra")
    spec = importlib.util.spec_from_file_location(
        "coassist_tests_fake_rtde_w", Path(__file__).with_name("fake_rtde.py")
    )
    fake_rtde = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = fake_rtde
    spec.loader.exec_module(fake_rtde)
    from coassist.robot.ur_rtde_world import URRTDEWorld

    robot = fake_rtde.FakeRobot()
    world = URRTDEWorld(
        "192.0.2.10", frequency=125.0, control_factory=robot.control_factory, receive_factory=robot.receive_factory
    )
    try:
        assert isinstance(world, ArmWorld) and not isinstance(world, HandWorld)
        assert not world.noise_free_sensor
        mass, com = world.tool_mass_and_com()
        assert mass == 0.0 and np.array_equal(com, np.zeros(3))
        # the controller's own TCP, read back at connect (the fake's installation TCP, not the flange)
        np.testing.assert_array_equal(world.kinematics().tcp_offset, robot.tcp_offset)
    finally:
        world.close()


@pytest.mark.parametrize(
    "module, cls", [("coassist.robot.franka_world", "FrankaWorld"), ("coassist.robot.ros2_world", "Ros2World")]
)
def test_the_other_real_worlds_offer_the_protocols_members(module, cls):
    klass = getattr(pytest.importorskip(module), cls)
    for member in ("kinematics", "tool_mass_and_com", "noise_free_sensor", "read", "apply", "stop", "close"):
        assert hasattr(klass, member), member
    assert not hasattr(klass, "hand_pose")  # a person holds the handle


def test_drive_refuses_a_world_without_the_protocol_in_one_line():
    pytest.importorskip("pinocchio", reason="the drive needs the robot extra")
    from coassist.robot.drive import DriveConfig, drive

    class OnlyAWorld:  # a World, but no kinematics, payload or sensor facts
        dt, command_space, n_joints, realtime = 0.008, "joint_velocity", 6, False

        def read(self): ...
        def apply(self, command): ...
        def stop(self): ...
        def close(self): ...

    with pytest.raises(ValueError) as info:
        drive(DriveConfig(world="ur"), world=OnlyAWorld())
    assert str(info.value) == (
        "world must be an arm world (coassist.robot.worlds.ArmWorld); a OnlyAWorld lacks "
        "kinematics, noise_free_sensor, tool_mass_and_com"
    )


def test_drive_config_reads_the_registry():
    pytest.importorskip("pinocchio", reason="the drive needs the robot extra")
    from coassist.robot.drive import DriveConfig

    assert DriveConfig(world="ros2").robot == "ur5"  # coassist ros2's runs are recorded as world "ros2"
    with pytest.raises(ValueError, match=r"DriveConfig.world must be one of \('mujoco', 'ur', 'franka', 'ros2'\)"):
        DriveConfig(world="gazebo")
    for world in (POINT_MASS, PLAY):  # in the table, not an arm: the drive names the arm worlds
        with pytest.raises(ValueError, match=r"DriveConfig.world must be one of \('mujoco', 'ur', 'franka', 'ros2'\)"):
            DriveConfig(world=world)
    for world in ("ur", "franka", "ros2"):
        with pytest.raises(
            ValueError, match="DriveConfig.intent must be a source a real arm can run, not the simulated"
        ):
            DriveConfig(world=world, intent="oracle")


def test_the_help_lists_every_world_and_its_arms():
    runner = CliRunner()
    drive_help = " ".join(runner.invoke(app, ["drive", "--help"], terminal_width=400).output.split())
    assert world_choices() in drive_help and arm_choices() in drive_help
    assert all(f"{e.host} (--world {n})" in drive_help for n, e in WORLDS.items() if e.host)
    play_help = " ".join(runner.invoke(app, ["play", "--help"], terminal_width=400).output.split())
    assert " | ".join(arm_worlds()) in play_help
    assert POINT_MASS not in world_choices() and "play (" not in world_choices()
    refused = runner.invoke(app, ["drive", "--world", POINT_MASS], terminal_width=400)
    assert refused.exit_code == 2
    assert "--world 'point-mass': no such arm world (choose from: mujoco, ur, franka, ros2)" in refused.output


def test_a_world_registered_by_one_line_drives_as_the_built_in_one(tmp_path, monkeypatch):
    """The recipe end to end: a new module with ``build_world`` and one more registry entry; the
    drive runs it, records it by name, and (built like the mujoco world) it gives the mujoco trial."""
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    from coassist.robot import drive as drive_module

    (tmp_path / "coassist_test_my_world.py").write_text(
        "from coassist.robot.mujoco_world import MujocoUR5World\n\n"
        "def build_world(request):\n"
        "    return MujocoUR5World(request.object, control_dt=1.0 / request.rate_hz, start=request.start,\n"
        "                          seed=request.seed, view=request.view, realtime=request.realtime)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    line = {
        "my-arm": WorldEntry(
            "coassist_test_my_world:build_world",
            ("ur5",),
            "the MuJoCo UR5, built by a test",
            simulated=True,
            host=None,
            extras=("robot",),
            origin="mujoco",
        )
    }
    WORLDS.register(*line.popitem())  # the one line, from this module: the drive reads the same table
    try:
        config = drive_module.DriveConfig(world="my-arm", controller="cooperative", intent="oracle", time_limit=0.6)
        mine = drive_module.drive(config)
    finally:
        WORLDS.unregister("my-arm")
    builtin = drive_module.drive(
        drive_module.DriveConfig(world="mujoco", controller="cooperative", intent="oracle", time_limit=0.6)
    )
    assert mine.meta.extra["world"] == "my-arm" and builtin.meta.extra["world"] == "mujoco"
    assert mine.n_samples == builtin.n_samples > 50
    for column in ("pose", "wrench", "effort_r", "joints", "joint_velocity", "fault"):
        np.testing.assert_array_equal(getattr(mine, column), getattr(builtin, column), err_msg=column)
