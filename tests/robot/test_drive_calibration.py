"""The lab's flow on an arm (issue 40): calibration trials recorded by drive with the probe fit a person model;
drive says in one line what the person will get; a scene file reaches the intent source on an arm."""

from __future__ import annotations

import hashlib
from typing import NamedTuple

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")

from coassist.data import Trial  # noqa: E402
from coassist.experiments.person_calibration import calibrate_people  # noqa: E402
from coassist.robot.drive import DriveConfig, drive  # noqa: E402
from coassist.robot.mujoco_world import MujocoUR5World  # noqa: E402
from coassist.runtime.operators import ScriptedForce  # noqa: E402
from coassist.scenario.intent_registry import INTENT_SOURCES  # noqa: E402
from coassist.scenario.person_model import PERSON_MODEL_FILE, person_filter_for, write_person_model  # noqa: E402
from coassist.scenario.scene import Scene, SceneBox  # noqa: E402

PUSH = ScriptedForce.constant((5.0, 0.0, 0.0, 0.0, 0.0, 0.0))


class Named(NamedTuple):
    id: str
    trial: Trial


@pytest.fixture(scope="module")
def probe_trials():
    """Three calibration trials of the simulated operator, recorded by drive in MuJoCo with the probe."""
    said: list[str] = []
    trials = [
        Named(
            f"mujoco/{s}",
            drive(
                DriveConfig(controller="manual-probe", task="linear", obstacle="large", seed=s, person="alice"),
                say=said.append,
            ),
        )
        for s in range(3)
    ]
    return trials, said


