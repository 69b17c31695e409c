"""The page, read-only, on a coassist drive run of the MuJoCo UR5."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

pytest.importorskip("starlette", reason="coassist play needs the web extra (pip install 'coassist[web]')")
websockets = pytest.importorskip("websockets", reason="the websocket client needs the web extra")
pytest.importorskip("mujoco", reason="the MuJoCo UR5 needs the robot extra")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra")

from coassist.data import read_dataset  # noqa: E402
from coassist.play.monitor import DriveMonitor  # noqa: E402
from coassist.play.server import PlayServer  # noqa: E402
from coassist.play.session import PlayConfig  # noqa: E402
from coassist.robot.drive import DriveConfig  # noqa: E402


def test_a_watcher_sees_the_drive_run_live_and_cannot_steer_it(tmp_path):
    drive = DriveConfig(world="mujoco", controller="manual", task="linear", time_limit=2.0, seed=1)
    monitor = DriveMonitor(drive, PlayConfig(user="lab", out=tmp_path, controllers=("manual",), tasks=("linear",)))

    async def watch(port: int) -> tuple[dict, list[dict], dict, int]:
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            init = json.loads(await ws.recv())
            assert monitor.start()
            frames, dropped = [], 0
            while True:
                m = json.loads(await ws.recv())
                if m["type"] == "frame":
                    frames.append(m)
                    dropped = m["dropped"]
                    if len(frames) % 20 == 0:  # a watcher's hand and start are dropped
                        await ws.send(
                            json.dumps({"type": "pointer", "x": m["x"], "y": m["y"] + 0.05, "down": True, "seq": 1})
                        )
                        await ws.send(json.dumps({"type": "start", "controller": "manual"}))
                elif m["type"] == "result":
                    return init, frames, m, dropped
                elif m["type"] == "status" and m["level"]:
                    raise AssertionError(m["text"])

    with PlayServer(monitor, port=0) as server:
        init, frames, result, dropped = asyncio.run(watch(server.port))
    assert init["mode"] == "monitor" and init["role"] == "watcher"
    assert result["result"]["ended"] == "time_limit" and result["result"]["controller"] == "manual"
    trial = read_dataset(tmp_path / "lab").trials[0]
    assert trial.meta.origin == "mujoco" and trial.joints is not None and trial.joints.shape[1] == 6
    # the frames are the drive's own rows: frame k shows tick k − 1's measured pose and hand wrench
    assert len(frames) > 0.8 * trial.n_samples
    for f in frames[:: max(1, len(frames) // 25)]:
        k = f["k"] - 1
        assert (f["x"], f["y"]) == (trial.pose[k, 0], trial.pose[k, 1])
        assert f["fh"] == [trial.wrench[k, 0], trial.wrench[k, 1]]
    assert dropped >= 2
    assert np.abs(trial.wrench).max() > 0.5  # the simulated operator pushed; nobody on the page did


def test_stopping_the_server_mid_drive_stops_the_arm_and_keeps_the_ticks(tmp_path):
    # a review (2026-12-06): Ctrl+C (the server's stop, an abort) left the drive running 10 s, then the process
    # exited with it mid-run and nothing written
    import time

    drive = DriveConfig(world="mujoco", controller="manual", task="linear", time_limit=20.0, seed=1)
    monitor = DriveMonitor(drive, PlayConfig(user="lab", out=tmp_path, controllers=("manual",), tasks=("linear",)))
    server = PlayServer(monitor, port=0)
    with server:
        assert monitor.start()
        deadline = time.monotonic() + 30.0
        while (monitor.frame is None or monitor.frame["k"] < 100) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert monitor.frame is not None and monitor.frame["k"] >= 100, "the drive never reached tick 100"
        t = time.monotonic()
        server.stop()
        took = time.monotonic() - t
    assert not monitor.running and took < 5.0  # at once, not after the 10 s the server waits
    trial = read_dataset(tmp_path / "lab").trials[0]
    assert trial.meta.extra["ended"] == "interrupted" and 100 <= trial.n_samples < 20.0 / drive.dt / 2
