"""The recipes of docs/architecture.md proven by doing them: an intent source and an arm world, each one
new module and one registration (``Registry.register``) from this test module, run through every
consumer: collect, drive, the study's simulated runner and the main job's ablation.

The new intent source ``echo-cv`` is the constant-velocity extrapolation ŷ(k+i) = x(k) + i·dt·ẋ(k)
written again from the formula in a module of its own, so each run with it must give the trials of the
built-in ``constant-velocity`` bit for bit (and count its calls: it ran, not the built-in). The new
world ``my-arm`` builds the MuJoCo UR5 from the run's request, so its runs must give the ``mujoco``
world's. What a consumer does not see (it keeps a list of its own) fails here.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from coassist.registry import Registry
from coassist.robot.worlds import WORLDS, WorldEntry
from coassist.scenario.intent_registry import INTENT_SOURCES, IntentSourceEntry

#: The columns two runs of the same trial share, bit for bit.
COLUMNS = ("time", "pose", "velocity", "wrench", "effort_r", "prediction")

INTENT_MODULE = '''
import numpy as np

CALLS = [0]


class EchoConstantVelocity:
    """x(k) + i dt v(k), i = 1 ... horizon, from the last feature row [x, y, vx, vy, ...]."""

    history = 1
    model_id = "echo-cv"

    def __init__(self, horizon=50):
        self.horizon = horizon
        self._steps = None

    def reset(self, context):
        self._steps = float(context.dt) * np.arange(1, self.horizon + 1)[:, None]

    def predict(self, history):
        CALLS[0] += 1
        row = history[-1]
        return row[0:2] + self._steps * row[2:4]
'''

WORLD_MODULE = """
from coassist.robot.mujoco_world import MujocoUR5World

BUILT = [0]


def build_world(request):
    BUILT[0] += 1
    return MujocoUR5World(request.object, control_dt=1.0 / request.rate_hz, start=request.start,
                          seed=request.seed, view=request.view, realtime=request.realtime)
"""


@contextmanager
def registered(registry: Registry, name: str, entry: object) -> Iterator[None]:
    registry.register(name, entry)
    try:
        yield
    finally:
        registry.unregister(name)


@pytest.fixture
def echo_cv(tmp_path, monkeypatch):
    """The throw-away intent source: its module, and its one line (the ablation runs it too)."""
    (tmp_path / "coassist_test_echo_cv.py").write_text(INTENT_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("coassist_test_echo_cv")
    entry = IntentSourceEntry(
        "coassist_test_echo_cv:EchoConstantVelocity", "the constant-velocity extrapolation, again", ablation=True
    )
    try:
        with registered(INTENT_SOURCES, "echo-cv", entry):
            yield module.CALLS
    finally:
        sys.modules.pop("coassist_test_echo_cv")  # the next test imports its own (its counter from 0)


@pytest.fixture
def my_arm(tmp_path, monkeypatch):
    """The throw-away world: its module, and its one line."""
    pytest.importorskip("mujoco", reason="the throw-away world is the MuJoCo UR5 built again: the robot extra")
    (tmp_path / "coassist_test_my_arm.py").write_text(WORLD_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("coassist_test_my_arm")
    entry = WorldEntry(
        "coassist_test_my_arm:build_world",
        ("ur5",),
        "the MuJoCo UR5, built by a test",
        simulated=True,
        host=None,
        extras=("robot",),
        origin="mujoco",
    )
    try:
        with registered(WORLDS, "my-arm", entry):
            yield module.BUILT
    finally:
        sys.modules.pop("coassist_test_my_arm")


def _same_trials(mine, builtin) -> None:
    assert len(mine) == len(builtin) > 0
    for a, b in zip(mine, builtin):
        assert a.n_samples == b.n_samples > 50
        for column in COLUMNS:
            np.testing.assert_array_equal(getattr(a, column), getattr(b, column), err_msg=column)


def test_registered_entries_leave_with_the_test():
    assert "echo-cv" not in INTENT_SOURCES and "my-arm" not in WORLDS
    from coassist.experiments.ablation_cells import registered_sources
    from coassist.study.plan import study_worlds

    assert registered_sources() == ()  # the main job's ablation runs the sources of its tables alone
    assert study_worlds() == ("play", "mujoco", "ur", "franka")


def test_collect_runs_a_registered_intent_source(echo_cv, tmp_path):
    from coassist.data import read_dataset
    from coassist.sim.collect import collect_dataset

    options = dict(
        workers=1,
        progress=False,
        controller="cooperative",
        users=[0],
        tasks=["curved"],
        objects=["handle"],
        trials=2,
        seed=5,
    )
    mine = read_dataset(collect_dataset(tmp_path / "echo", intent="echo-cv", **options))
    assert echo_cv[0] > 1000  # it ran every tick of both trials
    builtin = read_dataset(collect_dataset(tmp_path / "cv", intent="constant-velocity", **options))
    assert [t.meta.model_id for t in mine.trials] == ["echo-cv"] * 2
    _same_trials(mine.trials, builtin.trials)


def test_drive_runs_a_registered_world_with_a_registered_intent_source(echo_cv, my_arm):
    from coassist.robot.drive import DriveConfig, drive

    mine = drive(DriveConfig(world="my-arm", controller="cooperative", intent="echo-cv", time_limit=0.6))
    assert my_arm[0] == 1 and echo_cv[0] > 50
    builtin = drive(DriveConfig(world="mujoco", controller="cooperative", intent="constant-velocity", time_limit=0.6))
    assert mine.meta.extra["world"] == "my-arm" and mine.meta.model_id == "echo-cv"
    _same_trials([mine], [builtin])


STUDY = """
[study]
name = "registered"
protocol = "comparison"
world = "{world}"
participants = 2
seed = 3

