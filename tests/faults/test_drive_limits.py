"""Options that would switch a protection off are refused before anything moves (issue 37).

A protective limit beyond the arm's own hard limit limits nothing (``--tool-speed 1e9``), a
contact force beyond the sensor's range can never trip, a link that may stay silent for
``1e9`` s is never lost, a TCP metres from the flange is a unit typo: each is one line naming
the option, exit code 2, before a robot is contacted. The ROS 2 node's topics are checked
the same way: an input on the node's own command or monitor topic, or two inputs on one
topic, and ``--joint-names`` that are not the arm's joint count.
"""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.robot.drive import DriveConfig
from coassist.runtime.safety_limits import SafetyLimits

runner = CliRunner()


def _refused(args: list[str], option: str) -> str:
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    errors = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and option in errors[0], res.output
    assert "Traceback" not in res.output
    return errors[0]


@pytest.mark.parametrize(
    "args, option",
    [
        (["--tool-speed", "1e9"], "--tool-speed"),
        (["--tool-speed", "1.5"], "--tool-speed"),  # beyond the UR5's 1 m/s
        (["--contact-force", "1e9"], "--contact-force"),
    ],
)
def test_drive_refuses_limits_that_switch_a_protection_off(args, option, tmp_path):
    line = _refused(["drive", "--time-limit", "0.2", "--no-plot", "--out", str(tmp_path / "t.parquet"), *args], option)
    assert not (tmp_path / "t.parquet").exists()
    if option == "--tool-speed":
        assert "at most 1 m/s, the ur5's own tool speed limit" in line


def test_the_arm_sets_the_tool_speed_ceiling():
    DriveConfig(world="franka", robot="fr3", limits=SafetyLimits(tool_speed=1.7))  # Franka's own 1.7 m/s
    with pytest.raises(ValueError, match=r"SafetyLimits.tool_speed must be at most 1.7 m/s, the fr3's own"):
        DriveConfig(world="franka", robot="fr3", limits=SafetyLimits(tool_speed=2.0))
    with pytest.raises(ValueError, match=r"SafetyLimits.joint_velocity must be at most the ur5's own joint speeds"):
        DriveConfig(limits=SafetyLimits(joint_velocity=10.0))


ROS2 = ["ros2", "--yes", "--no-plot", "--connect-timeout", "0.3"]


@pytest.mark.parametrize(
    "args, option, words",
    [
        (["--tool-speed", "1e9"], "--tool-speed", "own tool speed limit"),
        (["--stale-after", "1e9"], "--stale-after", "at most 0.5 s"),
        (["--tcp-offset", "0,0,150,0,0,0"], "--tcp-offset", "within 0.5 m of the flange"),
        (["--joint-names", "a,b,c"], "--joint-names", "6 names, one per joint of the UR5 (got 3)"),
        (["--wrench-topic", "/forward_velocity_controller/commands"], "--wrench-topic", "--command-topic"),
        (["--joint-state-topic", "/force_torque_sensor_broadcaster/wrench"], "--joint-state-topic", "--wrench-topic"),
        (["--wrench-topic", "/coassist/tool_pose"], "--wrench-topic", "tool_pose_topic"),
        (["--wrench-topic", "~/hand_force"], "--wrench-topic", "/coassist/hand_force"),
    ],
)
def test_ros2_refuses_options_before_starting(args, option, words, tmp_path):
    pytest.importorskip("rclpy", reason="the ros2 extra (ros-rclpy and the message packages) is not installed")
    line = _refused([*ROS2, "--out", str(tmp_path / "t.parquet"), *args], option)
    assert words in line


@pytest.mark.parametrize("command", ["drive", "ros2"])
def test_a_recorded_run_is_not_replaced_without_overwrite(command, tmp_path):
    if command == "ros2":
        pytest.importorskip("rclpy", reason="the ros2 extra (ros-rclpy and the message packages) is not installed")
    out = tmp_path / "t.parquet"
    out.write_bytes(b"a recorded run")
    args = ROS2[1:] if command == "ros2" else ["--time-limit", "0.2", "--no-plot"]
    _refused([command, *args, "--out", str(out)], "--overwrite")
    assert out.read_bytes() == b"a recorded run"
