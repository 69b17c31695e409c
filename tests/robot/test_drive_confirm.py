"""``coassist drive`` on a real arm asks "Move the robot?" of the person at it: without ``--yes`` and with no
terminal to ask at (stdin closed or redirected), the arm does not move and the reason is one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from coassist.cli import app


def _check_one_line(stdout: str, stderr_lines: list[str]) -> None:
    assert "Move the robot?" not in stdout  # no prompt left without its answer
    assert stdout.rstrip().endswith("within reach.")  # the limits in force were shown
    assert len(stderr_lines) == 1 and stderr_lines[0].startswith("error: the robot was not moved: "), stderr_lines
    assert "stdin is not a terminal" in stderr_lines[0] and "--yes" in stderr_lines[0]


def test_no_terminal_no_yes_is_one_line_and_no_motion(tmp_path, monkeypatch):
    """bdc84ed printed "Move the robot? [y/N]: error:" and an empty message (click's Abort as the error)."""
    from coassist.robot import drive as drive_module

    moved = []

    def fake_drive(config, *, confirm=None, **kwargs):  # the drive up to its question, then the motion
        if confirm is not None and not confirm("joint speed ≤ 90 °/s"):
            raise RuntimeError("not confirmed: the robot was not moved")
        moved.append(config.world)

    monkeypatch.setattr(drive_module, "drive", fake_drive)
    args = ["drive", "--world", "franka", "--host", "192.0.2.1", "--out", str(tmp_path / "t.parquet")]
    result = CliRunner().invoke(app, args, input="")
    assert result.exit_code == 1 and not moved
    _check_one_line(result.stdout, [line for line in result.stderr.splitlines() if line.strip()])
    # what stops a Franka: its user stop (it has no teach pendant), a UR's pendant
    assert "Keep the Franka's user stop button within reach." in result.stdout
    args[2] = "ur"
    result = CliRunner().invoke(app, args, input="")
    assert "Keep the teach pendant's emergency stop within reach." in result.stdout and not moved


@pytest.mark.realtime  # franky-sim runs the arm's loop in threads: run alone (./dev test), as the Franka tests
def test_the_same_against_franky_sim(tmp_path):
    """The issue's case end to end: franky-sim on loopback, stdin closed."""
    pytest.importorskip("franky", reason="the Franka world needs franky: pip install 'coassist[franka]'")
    pytest.importorskip("franky_sim", reason="the test needs franky-sim: pip install 'coassist[franka]'")
    pytest.importorskip("pinocchio", reason="the Panda kinematics need the robot extra: pip install 'coassist[robot]'")
    from .test_franka_world import SimServer

    server = SimServer()
    try:
        out = tmp_path / "t.parquet"
        cmd = [sys.executable, "-m", "coassist.cli", "drive", "--world", "franka", "--robot", "fr3"]
        run = subprocess.run(
            [*cmd, "--host", server.host, "--out", str(out), "--no-plot"],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=120,
            cwd=Path(__file__).resolve().parents[2],
        )
    finally:
        server.close()
    assert run.returncode == 1 and not out.exists()
    _check_one_line(run.stdout, [line for line in run.stderr.splitlines() if line.strip()])
