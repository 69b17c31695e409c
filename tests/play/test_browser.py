"""The page in a real headless Chromium (Debian's, driven by Playwright's Python API).

A scripted mouse drag is the hand: it grabs the tool, follows the plan and holds in the
target. Checked: the page loads and connects, the drag moves the tool, the intent model's
prediction is drawn (a screenshot holds the path's and the prediction's colours), the
page draws at least 30 frames a second, and the trial is saved and listed on the page.
Skips, saying why, only where no Chromium (or no Playwright) can be had.
"""

from __future__ import annotations

import math
import time
from io import BytesIO
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("starlette", reason="coassist play needs the web extra (pip install 'coassist[web]')")
sync_api = pytest.importorskip("playwright.sync_api", reason="the browser test needs Playwright (the dev extra)")

from ..chromium import CHROMIUM, CHROMIUM_ARGS, needs_chromium  # noqa: E402

pytestmark = needs_chromium

PATH_RGB = (31, 119, 180)  # the page's colours (play.js COLOR)
PREDICTION_RGB = (255, 127, 14)


def tiny_model(folder: Path) -> Path:
    """A small LSTM predictor with the controller's horizon (50), trained for seconds on smooth synthetic motions."""
    from coassist.data import Trial, TrialMeta
    from coassist.intent import (
        LabeledTrial,
        Preset,
        TrainConfig,
        WindowConfig,
        train_model,
    )
    from coassist.intent.training import write_model

    rng = np.random.default_rng(0)
    trials = []
    for i in range(4):
        t = np.arange(300) * 0.008
        ref = np.stack([-0.1 + 0.1 * t, np.full_like(t, -0.615)], axis=1)
        pose = ref + 0.02 * np.sin(rng.uniform(1, 3) * t + rng.uniform(0, 6))[:, None]
        vel = np.gradient(pose, 0.008, axis=0)
        meta = TrialMeta(
            user="t", task="linear", object="none", controller="manual", model_id=None, seed=i, origin="sim", dt=0.008
        )
        trials.append(
            LabeledTrial(
                f"T/{i}", "T", Trial(meta=meta, time=t, pose=pose, velocity=vel, wrench=100 * vel, reference=ref)
            )
        )
    preset = Preset(
        "tiny50",
        WindowConfig(history=20, decimation=2, horizon=50, input_frame="relative", target="residual"),
        lstm_layers=1,
        hidden=8,
        fc=(8,),
        train=TrainConfig(epochs=1, batch_size=64, lr=3e-3, threads=1, train_stride=4, eval_stride=8),
    )
    model = train_model(trials, preset, preset.train)
    write_model(model, folder)
    return folder


def launch(playwright, profile: Path):
    return playwright.chromium.launch_persistent_context(
        str(profile),
        executable_path=str(CHROMIUM),
        headless=True,
        args=CHROMIUM_ARGS,
        viewport={"width": 1300, "height": 760},
    )


def colour_pixels(png: bytes, rgb: tuple[int, int, int]) -> int:
    from PIL import Image

    img = np.asarray(Image.open(BytesIO(png)).convert("RGB")).astype(int)
    return int(np.all(np.abs(img - np.array(rgb)) <= 2, axis=-1).sum())


