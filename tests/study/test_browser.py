"""The comparison study in a real headless Chromium (Debian's, driven by Playwright's Python API).

Four simulated participants × three conditions: for each, the page is opened, Start is pressed
for the step shown, the mouse moves along the simulated operator's intended path (the hand the
page's spring-damper pulls the tool with), the questionnaires are answered with the page's own
sliders and radio buttons, and the rests are ended with its Continue button. Then the report is
written. Every websocket frame the browser receives is kept: none names a controller or a
condition. Skips, saying why, only where no Chromium (or no Playwright) can be had.
"""

from __future__ import annotations

import json
import threading
import time

import pytest
from scipy import stats

pytest.importorskip("starlette", reason="the study's page needs the web extra (pip install 'coassist[web]')")
sync_api = pytest.importorskip("playwright.sync_api", reason="the browser test needs Playwright (the dev extra)")

from coassist.study.folder import init_study  # noqa: E402
from coassist.study.report import write_report  # noqa: E402
from coassist.study.runner import ParticipantRun  # noqa: E402

from ..chromium import CHROMIUM, CHROMIUM_ARGS, needs_chromium  # noqa: E402
from .conftest import calibrated_plan, comparison_plan  # noqa: E402
from .pagedriver import SECRETS, OperatorPath  # noqa: E402

pytestmark = needs_chromium


def _shown(run: ParticipantRun, timeout: float = 60.0) -> None:
    """Wait until ``run`` has shown its first step to the page (published before any page connected)."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        session = run.session
        if session is not None and session.setup is not None and "scene" in (session.view or {}):
            return
        time.sleep(0.02)
    raise AssertionError(f"the run showed no step in {timeout:g} s")


def _late_study_js(page, delay: float) -> None:
    """Serve the page's second script ``delay`` s late: the websocket's first messages then arrive while the
    parser waits for it (a loaded server or network). Before the page connected only once every script had
    run, the study's view in that first message was lost and the page waited for a step that never came."""

    def handler(route) -> None:
        time.sleep(delay)
        route.continue_()

    page.route("**/static/study.js", handler)


def _check(radio, tries: int = 3) -> None:
    """Check ``radio`` as a participant would, clicking again where a click did not take.

    Playwright's ``check`` clicks and then raises "Clicking the checkbox did not change its state" where the
    checkbox is not checked after the click; in headless Chromium on a loaded CI machine that happens on rare
    occasions to radios no script touches (microsoft/playwright#13470, open; CI's four-participant study once,
    not reproduced alone or beside three busy loops). A person whose click did not take clicks again; a radio
    that never checks still fails here, and the answers are read back from the page before they are sent.
    """
    for attempt in range(tries):
        try:
            radio.check()
            return
        except sync_api.Error as err:
            if "did not change its state" not in str(err) or attempt == tries - 1:
                raise


def _participant(page, url: str, path: OperatorPath, received: list[str], timeout: float = 120.0) -> dict:
    """Take part in the study on ``page`` until it says it is done (within ``timeout`` s); returns what was
    entered."""
    page.on("websocket", lambda ws: ws.on("framereceived", lambda payload: received.append(str(payload))))
    page.goto(url)
    # The page is ready within a second or two even on a loaded machine (it waits for nothing the run computes:
    # the view of the step shown comes with the first message); 60 s leaves room for a starved worker.
    page.wait_for_function("window.coassist && window.coassist.ready && window.coassist.study", timeout=60000)
    entered: dict = {"answers": {}, "starts": []}
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        view = page.evaluate("window.coassist.study")
        if view["kind"] == "done":
            return entered
        if view["kind"] == "trial" and not page.evaluate("window.coassist.running") and page.is_enabled("#start"):
            k = view["step"]
            entered["starts"].append(view["label"])
            page.click("#start")
            page.wait_for_function("window.coassist.frame !== null", timeout=10000)
            x, y = page.evaluate(f"window.coassist.toPixels(...{json.dumps(path.at(k, 0.0))})")
            page.mouse.move(x, y)
            page.mouse.down()
            while (f := page.evaluate("window.coassist.frame")) is not None:  # the result replaces the frame
                x, y = page.evaluate(f"window.coassist.toPixels(...{json.dumps(path.at(k, f['t'] + 0.03))})")
                page.mouse.move(x, y)
                time.sleep(0.015)
            page.mouse.up()
        elif view["kind"] == "questionnaire" and page.locator("#study-submit").count():
            values = path.answers(view["step"], view["form"]["items"])
            for item, v in zip(view["form"]["items"], values):
                if item["scale"] == "tlx":
                    page.locator(f"input[name='{item['key']}']").fill(str(v))
                else:
                    _check(page.locator(f"input[name='{item['key']}'][value='{v}']"))
            entered["answers"][view["step"]] = values
            # the same questionnaire shown again (a reconnect's init) keeps what was entered
            page.evaluate("window.coassist.extend({...window.coassist.study, type: 'step'})")
            for item, v in zip(view["form"]["items"], values):
                sel = f"input[name='{item['key']}']" + ("" if item["scale"] == "tlx" else ":checked")
                assert float(page.locator(sel).input_value()) == float(v), item["key"]
            page.click("#study-submit")
            page.wait_for_function(f"window.coassist.study.step !== {view['step']}", timeout=10000)
        elif view["kind"] == "rest" and page.is_visible("#study-next") and page.is_enabled("#study-next"):
            page.click("#study-next")
            page.wait_for_function(f"window.coassist.study.step !== {view['step']}", timeout=10000)
        else:
            time.sleep(0.05)
    raise AssertionError(f"the participant's session did not end in {timeout:g} s")


