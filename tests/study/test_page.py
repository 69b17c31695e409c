"""The study on its page, over the page's own websocket: blinded, driven by a simulated hand.

A websocket client plays the page (no browser needed): it presses Start for the step shown,
moves the hand along the simulated operator's intended path, answers the questionnaires and
goes on after the rests. Every message the server sends is kept: none may name a controller,
a condition or a model. (tests/study/test_browser.py does the same in a real Chromium.)
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

pytest.importorskip("starlette", reason="the study's page needs the web extra")
ws_client = pytest.importorskip("websockets.sync.client", reason="the test client needs websockets (the web extra)")

from coassist.data import read_dataset  # noqa: E402
from coassist.study.folder import init_study  # noqa: E402
from coassist.study.runner import ParticipantRun  # noqa: E402

from .conftest import comparison_plan  # noqa: E402
from .pagedriver import SECRETS, OperatorPath  # noqa: E402


def play_page(
    url: str,
    path: OperatorPath,
    received: list[str],
    timeout: float = 120.0,
    *,
    impatient: bool = False,
    abort_first: bool = False,
) -> dict:
    """Be the page until the study says it is done; returns what was entered per step.

    impatient : press Start twice per trial step, and once more as each trial's result arrives (an
    impatient person, or a page that lags); the study must run each step's trial once.
    abort_first : press Abort 20 frames into the first trial (once); its step is shown again."""
    entered: dict = {"answers": {}, "starts": []}
    ws_url = url.replace("http://", "ws://").rstrip("/").split("?")[0] + "/ws"
    with ws_client.connect(ws_url, open_timeout=10) as ws:
        bounds, view, running, seq, k = None, None, False, 0, -1
        frames_to_abort = 20 if abort_first else None
        pressed = None  # the step whose Start was pressed: a page shows it again (init and step may
        # both carry it when the page connects as it is shown) but a person presses once per showing
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            try:
                text = ws.recv(timeout=5)
            except TimeoutError:
                continue
            received.append(text)
            m = json.loads(text)
            kind = m["type"]
            if kind == "init":
                bounds = m["bounds"]
                view = m.get("study")
            elif kind == "step":
                view = m
                if m["kind"] == "done":
                    return entered
            elif kind == "started":
                running = True
            elif kind == "result":
                running, pressed = False, None
                view = None
                if impatient:
                    ws.send(json.dumps({"type": "start", "controller": entered["starts"][-1] or "go"}))
            elif kind == "status" and m.get("level") in ("warn", "error"):
                pressed = None  # aborted or failed: the step is shown again
            if kind == "frame" and running:
                if frames_to_abort is not None:
                    frames_to_abort -= 1
                    if frames_to_abort == 0:
                        ws.send(json.dumps({"type": "abort"}))
                        frames_to_abort, running = None, False
                        continue
                x, y = path.at(k, m["t"])
                seq += 1
                x = min(bounds[1], max(bounds[0], x))
                y = min(bounds[3], max(bounds[2], y))
                ws.send(json.dumps({"type": "pointer", "x": x, "y": y, "down": True, "seq": seq}))
                continue
            if view is None or running:
                continue
            if view["kind"] == "trial":
                if view["step"] == pressed:
                    view = None
                    continue
                pressed = view["step"]
                for _ in range(2 if impatient else 1):
                    ws.send(json.dumps({"type": "start", "controller": view["label"] or "go"}))
                entered["starts"].append(view["label"])
                k = view["step"]
                view = None
            elif view["kind"] == "questionnaire":
                values = path.answers(view["step"], view["form"]["items"])
                entered["answers"][view["step"]] = values
                ws.send(json.dumps({"type": "answers", "step": view["step"], "values": values}))
                view = None
            elif view["kind"] == "rest" and view.get("ready"):
                ws.send(json.dumps({"type": "next", "step": view["step"]}))
                view = None
    raise AssertionError("the study did not end in time")


def _study_on_the_page(tmp_path, *, impatient: bool = False, abort_first: bool = False):
    """A one-trial-per-condition comparison for participant S01, played to its end by :func:`play_page`:
    (the study, every message the page received, what the page entered)."""
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0, timing="motion_time = 1.5\ndwell = 0.5")
    plan.write_text(plan.read_text().replace("between_conditions = 30.0", "between_conditions = 0.5"))
    study = init_study(plan, tmp_path / "study")
    received: list[str] = []
    with ParticipantRun(study, "S01", simulate=True, page=("127.0.0.1", 0, None)) as run:
        done = threading.Thread(target=run.run, daemon=True)
        done.start()
        entered = play_page(
            run.url, OperatorPath(study.folder, "S01"), received, impatient=impatient, abort_first=abort_first
        )
        done.join(30)
        assert not done.is_alive() and run.complete
    return study, received, entered


def test_the_page_is_blinded_and_a_simulated_hand_drives_the_study(tmp_path):
    """The whole study through the page, Abort pressed once in the first condition's trial: nothing of that
    attempt is written, the step is shown again, the trial that ran to its end records that it was the second
    start, and the summary counts it as repeated in that condition (once, a repeat went uncounted: the report
    could not say a condition was broken off)."""
    from coassist.study.report import summarise_study

    study, received, entered = _study_on_the_page(tmp_path, abort_first=True)
    labels = study.labels
    # blinding: not one message names a controller kind or a condition
    assert received and not [s for s in SECRETS if any(s in text for text in received)]
    frames = [json.loads(t) for t in received if '"type": "frame"' in t]
    assert len(frames) > 300 and {f["controller"] for f in frames} <= set(labels.values())
    # nor a field that tells them apart: the robot's effort (zero under MG), whether a prediction ran, its rows
    # (once sent: MG's label had ur = 0 in every frame, the cooperative one predicted = true)
    from coassist.study.session import BLIND_FRAME_KEYS

    assert all(set(f) <= {*BLIND_FRAME_KEYS, "controller", "prediction", "dropped"} for f in frames), frames[0]
    assert all(f["prediction"] == [] and "ur" not in f and "predicted" not in f for f in frames)
    # the page started each condition by its label, in the participant's order (row 0: the plan's order); the
    # first twice (aborted, then run to its end)
    assert entered["starts"] == [labels["assistive"], labels["assistive"], labels["impedance"], labels["manual"]]
    assert sum('"type": "started"' in t for t in received) == 4 and sum('"type": "result"' in t for t in received) == 3
    pf = study.participant("S01")
    for name in ("assistive", "impedance", "manual"):
        (trial,) = read_dataset(pf.block(name)).trials
        assert trial.meta.extra["controller_name"] == labels[name] and trial.meta.extra["ended"] == "target"
        assert trial.meta.extra["attempts"] == (2 if name == "assistive" else 1)
    summary = summarise_study(study.folder)
    repeated = {b: c.repeated for b, c in summary.participants["S01"].trials.items()}
    assert repeated == {"assistive": 1, "impedance": 0, "manual": 0}
    assert any(line.startswith("1 of 3 measured trials were started again") for line in summary.limits)
    # the answers entered on the page are the ones stored, per condition
    stored = {r["step"]: list(r["answers"].values()) for r in pf.progress() if r["kind"] == "questionnaire"}
    assert stored == {int(k): v for k, v in entered["answers"].items()}


def test_a_second_or_late_start_runs_no_second_trial(tmp_path):
    """Start pressed twice, and again as the result arrives: each step's trial runs once, no trial
    runs that no step waits for, and the study still ends."""
    study, received, entered = _study_on_the_page(tmp_path, impatient=True)
    assert len(entered["starts"]) == 3
    assert sum('"type": "started"' in t for t in received) == 3
    assert sum('"type": "result"' in t for t in received) == 3
    pf = study.participant("S01")
    assert [len(read_dataset(pf.block(n)).trials) for n in ("assistive", "impedance", "manual")] == [1, 1, 1]


@pytest.mark.slow
def test_the_page_is_the_hand_on_the_mujoco_ur5(tmp_path):
    """The same page drives the MuJoCo UR5 (thesis' motion times, paced to the wall clock: ~16 s a trial)."""
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    plan = comparison_plan(tmp_path / "plans", world="mujoco", per_condition=1, practice=0, timing="")
    plan.write_text(
        plan.read_text()
        .replace("between_conditions = 30.0", "between_conditions = 0.5")
        .replace('tasks = ["linear", "curved"]', 'tasks = ["linear"]')
    )
    study = init_study(plan, tmp_path / "study")
    received: list[str] = []
    with ParticipantRun(study, "S01", simulate=True, page=("127.0.0.1", 0, None)) as run:
        done = threading.Thread(target=run.run, daemon=True)
        done.start()
        play_page(run.url, OperatorPath(study.folder, "S01"), received, timeout=180)
        done.join(30)
        assert run.complete
    assert not [s for s in SECRETS if any(s in text for text in received)]
    for name in ("assistive", "impedance", "manual"):
        trial = read_dataset(study.participant("S01").block(name)).trials[0]
        assert trial.meta.origin == "mujoco" and trial.meta.extra["ended"] == "target"
        assert float(np.abs(trial.wrench[:, 0]).max()) > 1.0  # the page's hand pushed the arm
