"""``--foxglove [PORT]`` on the commands that run the control loop (drive, play, collect, study run):
its port checked in one line before anything moves, the missing extra named, and every command's
trials handed to the live view, tick values equal to what the command wrote."""

from __future__ import annotations

import socket
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

import coassist.runtime.foxglove as foxglove_module
from coassist.cli import app
from coassist.data import read_dataset, read_trial
from coassist.runtime.foxglove import LiveServerError
from coassist.runtime.live import LiveFeed

from .test_live import Recorder

RUNNER = CliRunner()


def _lines(result) -> list[str]:
    return [line for line in result.output.splitlines() if line.strip()]


@pytest.fixture
def recorded(monkeypatch):
    """``open_foxglove`` replaced by a feed into a Recorder (no server): what each command hands over."""
    seen = SimpleNamespace(ports=[], sink=Recorder(), feed=None)

    def fake_open(port: int, **kw):
        seen.ports.append(port)
        seen.feed = LiveFeed(seen.sink, rate_hz=100.0)
        return seen.feed, SimpleNamespace(url=f"ws://127.0.0.1:{port}")

    monkeypatch.setattr(foxglove_module, "open_foxglove", fake_open)
    return seen


def _check_snapshots(snaps, trial) -> None:
    """Every snapshot is its tick's row of the trial written; the last tick is among them."""
    assert snaps and snaps[-1].k == trial.n_samples - 1
    for s in snaps:
        k = s.k
        np.testing.assert_array_equal(s.pose[:2], trial.pose[k, :2])
        np.testing.assert_array_equal(s.wrench[:2], trial.wrench[k, :2])
        np.testing.assert_array_equal(s.reference[:2], trial.reference[k, :2])
        assert s.fault == trial.fault[k]
        if trial.joints is not None:
            np.testing.assert_array_equal(s.joints, trial.joints[k])
            np.testing.assert_array_equal(s.joint_command, trial.joint_velocity[k])


@pytest.mark.parametrize("port", ["70000", "-1"])
def test_a_port_out_of_range_is_one_line(tmp_path, port):
    result = RUNNER.invoke(app, ["drive", "--foxglove", port, "--out", str(tmp_path / "t.parquet")])
    assert result.exit_code == 2
    assert _lines(result) == [f"error: --foxglove must be a port in 1 … 65535 (0: any free one), got {int(port)}"]


def test_a_port_in_use_is_one_line_before_the_arm_moves(tmp_path):
    out = tmp_path / "t.parquet"
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = RUNNER.invoke(app, ["drive", "--foxglove", str(port), "--time-limit", "0.2", "--out", str(out)])
    assert result.exit_code == 2
    assert _lines(result) == [
        f"error: --foxglove {port}: 127.0.0.1:{port} is in use (another program listens on it): pick another port"
    ]
    assert not out.exists()  # checked before the run


def test_the_pages_own_port_is_refused(tmp_path):
    pytest.importorskip("starlette", reason="coassist play needs the web extra")
    result = RUNNER.invoke(app, ["play", "--out", str(tmp_path), "--port", "9100", "--foxglove", "9100", "--no-open"])
    assert result.exit_code == 2
    assert _lines(result) == [
        "error: --foxglove 9100: the page listens on it (--port); give the live view another, e.g. --foxglove 9101"
    ]


def test_without_the_viz_extra_one_line_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "foxglove", None)  # import foxglove raises ImportError
    result = RUNNER.invoke(app, ["drive", "--foxglove", "--out", str(tmp_path / "t.parquet")])
    assert result.exit_code == 2
    assert _lines(result) == [
        "error: --foxglove: the live view needs the viz extra (foxglove missing): pip install 'coassist[viz]'"
    ]


@pytest.mark.parametrize(
    ("args", "port"),
    [
        (["drive", "--foxglove"], 8765),  # bare, last
        (["drive", "--foxglove", "--yes"], 8765),  # bare, another option after it
        (["drive", "--foxglove", "9000", "--yes"], 9000),
        (["drive", "--foxglove=9001"], 9001),
        (["collect", "--out", "x", "--foxglove"], 8765),
        (["play", "--foxglove", "--no-open"], 8766),  # the page has 8765
    ],
)
def test_a_bare_foxglove_takes_the_commands_default_port(monkeypatch, tmp_path, args, port):
    if args[0] == "play":
        pytest.importorskip("starlette", reason="coassist play needs the web extra")
    monkeypatch.chdir(tmp_path)
    asked = []

    def refuse(p, **kw):
        asked.append(p)
        raise LiveServerError("stopped here by the test")

    monkeypatch.setattr(foxglove_module, "open_foxglove", refuse)
    result = RUNNER.invoke(app, args)
    assert asked == [port] and result.exit_code == 2, result.output
    assert _lines(result) == [f"error: --foxglove {port}: stopped here by the test"]