def test_four_simulated_participants_take_the_comparison_in_chromium(tmp_path):
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0, timing="motion_time = 1.5\ndwell = 0.5")
    plan.write_text(plan.read_text().replace("between_conditions = 30.0", "between_conditions = 0.5"))
    study = init_study(plan, tmp_path / "study")
    received: list[str] = []
    entered = {}
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            for pid in ("S01", "S02", "S03", "S04"):
                with ParticipantRun(study, pid, simulate=True, page=("127.0.0.1", 0, None)) as run:
                    worker = threading.Thread(target=run.run, daemon=True)
                    worker.start()
                    page = browser.new_page(viewport={"width": 1300, "height": 900})
                    if pid == "S01":  # the page's scripts arrive after the first step was shown
                        _shown(run)
                        _late_study_js(page, 1.0)
                    try:
                        entered[pid] = _participant(page, run.url, OperatorPath(study.folder, pid), received)
                    finally:
                        page.close()
                    worker.join(30)
                    assert not worker.is_alive() and run.complete
        finally:
            browser.close()
    html_path, json_path = write_report(study.folder)
    summary = json.loads(json_path.read_text())
    labels = study.labels
    assert summary["n_complete"] == 4 and html_path.is_file()
    assert received and not [s for s in SECRETS if any(s in text for text in received)]
    for pid, got in entered.items():
        p = summary["participants"][pid]
        assert got["starts"] == [labels[c] for c in p["order"]]  # the page started the conditions in the square's order
        assert set(p["means"]) == {"assistive", "impedance", "manual"}
        stored = {
            r["step"]: list(r["answers"].values())
            for r in study.participant(pid).progress()
            if r["kind"] == "questionnaire"
        }
        assert stored == {int(k): v for k, v in got["answers"].items()} and len(stored) == 3
    # the drag carried the tool to the target in every trial
    ended = [r["ended"] for pid in entered for r in study.participant(pid).progress() if r["kind"] == "trial"]
    assert ended == ["target"] * 12


def test_two_simulated_participants_take_mg_against_their_own_calibrated_model_in_chromium(tmp_path):
    """Issue 40's lab flow on the page: a calibration block under the probe, each participant's person model
    fitted from it, then MG against that model (blinded), then the report."""
    study = init_study(calibrated_plan(tmp_path / "plans", trials=3, dwell=0.5), tmp_path / "study")
    received: list[str] = []
    entered = {}
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS)
        try:
            for pid in ("S01", "S02"):
                with ParticipantRun(study, pid, simulate=True, page=("127.0.0.1", 0, None)) as run:
                    worker = threading.Thread(target=run.run, daemon=True)
                    worker.start()
                    page = browser.new_page(viewport={"width": 1300, "height": 900})
                    try:
                        path = OperatorPath(study.folder, pid)
                        entered[pid] = _participant(page, run.url, path, received, timeout=300)
                    finally:
                        page.close()
                    worker.join(30)
                    assert not worker.is_alive() and run.complete
        finally:
            browser.close()
    html_path, json_path = write_report(study.folder)
    summary = json.loads(json_path.read_text())
    labels = study.labels
    assert summary["n_complete"] == 2 and summary["calibration"] == {"trials": 3, "calibrated": ["person"], "asked": 0}
    # blinding: nothing the page received names a controller, a condition, the probe or the person model
    assert received and not [s for s in (*SECRETS, "probe", "calibrat", "P0") if any(s in t for t in received)]
    for pid, got in entered.items():
        p = summary["participants"][pid]
        assert got["starts"] == [None] * 3 + [labels[c] for c in p["order"]]  # the block first, unlabelled
        (fit,) = p["person_models"]
        assert fit["model"] == "P0" and fit["trials"] == {"curved": 3} and not fit["failed"]
        arm = fit["arm"]
        if arm["measured"]:  # the page's hand is a 400 N/m spring (coassist.play.hand.SpringDamper)
            # a jackknife SE over n trials is itself an estimate with n − 1 degrees of freedom: the 99 % two-sided
            # bound is Student's t (9.92 SE for the 3 trials here), not the normal's 3 SE, which a 3-trial fit
            # misses one time in ten (CI at 85d39b7: 586 ± 57 N/m). Identification accuracy is tested on its own
            # (tests/scenario/test_arm_identification.py); here the lab's flow
            bound = float(stats.t.ppf(0.995, arm["trials"] - 1)) * arm["stiffness_se"]
            assert abs(arm["stiffness"] - 400.0) <= bound, arm
        else:
            assert arm["stiffness"] == 800.0 and "measured K" in arm["note"], arm
        lines = [r for r in study.participant(pid).progress() if r["kind"] == "trial"]
        assert [r["ended"] for r in lines[:3]] == ["target"] * 3
        assert {r["block"]: r.get("model_sha256") for r in lines[3:]} == {"mg": None, "person": fit["sha256"]["curved"]}
    html = html_path.read_text()
    assert "<h2>Person models</h2>" in html and html.count("3 curved trials of calibration") == 2