def test_probe_trials_recorded_by_drive_fit_a_person_model(probe_trials, tmp_path):
    trials, said = probe_trials
    # the probe is a calibration trial, never assistance, and drive says so (one line per run)
    assert said == [said[0]] * 3 and said[0].startswith("assistance: none: a calibration trial")
    for t in trials:
        assert t.trial.meta.controller == "manual-probe" and t.trial.meta.user == "alice"
        # the probe's push is what the robot exerts: 2.5 N RMS per axis (coassist.control.presets.PROBE)
        rms = np.sqrt(np.mean(t.trial.effort_r[:, :2] ** 2, axis=0))
        np.testing.assert_allclose(rms, 2.5, rtol=0.1)
    (c,) = calibrate_people(trials)
    arm = c.fit.arm
    assert arm.method == "probe-iv" and arm.trials == 3
    # the simulated operator's arm stiffens from 550 to 1300 N/m with their effort: the estimate lies there
    assert 550.0 - 3 * arm.stiffness_se < arm.stiffness < 1300.0 + 3 * arm.stiffness_se
    # the MuJoCo world's filter, as calibrate writes it for trials of that world
    folder = write_person_model(tmp_path / "cal", {"alice": c.fit}, settings=person_filter_for("mujoco"))

    # assisting with it: drive names the person model, whose arm and how many demonstrations
    said = []
    run = drive(
        DriveConfig(task="linear", obstacle="large", intent=str(folder), person="alice", time_limit=0.4),
        say=said.append,
    )
    sides = c.fit.paths.sides
    left, right = int(np.sum(sides == 1)), int(np.sum(sides == -1))
    # a way shown once or twice: said, as it is followed from those paths alone
    thin = ", ".join(
        f"{w} from {k} path{'s' * (k > 1)} only" for w, k in (("left", left), ("right", right)) if 0 < k < 3
    )
    assert said == [
        f"assistance: cooperative, toward the person model {folder} (alice: arm measured, {sides.size} "
        f"demonstrations ({left} left, {right} right{'; ' + thin if thin else ''}))"
        "; a damper if the hand force oscillates above 20 N (the stability guard)"
    ]
    # the folder's name and the first 12 hex digits of the file's SHA-256: another calibration, another id
    digest = hashlib.sha256((folder / PERSON_MODEL_FILE).read_bytes()).hexdigest()[:12]
    assert run.meta.model_id == f"person:cal@{digest}" and run.meta.user == "alice"
    # another task: the person model says it serves another plan
    said.clear()
    drive(
        DriveConfig(task="curved", intent=str(folder), person="alice", time_limit=0.2),
        say=said.append,
    )
    assert "recorded on another plan than this run's: the present estimate held, with their arm" in said[0]
    # a person it holds no calibration of is refused before anything moves
    with pytest.raises(ValueError, match=r"holds no calibration of 'bob' \(it holds alice\).*--person"):
        drive(DriveConfig(task="linear", intent=str(folder), person="bob", time_limit=0.2))
    # and by play, whose option is --user (its line named --person, an option play does not have: review, 2026-12-06)
    from coassist.play.session import PlayConfig, PlaySession

    with pytest.raises(ValueError, match=r"holds no calibration of 'bob' \(it holds alice\); play as .*\(--user\)"):
        PlaySession(PlayConfig(user="bob", out=tmp_path / "play", controllers=("cooperative",), intent=str(folder)))
    # a model of another world, whose filter, arm and paths are that world's, is refused where it would run: the
    # point-mass world's filter on the MuJoCo UR5 (its jerk 2.4-3.7 m/s³ against MG's 1.8 in review), the arm's on the page,
    # in a collection or a comparison (the point-mass world)
    elsewhere = write_person_model(tmp_path / "pm", {"alice": c.fit}, settings=person_filter_for("sim"))
    with pytest.raises(ValueError, match=r"object twists on its mount.*not of the mujoco world.*manual-probe"):
        drive(DriveConfig(task="linear", intent=str(elsewhere), person="alice", time_limit=0.2))
    with pytest.raises(ValueError, match=r"calibrated on trials of the MuJoCo UR5 .*not of the play world"):
        PlaySession(PlayConfig(user="alice", out=tmp_path / "play", controllers=("cooperative",), intent=str(folder)))
    # play's line says each task of the session: the model leads on its own plan only (the first task's alone was said)
    from coassist.cli.play import _page_assistance

    session = PlaySession(
        PlayConfig(
            user="alice", out=tmp_path / "play2", controllers=("cooperative",), intent=str(elsewhere),
            tasks=("curved", "linear", "z"),
        )
    )  # fmt: skip
    line = _page_assistance(session)
    assert line.startswith(f"assistance: cooperative, on task curved, z: toward the person model {elsewhere} (alice:")
    assert "recorded on another plan than this run's" in line.split("; on task linear: ")[0]
    assert "recorded on another plan" not in line.split("; on task linear: ")[1], line
    from typer.testing import CliRunner

    from coassist.cli import app

    res = CliRunner().invoke(app, ["collect", "--out", str(tmp_path / "D"), "--trials", "1", "--intent", str(folder)])
    said_line = " ".join(res.output.split())
    assert (
        res.exit_code == 2
        and f"--intent {folder}: the person model was calibrated on trials of the MuJoCo" in said_line
    )
    assert not (tmp_path / "D").exists()
    from coassist.experiments.precision import compare_intents

    with pytest.raises(ValueError, match=r"source pm: .*alice's person model was fitted on task 'linear', not on task"):
        compare_intents({"pm": str(elsewhere)}, tmp_path / "cmp", bases=[50000])


class _Told:
    """The ``paths`` source, remembering what each trial told it."""

    def __init__(self) -> None:
        self.inner = INTENT_SOURCES["paths"].build(60)
        self.history, self.horizon, self.model_id = 1, 60, "paths"
        self.contexts: list = []

    def reset(self, context) -> None:
        self.contexts.append(context)
        self.inner.reset(context)

    def predict(self, history):
        return self.inner.predict(history)


class _Sink:
    """A live view's sink keeping the trials it was shown (what Foxglove would draw)."""

    def __init__(self) -> None:
        self.trials: list = []

    def publish(self, snapshot) -> None:
        if not self.trials or self.trials[-1] is not snapshot.trial:
            self.trials.append(snapshot.trial)

    def close(self) -> None:
        pass