def test_drive_shows_its_run_with_the_arms_joints(tmp_path, recorded):
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    from coassist.robot.ros2_world import UR_JOINT_NAMES

    out = tmp_path / "t.parquet"
    result = RUNNER.invoke(
        app, ["drive", "--time-limit", "0.6", "--foxglove", "0", "--out", str(out), "--no-plot", "--intent", "oracle"]
    )
    assert result.exit_code == 0, result.output
    assert "live view: open ws://127.0.0.1:0 in Foxglove" in result.output
    trial = read_trial(out)
    snaps = recorded.sink.snapshots
    _check_snapshots(snaps, trial)
    assert {s.trial.number for s in snaps} == {0} and snaps[0].trial.joint_names == UR_JOINT_NAMES
    assert recorded.sink.closed  # the command stopped the view when done


def test_collect_shows_the_first_trial_still_to_run_and_writes_the_same_dataset(tmp_path, recorded):
    args = ["collect", "--tasks", "linear", "--trials", "3", "--workers", "1", "--seed", "4"]
    plain = RUNNER.invoke(app, [*args, "--out", str(tmp_path / "plain")])
    assert plain.exit_code == 0, plain.output
    watched = RUNNER.invoke(app, [*args, "--out", str(tmp_path / "live"), "--foxglove", "0"])
    assert watched.exit_code == 0, watched.output
    assert "live: trial 0 (task linear, user 0, seed 4) runs first, watched" in watched.output
    a, b = read_dataset(tmp_path / "plain").trials, read_dataset(tmp_path / "live").trials
    for x, y in zip(a, b, strict=True):  # the watched trial runs per trial: bit for bit the lockstep one
        for name in ("pose", "velocity", "wrench", "effort_r", "prediction", "fault"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name))
    snaps = recorded.sink.snapshots
    assert {s.trial.number for s in snaps} == {0}  # one trial shown
    _check_snapshots(snaps, b[0])


def test_study_run_shows_every_trial_of_the_page_world(tmp_path, recorded):
    from ..study.conftest import comparison_plan

    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    folder = tmp_path / "study"
    assert RUNNER.invoke(app, ["study", "init", str(plan), "--out", str(folder)]).exit_code == 0
    result = RUNNER.invoke(app, ["study", "run", "--foxglove", str(folder), "--simulate", "-p", "S01"])
    assert result.exit_code == 0, result.output
    assert recorded.ports == [8766]  # bare: the page's 8765 is taken (even when it is not served)
    snaps = recorded.sink.snapshots
    by_trial: dict[int, list] = {}
    for s in snaps:
        by_trial.setdefault(s.trial.number, []).append(s)
    written = {}
    for condition in ("assistive", "impedance", "manual"):
        (trial,) = read_dataset(folder / "participants" / "S01" / condition).trials
        written[trial.meta.extra["trial_index"]] = trial
    assert len(by_trial) == len(written) == 3  # every trial shown, each its own LiveTrial
    # the trials in the order they ran: the live view's numbers follow the study's steps
    for number, step in zip(sorted(by_trial), sorted(written), strict=True):
        _check_snapshots(by_trial[number], written[step])


def test_the_page_watching_a_drive_shows_it_too(tmp_path):
    pytest.importorskip("starlette", reason="coassist play needs the web extra")
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    from coassist.play.monitor import DriveMonitor
    from coassist.play.session import PlayConfig
    from coassist.robot.drive import DriveConfig

    sink = Recorder()
    with LiveFeed(sink, rate_hz=100.0) as feed:
        monitor = DriveMonitor(
            DriveConfig(world="mujoco", controller="manual", task="linear", time_limit=0.8, seed=1),
            PlayConfig(user="lab", out=tmp_path, controllers=("manual",), tasks=("linear",)),
            live=feed,
        )
        assert monitor.start()
        end = time.monotonic() + 60
        while not monitor.results and time.monotonic() < end:
            time.sleep(0.05)
        assert feed.flush(10)
    trial = read_dataset(tmp_path / "lab").trials[0]
    _check_snapshots(sink.snapshots, trial)
