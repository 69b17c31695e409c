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
