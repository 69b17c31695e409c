"""The protocol without a browser: a websocket client plays whole trials against the real server.

The server runs on uvicorn on 127.0.0.1 with the loop paced at 125 Hz (real time): a
trial with a 1 s plan (after the thesis' 0.9 s start delay) and a 0.5 s dwell takes about 2.5 s.
"""

from __future__ import annotations

import asyncio
import json
import time

import numpy as np
import pytest
from scipy.linalg import expm

pytest.importorskip("starlette", reason="coassist play needs the web extra (pip install 'coassist[web]')")
websockets = pytest.importorskip("websockets", reason="the websocket client needs the web extra")

from coassist.control.presets import get_preset  # noqa: E402
from coassist.data import read_dataset  # noqa: E402
from coassist.play.server import PlayServer  # noqa: E402
from coassist.play.session import PlayConfig, PlaySession  # noqa: E402
from coassist.scenario import person_model  # noqa: E402


def short_config(tmp_path, **kw) -> PlayConfig:
    base = {
        "user": "alice",
        "out": tmp_path,
        "controllers": ("cooperative", "manual"),
        "motion_time": 1.0,
        "dwell": 0.5,
        "grace": 0.5,
    }
    base.update(kw)
    return PlayConfig(**base)


async def play_trial(port: int, controller: str, *, junk: bool = False, token: str | None = None) -> dict:
    """Follow the moving reference with the hand, then hold at the target; returns what the page would see."""
    query = f"?token={token}" if token else ""
    async with websockets.connect(f"ws://127.0.0.1:{port}/ws{query}") as ws:
        init = json.loads(await ws.recv())
        assert init["type"] == "init" and init["role"] == "hand"
        target, t_end = init["scene"]["target"], init["scene"]["motion_end"]
        await ws.send(json.dumps({"type": "start", "controller": controller}))
        seq, frames, dropped = 0, [], 0
        while True:
            m = json.loads(await ws.recv())
            if m["type"] == "frame":
                frames.append(m)
                dropped = m["dropped"]
                seq += 1
                x, y = target if m["t"] > t_end else m["ref"]
                await ws.send(json.dumps({"type": "pointer", "x": x, "y": y, "down": True, "seq": seq}))
                if junk and seq % 25 == 0:  # hostile input mid-trial: dropped and counted, the loop goes on
                    for bad in (
                        "{",
                        '{"type": "pointer", "x": 1e999, "y": 0, "down": true, "seq": 1}',
                        '{"type": "save", "file": "../../escape.parquet"}',
                        "x" * 4000,
                    ):
                        await ws.send(bad)
            elif m["type"] == "result":
                return {"init": init, "frames": frames, "result": m, "dropped": dropped}
            elif m["type"] == "status" and m["level"]:
                raise AssertionError(m["text"])