def test_a_scripted_drag_in_chromium_plays_a_trial(tmp_path):
    pytest.importorskip("torch", reason="the drawn prediction comes from a small intent model (the learn extra)")
    from coassist.play.server import PlayServer
    from coassist.play.session import PlayConfig, PlaySession

    model = tiny_model(tmp_path / "M0")
    config = PlayConfig(
        user="carol",
        out=tmp_path / "runs",
        controllers=("cooperative", "manual"),
        intent=str(model),
        motion_time=2.0,
        dwell=1.0,
    )
    with PlayServer(PlaySession(config), port=0) as server, sync_api.sync_playwright() as pw:
        context = launch(pw, tmp_path / "profile")
        try:
            page = context.pages[0] if context.pages else context.new_page()
            page.goto(server.url)
            page.wait_for_function("window.coassist && window.coassist.ready", timeout=15000)
            assert page.title().startswith("coassist play")
            assert page.locator("#controller option").count() == 2
            page.select_option("#controller", "cooperative")
            page.click("#start")
            page.wait_for_function("window.coassist.frame !== null", timeout=10000)
            start = page.evaluate("window.coassist.scene.start")
            target = page.evaluate("window.coassist.scene.target")
            x, y = page.evaluate(f"window.coassist.toPixels({start[0]}, {start[1]})")
            page.mouse.move(x, y)
            page.mouse.down()
            draws0, t0 = page.evaluate("window.coassist.draws"), time.perf_counter()
            xs, shot, prediction_pixels, shots = [], None, 0, 0
            while True:
                f = page.evaluate("window.coassist.frame")
                if f is None:  # the trial ended: the result replaced the frame
                    break
                xs.append(f["x"])
                aim = target if f["t"] > 2.9 else f["ref"]
                x, y = page.evaluate(f"window.coassist.toPixels({aim[0]}, {aim[1]})")
                page.mouse.move(x, y)
                if prediction_pixels <= 20 and shots < 5 and f["t"] > 1.6 and f["predicted"]:
                    # a prediction long enough on screen to count its pixels: on a loaded machine
                    # the drag can pause, and the tool's prediction 0.4 s ahead then shrinks to a dot.
                    # The canvas may be redrawn from a later frame between reading this one and the
                    # screenshot (on 2026-12-04, under the suite's load, one shot had no prediction
                    # drawn), so up to five shots are taken until one shows it.
                    tip = page.evaluate(f"window.coassist.toPixels({f['prediction'][-1][0]}, {f['prediction'][-1][1]})")
                    tool = page.evaluate(f"window.coassist.toPixels({f['x']}, {f['y']})")
                    if math.dist(tip, tool) >= 30:
                        shot = page.locator("canvas").screenshot()
                        shots += 1
                        prediction_pixels = colour_pixels(shot, PREDICTION_RGB)
                if time.perf_counter() - t0 > 20:
                    raise AssertionError("the trial did not end within 20 s")
                time.sleep(0.02)
            fps = (page.evaluate("window.coassist.draws") - draws0) / (time.perf_counter() - t0)
            page.mouse.up()
            page.wait_for_function("window.coassist.results.length === 1", timeout=5000)
            result = page.evaluate("window.coassist.results[0]")
            rows = page.locator("#results tbody tr").count()
            latencies = page.evaluate("window.coassist.latencies")
            untimed, last_drawn = page.evaluate("[window.coassist.untimed(), window.coassist.lastDrawSeq]")
        finally:
            context.close()
    assert max(xs) - start[0] > 0.4  # the drag carried the tool most of the 0.5 m path
    assert shot is not None, "the model's prediction never arrived in a frame"
    assert colour_pixels(shot, PATH_RGB) > 200
    assert prediction_pixels > 20, f"none of {shots} screenshots showed the prediction"
    assert fps >= 30.0, f"the page drew {fps:.1f} frames/s"
    # every pointer move the drag made was timed by the first frame drawn that answered it: those still untimed came
    # after the last frame drawn (the trial's end). How many those are depends on this machine's load (one or two
    # quiet; three in a CI run of 2026-12-05, 72 of 75 timed), so the property is checked, not a count
    assert len(latencies) >= 10 and all(s > last_drawn for s in untimed), (len(latencies), untimed, last_drawn)
    assert result["ended"] == "target" and result["file"] == "trial_00000.parquet" and rows == 1
    from coassist.data import read_dataset

    trial = read_dataset(tmp_path / "runs" / "carol").trials[0]
    assert trial.meta.model_id.startswith("M0@") and trial.n_samples == result["n_ticks"]
    assert np.isfinite(trial.prediction[-1]).all()  # the model's prediction was in use and logged


GAMEPAD = """
window.__pad = {pressed: false, axes: [0, 0]};
navigator.getGamepads = () => [{id: "fake", connected: true, axes: window.__pad.axes,
    buttons: [{pressed: window.__pad.pressed, value: window.__pad.pressed ? 1 : 0}]}];
"""


def test_a_gamepad_is_a_hand_too(tmp_path):
    from coassist.play.server import PlayServer
    from coassist.play.session import PlayConfig, PlaySession

    # asked for a way round (--ask-way left): the page says it before the trial
    config = PlayConfig(user="dave", out=tmp_path / "runs", controllers=("manual",), motion_time=2.0, dwell=1.0, way=1)
    session = PlaySession(config)
    with PlayServer(session, port=0) as server, sync_api.sync_playwright() as pw:
        context = launch(pw, tmp_path / "profile")
        try:
            context.add_init_script(GAMEPAD)  # the Gamepad API, as a pad with A held and the stick pushed right
            page = context.new_page()
            page.goto(server.url)
            page.wait_for_function("window.coassist && window.coassist.ready", timeout=15000)
            page.wait_for_function("document.getElementById('hud-controller').textContent.length > 0", timeout=5000)
            hud = page.text_content("#hud-controller")
            page.click("#start")
            page.wait_for_function("window.coassist.frame !== null", timeout=10000)
            x0 = page.evaluate("window.coassist.frame.x")
            page.evaluate("window.__pad.pressed = true; window.__pad.axes = [1, 0]")
            time.sleep(1.0)
            held = page.evaluate("window.coassist.frame")
            page.evaluate("window.__pad.pressed = false; window.__pad.axes = [0, 0]")
            time.sleep(0.3)
            released = page.evaluate("window.coassist.frame")
            page.click("#abort")
        finally:
            context.close()
        session.wait(5.0)
    # full stick = the hand 8 cm ahead of the tool: K_s · 0.08 = 32 N minus damping, pushing +x. The bound
    # leaves room for a busy machine (two CPU hogs beside the suite: 14.2 N, the frame read late in the
    # push); a pad that does not push reads 0
    assert hud.startswith("next: linear path") and "go round the box on the left" in hud, hud
    assert held["held"] and held["fh"][0] > 10.0 and abs(held["fh"][1]) < 2.0
    assert held["x"] - x0 > 0.05
    assert not released["held"] and released["fh"] == [0.0, 0.0]