[[condition]]
name = "echo"
controller = "cooperative"
intent = "echo-cv"

[[condition]]
name = "built-in"
controller = "cooperative"
intent = "constant-velocity"

[trials]
tasks = ["linear"]
per_condition = 1
practice = 0
{timing}

[rest]
between_conditions = 0.0
"""


def _run_study(root: Path, world: str, timing: str) -> dict[str, list]:
    """The plan's simulated participant S01, run to the end; the trials of each condition."""
    from coassist.data import read_dataset
    from coassist.study.folder import init_study
    from coassist.study.runner import ParticipantRun

    root.mkdir(parents=True)
    (root / "plan.toml").write_text(STUDY.format(world=world, timing=timing))
    study = init_study(root / "plan.toml", root / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    by_condition: dict[str, list] = {}
    for manifest in sorted((study.folder / "participants" / "S01").rglob("manifest.json")):
        for trial in read_dataset(manifest.parent).trials:
            by_condition.setdefault(trial.meta.extra["study_condition"], []).append(trial)
    return by_condition


def test_the_study_runs_a_registered_intent_source_in_the_page_world(echo_cv, tmp_path):
    trials = _run_study(tmp_path / "play", "play", "motion_time = 3.0\ndwell = 1.0")
    assert echo_cv[0] > 100
    assert sorted(trials) == ["built-in", "echo"]
    _same_trials(trials["echo"], trials["built-in"])


def test_the_study_runs_a_registered_world(echo_cv, my_arm, tmp_path):
    from coassist.study.plan import study_worlds

    assert study_worlds()[-1] == "my-arm"
    timing = "time_limit = 16.0"  # an arm trial's least: the linear path's planned motion and the 5 s dwell
    mine = _run_study(tmp_path / "mine", "my-arm", timing)
    assert my_arm[0] == 2  # one world per trial
    builtin = _run_study(tmp_path / "builtin", "mujoco", timing)
    assert {t.meta.extra["world"] for ts in mine.values() for t in ts} == {"my-arm"}
    for condition in ("echo", "built-in"):
        _same_trials(mine[condition], builtin[condition])
    _same_trials(mine["echo"], mine["built-in"])


def test_the_ablation_runs_a_registered_intent_source(echo_cv, tmp_path):
    from coassist.experiments import pipeline, reproduce_config
    from coassist.experiments.ablation import OBJECTS, AblationAhead, run_ablation
    from coassist.experiments.ablation_cells import ARBITRATED, ablation_cells, registered_sources
    from coassist.scenario.path_hypotheses import write_calibration
    from coassist.scenario.person_model import write_person_model

    assert registered_sources() == ("echo-cv",)
    cfg = replace(
        reproduce_config.REPRODUCE_PRESETS["tiny"],
        workers=1,
        threads=1,
        learned_sources=(),
        held_out_trials=0,
        ablation_mujoco_trials=0,
    )
    assert {(c, s) for c, s in ablation_cells(cfg) if s == "echo-cv"} == {
        ("cooperative", "echo-cv"),
        (ARBITRATED, "echo-cv"),
    }
    ws = pipeline.Workspace(cfg, tmp_path / "run", progress=False)
    models = {
        "paths": str(write_calibration(tmp_path / "paths", {})),
        "person": str(write_person_model(tmp_path / "person", {})),
    }
    # As the main job does: AblationAhead starts every cell ahead (the registered source's too, from the
    # same ablation_cells), and with one worker Workspace.prefetch defers them; the first collect runs them
    # all in lockstep groups, the same trials bit for bit as each alone (tests/experiments/test_prefetch.py).
    # The 34 one-trial cells then cost 6.5 CPU-s in all instead of 18.1 one by one (issue 44).
    AblationAhead(ws, set())(models)
    assert {n for n in ws._deferred if n.endswith("echo-cv")} == {
        f"ablation-{o}-{c}-echo-cv" for o in OBJECTS for c in ("cooperative", ARBITRATED)
    }
    result = run_ablation(ws, models)
    assert echo_cv[0] > 100
    for obj in ("board", "heavy"):
        for controller in ("cooperative", ARBITRATED):
            mine = result.metrics[("point-mass", obj, controller, "echo-cv")]
            builtin = result.metrics[("point-mass", obj, controller, "constant-velocity")]
            assert (
                mine["f_rms_trials"] == builtin["f_rms_trials"]
                and mine["overshoot_trials"] == builtin["overshoot_trials"]
            )
    assert "point-mass/board/cooperative-arbitrated/echo-cv" in result.summary()["cells"]


def test_a_registered_controller_kind_is_what_its_trials_record():
    """A kind built on ImpedanceControl recorded TrialMeta.controller 'impedance': its data read as IMP (review,
    2026-12-06). A registered kind's trials record the kind; the declared kinds record what they always did."""
    from coassist.config import CONTROL_PRESETS
    from coassist.control.controllers import ImpedanceControl
    from coassist.control.presets import CONTROLLERS, ControllerEntry, make_controller
    from coassist.sim.trial_runner import TrialSpec, run_spec

    def soft(model, preset):
        return ImpedanceControl(model, K=50.0, effort_limit=preset.effort_limit)

    CONTROLLERS.register("soft-imp", ControllerEntry(soft, "a softer impedance"))
    try:
        preset = CONTROL_PRESETS["thesis-application"]
        assert make_controller("soft-imp", preset).name == "soft-imp"
        assert make_controller("impedance", preset).name == "impedance"  # the declared kind: unchanged
        assert make_controller("cooperative-arbitrated", preset).name == "cooperative+target"
        trial = run_spec(TrialSpec(task="linear", controller="soft-imp", seed=3))
        assert trial.meta.controller == "soft-imp"
    finally:
        CONTROLLERS.unregister("soft-imp")


def test_a_source_that_is_no_intent_source_is_told_what_it_lacks():
    """A custom source without ``history`` was refused as "must implement IntentSource, got NoHistory", naming no
    member (the world path names them): both paths now say what it lacks (review, 2026-12-06)."""
    from coassist.config import CONTROL_PRESETS
    from coassist.control.presets import make_controller
    from coassist.runtime.intent import WindowIntent
    from coassist.scenario.objects import get_object
    from coassist.scenario.populations import population_profile
    from coassist.scenario.tasks import task_for_seed
    from coassist.sim.trial_runner import build_trial

    class NoHistory:
        horizon = 50
        model_id = "mine"

        def reset(self, context) -> None:
            pass

        def predict(self, history):
            return history[-1:, :2].repeat(50, axis=0)

    with pytest.raises(ValueError, match=r"got NoHistory, which lacks history$"):
        WindowIntent(NoHistory(), 50)
    with pytest.raises(ValueError, match=r"got NoHistory, which lacks history$"):
        build_trial(
            task_for_seed("linear", 0),
            population_profile("thesis", 0),
            get_object("handle"),
            make_controller("cooperative", CONTROL_PRESETS["thesis-application"]),
            NoHistory(),
        )