def zoh(M: float, D: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation of x' = v, M v' = −D v + u (per axis), by the matrix exponential."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, -D / M, 1.0 / M], [0.0, 0.0, 0.0]])
    E = expm(A * dt)
    return E[:2, :2], E[:2, 2]


def test_a_websocket_client_plays_a_whole_trial_and_it_is_saved_as_a_dataset(tmp_path):
    # asked to go round on the right (--ask-way right): the page is told, the trial records it
    session = PlaySession(short_config(tmp_path, way=-1))
    with PlayServer(session, port=0) as server:
        t0 = time.perf_counter()
        seen = asyncio.run(play_trial(server.port, "cooperative", junk=True))
        wall = time.perf_counter() - t0
    r = seen["result"]["result"]
    assert r["ended"] == "target" and r["controller"] == "cooperative" and r["file"] == "trial_00000.parquet"
    # the file: a dataset coassist train reads, with one row per control period
    ds = read_dataset(tmp_path / "alice")
    assert (
        ds.id == "play-alice"
        and len(ds) == 1
        and sorted(p.name for p in (tmp_path / "alice").iterdir()) == ["manifest.json", "trial_00000.parquet"]
    )
    trial = ds.trials[0]
    dt = trial.meta.dt
    assert seen["init"]["scene"]["way"] == "right" and person_model.asked_way(trial) == -1
    assert trial.meta.user == "alice" and trial.meta.task == "linear" and trial.meta.controller == "cooperative"
    assert trial.n_samples == r["n_ticks"] == seen["frames"][-1]["k"] >= len(seen["frames"]) > 0.9 * trial.n_samples
    assert np.array_equal(trial.time, np.arange(trial.n_samples) * dt)
    # paced in real time: the trial's simulated time took as long on the wall clock
    assert wall >= trial.duration
    # the sensor reads last period's hand force; the plant is M a + D v = u_h + u_r exactly (eq. 3.5)
    assert np.array_equal(trial.wrench[1:], trial.effort_h[:-1])
    imp = get_preset("thesis-application-dm").impedance
    Ad, Bd = zoh(imp.M[0], imp.D[0], dt)
    for j in range(2):
        state = np.stack([trial.pose[:-1, j], trial.velocity[:-1, j]])
        u = trial.effort_h[:-1, j] + trial.effort_r[:-1, j]
        nxt = Ad @ state + np.outer(Bd, u)
        np.testing.assert_allclose(nxt[0], trial.pose[1:, j], atol=1e-12)
        np.testing.assert_allclose(nxt[1], trial.velocity[1:, j], atol=1e-12)
    # the hand pulled (the client's pointer), and the trial ended held in the target
    assert np.abs(trial.effort_h).max() > 1.0
    target = np.asarray(trial.meta.extra["target"])
    assert np.linalg.norm(trial.pose[-1] - target) < 0.025
    # the page's scores are eq. 5.9 and 5.11 of the saved file
    assert r["f_rms"] == pytest.approx(np.mean(np.hypot(trial.wrench[:, 0], trial.wrench[:, 1])), rel=1e-12)
    dist = np.linalg.norm(trial.pose - target, axis=1)
    k0 = int(np.flatnonzero(dist <= 0.025)[0])
    assert r["sigma"] == pytest.approx(dist[k0 : k0 + 375].mean(), rel=1e-12)
    assert seen["result"]["summary"]["cooperative"]["trials"] == 1
    # the hostile messages were dropped and counted, and nothing was written anywhere else
    assert seen["dropped"] >= 4
    assert not list(tmp_path.rglob("escape*"))
    # coassist train reads the folder as it is
    from coassist.intent import load_trials

    labeled = load_trials([tmp_path / "alice"])
    assert [lt.id for lt in labeled] == ["play-alice/trial_00000"]


def test_the_session_resumes_and_keeps_running_means_per_controller(tmp_path):
    with PlayServer(PlaySession(short_config(tmp_path)), port=0) as server:
        first = asyncio.run(play_trial(server.port, "manual"))
    assert first["result"]["result"]["file"] == "trial_00000.parquet"
    session = PlaySession(short_config(tmp_path))  # a new server on the same folder: trial 1 follows
    assert len(session.results) == 1 and session.next_task().kind == "curved"
    with PlayServer(session, port=0) as server:
        second = asyncio.run(play_trial(server.port, "manual"))
    res = second["result"]
    assert res["result"]["file"] == "trial_00001.parquet" and res["result"]["task"] == "curved"
    f = [first["result"]["result"]["f_rms"], res["result"]["f_rms"]]
    assert res["summary"]["manual"]["trials"] == 2 and res["summary"]["manual"]["f_rms"] == pytest.approx(np.mean(f))
    assert len(read_dataset(tmp_path / "alice")) == 2


def test_a_dropped_link_lets_go_at_once_and_aborts_the_trial_after_the_grace(tmp_path):
    session = PlaySession(short_config(tmp_path, motion_time=5.0))

    async def grab_and_vanish(port: int) -> None:
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            init = json.loads(await ws.recv())
            x, y = init["scene"]["start"]
            await ws.send(json.dumps({"type": "start", "controller": "manual"}))
            for seq in range(1, 40):  # pull 5 cm to the side: 20 N
                m = json.loads(await ws.recv())
                await ws.send(json.dumps({"type": "pointer", "x": x, "y": y + 0.05, "down": True, "seq": seq}))
            assert m["type"] == "frame" and m["held"] and abs(m["fh"][1]) > 5.0
        # closed without a word

    async def come_back(port: int) -> list[dict]:
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            return [json.loads(await asyncio.wait_for(ws.recv(), 5.0)) for _ in range(2)]

    with PlayServer(session, port=0) as server:
        asyncio.run(grab_and_vanish(server.port))
        time.sleep(0.1)
        assert session.running
        frame = session.frame
        assert frame["fh"] == (0.0, 0.0) and not frame["held"]  # let go, not frozen
        assert session.wait(3.0)  # aborted after the 0.5 s grace
        # the page that comes back is told its trial was aborted (it was told nothing: no page was there to hear it)
        init, told = asyncio.run(come_back(server.port))
        assert init["type"] == "init" and init["role"] == "hand" and not init["running"] and init["results"] == []
        assert told == {
            "type": "status",
            "level": "warn",
            "text": "the hand left for too long: trial aborted (nothing written)",
        }
        assert session.start_trial("manual") and session.notice is None  # the next trial's start clears it
        session.abort()
        assert session.wait(3.0)
    assert not (tmp_path / "alice" / "manifest.json").exists()


def test_tokens_and_origins_guard_the_websocket(tmp_path):
    session = PlaySession(short_config(tmp_path))
    with pytest.raises(ValueError, match="needs a token"):
        PlayServer(session, host="0.0.0.0", port=0)

    async def handshake(port: int, query: str = "", origin: str | None = None) -> str:
        try:
            async with websockets.connect(f"ws://127.0.0.1:{port}/ws{query}", origin=origin) as ws:
                return json.loads(await ws.recv())["type"]
        except (websockets.exceptions.InvalidStatus, websockets.exceptions.ConnectionClosed) as exc:
            return type(exc).__name__

    with PlayServer(session, port=0, token="s3cret") as server:
        assert asyncio.run(handshake(server.port)) != "init"
        assert asyncio.run(handshake(server.port, "?token=wrong")) != "init"
        assert asyncio.run(handshake(server.port, "?token=s3cret")) == "init"
        assert "token=s3cret" in server.url
        assert asyncio.run(handshake(server.port, "?token=s3cret", origin="http://evil.example")) != "init"
        assert asyncio.run(handshake(server.port, "?token=s3cret", origin=f"http://127.0.0.1:{server.port}")) == "init"


def test_a_flood_is_cut_at_the_rate_limit_and_the_link_survives(tmp_path):
    from coassist.play.server import MAX_RATE

    async def flood(port: int) -> dict:
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            init = json.loads(await ws.recv())
            x, y = init["scene"]["start"]
            msg = json.dumps({"type": "pointer", "x": x, "y": y, "down": False, "seq": 1})
            t0 = time.monotonic()
            for _ in range(MAX_RATE + 500):
                await ws.send(msg)
            assert time.monotonic() - t0 < 1.0, "the flood must fit in one second for this test"
            await asyncio.sleep(1.1)  # a new second: the link still answers
            await ws.send(json.dumps({"type": "ping", "seq": 7}))
            while (m := json.loads(await ws.recv()))["type"] != "pong":
                pass
            return m

    with PlayServer(PlaySession(short_config(tmp_path)), port=0) as server:
        pong = asyncio.run(flood(server.port))
        dropped = dict(server.hub.dropped)
    assert pong == {"type": "pong", "seq": 7}
    assert 0 < dropped.get("rate", 0) <= 500  # all that came past MAX_RATE within one second, no more


def test_a_link_gone_silent_without_closing_is_a_hand_that_left(tmp_path):
    """Wi-Fi lost or a laptop asleep: the page's socket stays open and says nothing. The hand let go after 0.25 s,
    but the link was only closed after uvicorn's default keepalive (20 s + 20 s): the trial ran to its end with
    nobody in it and was written as played, and the person's reloaded page was a watcher. The server pings each
    page (WS_PING_INTERVAL) and closes a link that does not answer (WS_PING_TIMEOUT): the trial is aborted after
    the grace, nothing written, and the next page is the hand again."""
    from coassist.play.server import WS_PING_INTERVAL, WS_PING_TIMEOUT

    assert WS_PING_INTERVAL + WS_PING_TIMEOUT <= 10.0  # the default lets a silent link go well before uvicorn's 40 s
    ping = (0.5, 1.0)  # shorter here, so the test waits less
    session = PlaySession(short_config(tmp_path, motion_time=5.0))
    silent = sum(ping) + session.config.grace + 1.5

    async def grab_and_go_silent(port: int) -> None:
        ws = await websockets.connect(f"ws://127.0.0.1:{port}/ws")
        init = json.loads(await ws.recv())
        x, y = init["scene"]["start"]
        await ws.send(json.dumps({"type": "start", "controller": "manual"}))
        for seq in range(1, 20):
            m = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "pointer", "x": x, "y": y + 0.05, "down": True, "seq": seq}))
        assert m["type"] == "frame" and m["held"]
        time.sleep(silent)  # the event loop blocked: the client neither reads, sends nor answers a ping
        assert not session.running  # aborted while the link was silent (a 22 s trial otherwise)

    async def next_page(port: int) -> str:
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            return json.loads(await ws.recv())["role"]

    with PlayServer(session, port=0, ping=ping) as server:
        asyncio.run(grab_and_go_silent(server.port))
        assert asyncio.run(next_page(server.port)) == "hand"
    assert not (tmp_path / "alice" / "manifest.json").exists()  # nothing written of the trial nobody was in