def test_a_scene_file_reaches_the_source_on_an_arm():
    # a real arm's world ("ur"), here MuJoCo behind it with a scripted hand: the robot is told nothing of the task,
    # only the scene (a box on the plan, y = −0.615 m from x = −0.1 to 0.4 m in the base frame: one a person goes
    # round); MuJoCo's own world, where the simulated operator goes round the task's box, is told that box. What
    # the source was told, what the one-line statement says and what the live view draws are one answer
    # (build_episode's context): the live view had drawn the task's box for the scripted hand on "ur", which the
    # source never saw.
    from coassist.runtime.live import LiveFeed

    scene = Scene((SceneBox((0.15, -0.6), (0.12, 0.12), "box"),), "scene.toml")
    base = {"controller": "cooperative", "task": "linear", "time_limit": 0.3, "intent": "paths"}
    head = "assistance: cooperative, toward the path hypotheses"
    guard = "; a damper if the hand force oscillates above 20 N (the stability guard)"
    cases = (
        ("ur", None, head + ", but the robot is told no obstacle: the present estimate (give --scene FILE)"),
        ("ur", scene, head + " round the 1 obstacle of the scene file scene.toml (the robot is told the scene)"),
        ("mujoco", None, head + " round the 1 obstacle of the simulated task (the robot is told the scene)"),
    )
    for name, given, statement in cases:
        source, sink, said = _Told(), _Sink(), []
        world = MujocoUR5World("handle", seed=0) if name == "ur" else None
        try:
            with LiveFeed(sink, rate_hz=100.0) as live:
                trial = drive(
                    DriveConfig(**base, world=name, scene=given),
                    world=world,
                    intent_source=source,
                    operator=PUSH if name == "ur" else None,
                    say=said.append,
                    live=live,
                )
                assert live.flush(10)
        finally:
            if world is not None:
                world.close()
        (context,) = source.contexts
        (shown,) = sink.trials
        assert said == [statement + guard]
        assert [(c.tolist(), z.tolist()) for c, z in shown.obstacles] == [
            (list(c), list(z)) for c, z in context.obstacles
        ]
        np.testing.assert_array_equal(shown.path, context.path)
        if name == "mujoco":
            assert len(context.obstacles) == 1 and source.inner.curves[0].size > 0
        elif given is None:
            assert context.obstacles == () and "scene" not in trial.meta.extra
            assert source.inner.curves[0].size == 0  # no obstacle: paths is the present estimate
        else:
            assert context.obstacles == (((0.15, -0.6), (0.12, 0.12)),)
            told = trial.meta.extra["scene"]  # recorded with the trial: reported apart
            assert told["file"] == "scene.toml" and told["frame"] == "base"
            assert [(tuple(o["center"]), tuple(o["size"]), o["name"]) for o in told["obstacles"]] == [
                ((0.15, -0.6), (0.12, 0.12), "box")
            ]
            sides, points = source.inner.curves
            assert set(sides.tolist()) == {1, -1} and points.shape[0] == sides.size  # hypotheses round the box


def test_the_statement_names_the_scene_for_paths():
    # a box on the plan (y = −0.615 m, x from −0.1 to 0.4 m), and one 0.7 m off it (a fixture on the table)
    guard = "; a damper if the hand force oscillates above 20 N (the stability guard)"
    said: list[str] = []
    for box in ((0.15, -0.6), (0.52, 0.16)):
        scene = Scene((SceneBox(box, (0.12, 0.12)),), "lab/scene.toml")
        drive(DriveConfig(task="linear", intent="paths", scene=scene, time_limit=0.2), say=said.append)
    assert said == [
        "assistance: cooperative, toward the path hypotheses round the 1 obstacle of the scene file "
        "lab/scene.toml (the robot is told the scene)" + guard,
        "assistance: cooperative, toward the path hypotheses, but the 1 obstacle of the scene file lab/scene.toml lies "
        "clear of this run's plan: nothing to go round, the present estimate" + guard,
    ]


def test_the_statement_says_which_of_several_boxes_paths_goes_round():
    """Two boxes on the plan, one off it: the line said "round the 3 obstacles" while one detour a run goes round the
    box in the way the plan passes nearest and the predictions ran through the other (a review, 2026-12-07)."""
    guard = "; a damper if the hand force oscillates above 20 N (the stability guard)"
    said: list[str] = []
    boxes = ((0.03, -0.615), (0.27, -0.615), (0.52, 0.16))
    scene = Scene(tuple(SceneBox(b, (0.08, 0.08)) for b in boxes), "lab/scene.toml")
    drive(DriveConfig(task="linear", intent="paths", scene=scene, time_limit=0.2), say=said.append)
    assert said == [
        "assistance: cooperative, toward the path hypotheses round one of the 3 obstacles of the scene file "
        "lab/scene.toml, the one in the way its plan passes nearest; 1 more in the way is NOT gone round (the "
        "predictions run through it: one detour a run); 1 lies clear of the plan (the robot is told the scene)" + guard
    ]


