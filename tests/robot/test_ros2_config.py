"""coassist.robot.ros2_world split (issue 43): the configuration and the monitor in their own modules, every
public name still importable from ros2_world, and neither the configuration nor the world's module importing
rclpy until a node is built (what `coassist drive` and the Foxglove view rely on for the joint names)."""

from __future__ import annotations

import subprocess
import sys

import pytest


def test_the_names_are_the_same_objects_from_either_module():
    from coassist.robot import ros2_config, ros2_world

    for name in ros2_config.__all__:
        assert getattr(ros2_world, name) is getattr(ros2_config, name), name
    assert set(ros2_config.__all__) <= set(ros2_world.__all__)


@pytest.mark.parametrize("module", ["coassist.robot.ros2_config", "coassist.robot.ros2_world"])
def test_importing_it_imports_no_rclpy(module):
    code = f"import sys, {module}; print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'std_msgs')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_configuration_still_names_the_field_it_refuses():
    from coassist.robot.ros2_config import MAX_STALE_AFTER, Ros2Config

    with pytest.raises(ValueError, match=r"Ros2Config\.stale_after must be at most 0\.5 s"):
        Ros2Config(stale_after=MAX_STALE_AFTER * 1.01)
    with pytest.raises(ValueError, match=r"Ros2Config\.payload"):
        Ros2Config(payload=(1.0, (0.0, 0.0)))
    assert Ros2Config(payload=(2, (0, 0, 1))).payload == (2.0, (0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match=r"Ros2Config\.command_topic .* the topic of Ros2Config\.wrench_topic"):
        Ros2Config(command_topic="/force_torque_sensor_broadcaster/wrench")


def test_the_unused_wrench_in_base_option_says_it_does_nothing(tmp_path):
    """``--wrench-in-base`` is kept for old scripts, but each wrench message's ``frame_id`` decides its frame: a
    user who passes it is told so (it was accepted silently), before anything else fails or the robot moves."""
    pytest.importorskip("rclpy", reason="coassist ros2 needs the ros2 extra (rclpy)")
    from typer.testing import CliRunner

    from coassist.cli import app

    out = tmp_path / "run.parquet"
    out.write_bytes(b"a recorded run")
    said = CliRunner().invoke(app, ["ros2", "--wrench-in-base", "--out", str(out), "--yes"])
    assert said.exit_code == 2 and "exists; pass --overwrite" in said.output
    assert "note: --wrench-in-base does nothing: each wrench message's frame_id says its frame" in said.output
    plain = CliRunner().invoke(app, ["ros2", "--out", str(out), "--yes"])
    assert plain.exit_code == 2 and "--wrench-in-base" not in plain.output


def test_the_urs_joints_out_of_kinematic_order_are_refused():
    # q is read in joint_names' order and taken for joint 1..6 by the forward kinematics: the UR's names in
    # ur_robot_driver's alphabetical order made a +8 N push move the tool against it (a review, 2026-12-06)
    from coassist.robot.ros2_config import UR_JOINT_NAMES, Ros2Config

    for names in (sorted(UR_JOINT_NAMES), UR_JOINT_NAMES[::-1], tuple("ur5e_" + n for n in sorted(UR_JOINT_NAMES))):
        with pytest.raises(ValueError, match=r"Ros2Config\.joint_names must be the UR's joints from the base"):
            Ros2Config(joint_names=tuple(names))
    prefixed = tuple("left_" + n for n in UR_JOINT_NAMES)  # a description's prefix, in kinematic order
    assert Ros2Config(joint_names=prefixed).joint_names == prefixed
    custom = ("j1", "j2", "j3", "j4", "j5", "j6")  # names it cannot place: taken as base to tool, as documented
    assert Ros2Config(joint_names=custom).joint_names == custom