def test_a_pointer_message_older_than_the_last_is_dropped(tmp_path):
    """Messages overtaken or replayed: an older pointer (seq 5 after seq 100) reversed the hand's pull from +18 to
    −21 N, and one repeated kept the hand held past its stale-after. Dropped now, counted, the hand as the newest."""
    session = PlaySession(short_config(tmp_path, motion_time=5.0))

    async def pull_then_replay(port: int) -> list[dict]:
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
            init = json.loads(await ws.recv())
            x, y = init["scene"]["start"]
            await ws.send(json.dumps({"type": "start", "controller": "manual"}))
            frames = []
            for i in range(30):
                m = json.loads(await ws.recv())
                if m["type"] != "frame":
                    continue
                frames.append(m)
                seq, dy = (100 + i, 0.05) if i < 10 else (5, -0.05)  # then an old message, again and again
                await ws.send(json.dumps({"type": "pointer", "x": x, "y": y + dy, "down": True, "seq": seq}))
            await ws.send(json.dumps({"type": "abort"}))
            return frames

    with PlayServer(session, port=0) as server:
        frames = asyncio.run(pull_then_replay(server.port))
        dropped = dict(server.hub.dropped)
    assert dropped.get("pointer: stale seq", 0) >= 15
    late = frames[12:]
    # never the old message's pull (−y), never its seq: the newest pull, or let go once it is stale (0 N)
    assert late and all(f["seq"] >= 100 and f["fh"][1] >= 0.0 for f in late)


def test_when_the_hand_closes_its_tab_another_open_tab_becomes_the_hand_and_is_told(tmp_path):
    # a review (2026-12-06): the other tab stayed "watching (another page is the hand)", its start refused, until
    # it was reloaded
    session = PlaySession(short_config(tmp_path))

    async def two_tabs(port: int) -> tuple[str, str, dict]:
        url = f"ws://127.0.0.1:{port}/ws"
        a = await websockets.connect(url)
        first = json.loads(await a.recv())["role"]
        async with websockets.connect(url) as b:
            second = json.loads(await b.recv())["role"]
            await a.close()  # b is told it is the hand now
            promoted = json.loads(await asyncio.wait_for(b.recv(), 5.0))
            await b.send(json.dumps({"type": "start", "controller": "manual"}))
            while json.loads(await asyncio.wait_for(b.recv(), 5.0))["type"] != "frame":
                pass
            return first, second, promoted

    with PlayServer(session, port=0) as server:
        first, second, promoted = asyncio.run(two_tabs(server.port))
        assert session.running  # b's start was taken
        session.abort()
        assert session.wait(5.0)
    assert (first, second) == ("hand", "watcher")
    assert promoted["type"] == "init" and promoted["role"] == "hand"