def test_a_scene_box_on_the_plans_start_or_target_is_refused_before_the_arm_moves():
    """A box of the scene file holding the plan's start (where the tool stands) or its target was taken as given:
    the path hypotheses led the tool round it, 10.9 N of hand force against MG's 6.3 (review, 2026-12-06). Refused
    in one line naming the box, before anything moves (the linear plan from −0.1 to 0.4 m at y = −0.615 m)."""
    from coassist.scenario.scene import SceneError

    for center, what in (((-0.1, -0.615), "start (where the tool stands)"), ((0.4, -0.615), "target")):
        scene = Scene((SceneBox(center, (0.12, 0.12), "crate"),), "lab/scene.toml")
        with pytest.raises(SceneError) as err:
            drive(DriveConfig(task="linear", intent="paths", scene=scene, time_limit=0.2))
        msg = str(err.value)
        assert msg.startswith("scene lab/scene.toml: obstacle 1 (crate)") and f"holds the plan's {what}" in msg, msg
        assert "\n" not in msg


def test_the_commands_say_what_the_person_gets_and_refuse_bad_lab_inputs(tmp_path):
    from typer.testing import CliRunner

    from coassist.cli import app

    runner = CliRunner()
    out = str(tmp_path / "t.parquet")
    res = runner.invoke(app, ["drive", "--time-limit", "0.2", "--no-plot", "--out", out])
    assert res.exit_code == 0, res.output
    said = [line for line in res.output.splitlines() if line.startswith("assistance:")]
    assert said == [
        "assistance: cooperative, toward the present estimate from the hand force (no calibration: run coassist "
        "calibrate); a damper if the hand force oscillates above 20 N (the stability guard)"
    ]
    # the guard off (a lab's choice, docs/robots.md): the statement says the controller alone, as on MG, which is
    # never guarded (which runs the guard wraps: tests/robot/test_drive.py)
    for args, line in (
        (
            ["--no-stability-guard"],
            "assistance: cooperative, toward the present estimate from the hand force "
            "(no calibration: run coassist calibrate)",
        ),
        (
            ["--controller", "manual"],
            "assistance: none: manual guidance (MG), the robot renders its inertia and damping only",
        ),
    ):
        res = runner.invoke(app, ["drive", "--time-limit", "0.2", "--no-plot", "--overwrite", "--out", out, *args])
        assert res.exit_code == 0, res.output
        assert [x for x in res.output.splitlines() if x.startswith("assistance:")] == [line]
    bad = tmp_path / "scene.toml"
    bad.write_text("[[obstacle]]\ncenter = [0.5, 0.1]\n")
    res = runner.invoke(app, ["drive", "--intent", "paths", "--scene", str(bad), "--out", str(tmp_path / "u.parquet")])
    assert res.exit_code == 2 and f"error: --scene {bad}: obstacle[0].size is missing" in res.output
    # a scene given to a run that reads none was recorded with its trial as if the robot had been told it (a
    # review, 2026-12-07): refused, for every source and controller but the path hypotheses under assistance
    good = tmp_path / "good.toml"
    good.write_text("[[obstacle]]\ncenter = [0.5, 0.1]\nsize = [0.1, 0.1]\n")
    for args in (["--intent", "present-held"], ["--controller", "manual", "--intent", "paths"], ["--intent", "oracle"]):
        res = runner.invoke(app, ["drive", *args, "--scene", str(good), "--out", str(tmp_path / "u.parquet")])
        assert res.exit_code == 2 and f"error: --scene {good}: " in res.output and "reads no scene" in res.output
    res = runner.invoke(app, ["drive", "--person", "a b", "--out", str(tmp_path / "u.parquet")])
    assert res.exit_code == 2 and "--person must be 1-32 letters, digits" in res.output
    assert not (tmp_path / "u.parquet").exists()
    # a trial file is Parquet: a .csv name was written as Parquet without a word (review, 2026-12-06)
    res = runner.invoke(app, ["drive", "--time-limit", "0.2", "--out", str(tmp_path / "t.csv")])
    assert res.exit_code == 2 and "a trial is written as Parquet: give a .parquet name" in res.output
    assert not (tmp_path / "t.csv").exists()
    pytest.importorskip("starlette", reason="play needs the web extra")
    res = runner.invoke(app, ["play", "--scene", str(bad), "--no-open"])
    assert res.exit_code == 2 and "a scene file is for --drive (an arm)" in res.output
