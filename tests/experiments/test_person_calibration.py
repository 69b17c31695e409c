"""A lab's calibration (coassist.experiments.person_calibration, ``coassist calibrate``): recorded trials in,
one person model per person out, with one line each and one-line refusals naming the person and the trial."""

import time
from dataclasses import replace
from typing import NamedTuple

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.control.presets import get_preset, make_controller
from coassist.data import Trial, TrialMeta, default_real_data, load_ros_user, write_dataset
from coassist.experiments.person_calibration import (
    CalibrationError,
    PersonCalibration,
    calibrate_people,
    summary_line,
    thin_ways,
    ways_to_ask,
)
from coassist.scenario.arm_identification import ASSUMED_ARM, identify_arm
from coassist.scenario.objects import get_object
from coassist.scenario.operator import AUTHOR
from coassist.scenario.person_model import read_person_model
from coassist.scenario.tasks import task_for_seed
from coassist.sim.trial_runner import run_trial

PRESET = get_preset("thesis-application-damped")
#: a person of known, fixed arm (no co-contraction): what the probe must recover
K, C = 700.0, 7.0
ALICE = replace(AUTHOR, name="alice", stiffness_min=K, stiffness_max=K, stiffness_gain=0.0, damping=C)
BOB = replace(AUTHOR, name="bob")
runner = CliRunner()


class Named(NamedTuple):
    id: str
    trial: Trial


def _run(profile, controller, seeds, task="linear", obj="handle"):
    ctrl = make_controller(controller, PRESET)
    return [
        Named(
            f"lab/{profile.name}-{task}-{s}{'' if obj == 'handle' else '-' + obj}",
            run_trial(task_for_seed(task, s, obstacle="large"), profile, get_object(obj), ctrl, None, s),
        )
        for s in seeds
    ]


@pytest.fixture(scope="module")
def alice():
    """Four probe trials of alice on the linear task, and the CPU seconds their calibration took."""
    return _run(ALICE, "manual-probe", range(4))


@pytest.fixture(scope="module")
def bob():
    """Three plain MG trials of bob (no probe)."""
    return _run(BOB, "manual", range(10, 13))


def test_each_person_gets_their_own_fit_and_a_line(alice, bob):
    people = calibrate_people([*alice, *bob])
    assert [c.person for c in people] == ["alice", "bob"]
    a, b = people
    assert isinstance(a, PersonCalibration) and a.task == "linear" and a.trials == tuple(t.id for t in alice)
    # alice's arm is measured by the probe: the known K within three of its standard errors
    assert a.fit.arm.method == "probe-iv" and a.fit.arm.trials == 4 and a.probe_trials == 4
    assert abs(a.fit.arm.stiffness - K) < 3 * a.fit.arm.stiffness_se, a.fit.arm
    # bob's trials carry no probe: his arm is assumed, and the line says so
    assert b.fit.arm is ASSUMED_ARM and b.probe_trials == 0
    line_a, line_b = summary_line(a), summary_line(b)
    assert f"K̂ {a.fit.arm.stiffness:.0f} ± {a.fit.arm.stiffness_se:.0f} N/m" in line_a
    assert "measured by the probe in 4 trial(s)" in line_a and "ASSUMED" not in line_a
    assert "arm ASSUMED, not measured" in line_b and "carry no probe" in line_b and "manual-probe" in line_b
    # the same trials as a bag gives them (no record of the controller that ran): the line says that, not "no
    # probe", and what to calibrate instead (drive's trial files beside its bags)
    unknown = [Named(t.id, replace(t.trial, meta=replace(t.trial.meta, controller="unknown"))) for t in bob]
    for trials, what in ((unknown, "the trials do"), ([*unknown[:2], bob[2]], "2 of the trials do")):
        (c,) = calibrate_people(trials)
        line = summary_line(c)
        assert c.unrecorded == len(trials) - (what != "the trials do") and "carry no probe" not in line, line
        assert f"{what} not record which controller ran" in line and "drive's .parquet" in line, line
    # demonstrations per way round, as the path model labelled them
    for c, line in ((a, line_a), (b, line_b)):
        sides = c.fit.paths.sides
        assert f"{int(np.sum(sides == 1))} left, {int(np.sum(sides == -1))} right" in line
        assert "\n" not in line


@pytest.mark.real_data
def test_the_recorded_people_calibrate_and_their_free_deviations_do_not_repeat():
    # user-a of the thesis lab deviated as they wished, with nothing to go round (docs/person-model.md, "On the
    # real recordings"). Each plan they followed more than once calibrates (the trials' periods, measured from their
    # timestamps, differ by up to 0.6 %), and its paths repeat less than any simulated person's with the
    # application's obstacle (0.12–0.32, eight probe trials each; user-a's 0.42–0.89)
    folder = default_real_data()
    if not (folder / "user-a").is_dir():
        pytest.skip(f"real UR5 recordings (shared/data/ur5-thesis) not found: {folder.resolve()}")
    plans: dict[tuple, list] = {}
    for t in load_ros_user(folder / "user-a"):
        ref = np.asarray(t.reference[:, :2])
        plans.setdefault(tuple(np.round(np.concatenate([ref[0], ref.min(axis=0), ref.max(axis=0)]), 3)), []).append(t)
    fitted = []
    for trials in plans.values():
        if len(trials) > 1:
            (c,) = calibrate_people([Named(t.meta.extra["recording"], t) for t in trials])
            assert "arm ASSUMED" in summary_line(c) and c.fit.paths.repeatability() is not None
            fitted.append(c.fit.paths.repeatability())
    simulated_most = 0.32
    assert len(fitted) == 3 and all(r > simulated_most for r in fitted), fitted


def test_the_arm_comes_from_the_probe_trials_alone(alice):
    # a person's assisted trial carries the robot's own effort, which follows their motion: it must not
    # enter the arm's instruments, only the paths
    coop = _run(ALICE, "cooperative", [20])
    (c,) = calibrate_people([*alice, *coop])
    assert c.probe_trials == 4 and len(c.trials) == 5
    reference = identify_arm([t.trial for t in alice])
    assert c.fit.arm == reference
    assert c.fit.paths.sides.shape == (5,)


def test_the_fit_is_fast_enough(alice):
    # the goal: 10 trials a person in <= 30 s on 2 cores. CPU seconds (not wall time: the machine is shared)
    # per trial, against the goal's 3 s per trial; the fit is linear in the trials
    t0 = time.process_time()
    (c,) = calibrate_people(alice)
    spent = time.process_time() - t0
    assert spent / len(alice) < 3.0, spent
    assert 0.0 < c.cpu_seconds <= spent + 1e-6


def _trial(base: Trial, **changes) -> Trial:
    fields = {k: getattr(base, k) for k in ("meta", "time", "pose", "velocity", "wrench", "reference")}
    fields["effort_r"] = base.effort_r
    fields.update(changes)
    return Trial(**fields)


def test_refusals_name_the_person_and_the_trial(alice):
    first = alice[0]
    with pytest.raises(CalibrationError, match=r"alice: 2 trial\(s\) of task 'linear' \(lab/alice-linear-0, "):
        calibrate_people(alice[:2])
    z = _run(ALICE, "manual-probe", [30], task="z")
    with pytest.raises(CalibrationError, match=r"alice: trial lab/alice-z-30 is of task 'z'.*--task"):
        calibrate_people([*alice, *z])
    # --task keeps one task's trials, and names the tasks there are when none is of it
    (c,) = calibrate_people([*alice, *z], task="linear")
    assert c.trials == tuple(t.id for t in alice)
    with pytest.raises(CalibrationError, match="no trial of task 'curved'.*linear, z"):
        calibrate_people([*alice, *z], task="curved")
    # another start (an arm lays the plan out from where the tool is): another nominal path
    moved = _trial(first.trial, reference=first.trial.reference + [0.05, 0.0], pose=first.trial.pose + [0.05, 0.0])
    with pytest.raises(CalibrationError, match=r"alice: trial lab/moved follows another nominal path.*5\.0 cm"):
        calibrate_people([*alice, Named("lab/moved", moved)])
    # a loop: a plan round a circle, ending where it started
    n = first.trial.n_samples
    theta = np.linspace(0.0, 2.0 * np.pi, n)
    circle = first.trial.reference[0, :2] + 0.2 * np.stack([np.cos(theta) - 1.0, np.sin(theta)], axis=1)
    ref = first.trial.reference.copy()
    ref[:, :2] = circle
    loop = _trial(first.trial, reference=ref, pose=ref.copy())
    with pytest.raises(CalibrationError, match=r"alice: trial lab/loop: its plan ends 0\.0 cm from where it starts"):
        calibrate_people([*alice, Named("lab/loop", loop)])
    # a trial where the tool never moved
    still = _trial(first.trial, pose=np.repeat(first.trial.pose[:1], first.trial.n_samples, axis=0))
    with pytest.raises(CalibrationError, match=r"alice: trial lab/still: the tool moved 0 mm and reached 0 %"):
        calibrate_people([*alice, Named("lab/still", still)])
    # one DOF
    t = first.trial
    one = Trial(
        meta=t.meta, time=t.time, pose=t.pose[:, :1], velocity=t.velocity[:, :1], wrench=t.wrench[:, :1],
        reference=t.reference[:, :1],
    )  # fmt: skip
    with pytest.raises(CalibrationError, match="alice: trial lab/one has 1 DOF"):
        calibrate_people([*alice, Named("lab/one", one)])
    # another control rate
    meta = TrialMeta(**{**{k: getattr(t.meta, k) for k in t.meta.__dataclass_fields__}, "dt": 0.002})
    fast = _trial(t, meta=meta, time=t.time / 4)
    with pytest.raises(CalibrationError, match=r"alice: trial lab/fast was recorded at 500 Hz.*125 Hz"):
        calibrate_people([*alice, Named("lab/fast", fast)])
    # a recording's period measured from its timestamps, 0.5 % off: the same control rate
    meta = TrialMeta(**{**{k: getattr(t.meta, k) for k in t.meta.__dataclass_fields__}, "dt": 0.008 * 1.005})
    (c,) = calibrate_people([*alice, Named("lab/measured", _trial(t, meta=meta, time=t.time * 1.005))])
    assert c.trials[-1] == "lab/measured"
    with pytest.raises(CalibrationError, match="no trials given"):
        calibrate_people([])
    with pytest.raises(ValueError, match="min_trials"):
        calibrate_people(alice, min_trials=0)


def test_a_trial_stopped_halfway_is_refused_though_its_tool_passed_near_the_plans_end(alice):
    """On the Z plan the tool out on its detour passes near the plan's last leg: the nearest point of the plan jumped
    from 46 % to 92 % of its length in one sample, so a person who stopped there read as having reached 92 %. The
    progress is followed sample by sample (each within 2 cm of arc of the last), and the trial is refused."""
    from coassist.experiments.person_calibration import MIN_PROGRESS
    from coassist.scenario.path_model import PathFrame

    (z,) = _run(ALICE, "manual-probe", [31], task="z")
    t = z.trial
    frame = PathFrame(t.reference[np.r_[True, np.any(np.diff(t.reference[:, :2], axis=0) != 0.0, axis=1)], :2])
    s, _ = frame.project(t.pose[:, :2])
    k = int(np.argmax(s >= 0.55 * frame.length))  # the sample the nearest vertex jumps past 55 %
    assert s[k] / frame.length > 0.9 and s[k - 1] / frame.length < MIN_PROGRESS  # the jump itself
    pose = t.pose.copy()
    pose[k:] = pose[k]  # the person holds still from there
    stopped = Named(
        "lab/stopped", _trial(t, pose=pose, velocity=np.where(np.arange(len(pose))[:, None] >= k, 0.0, t.velocity))
    )
    rest = _run(ALICE, "manual-probe", [32, 33, 34], task="z")
    calibrate_people(rest + [z])  # the whole trial: accepted
    # a plan recorded at 1 Hz (its vertices up to 9 cm apart, farther than the 2 cm followed a sample): accepted too
    sparse = [
        Named(
            f"{n.id}-1hz",
            _trial(n.trial, reference=n.trial.reference[(np.arange(len(n.trial.reference)) // 125) * 125]),
        )
        for n in rest + [z]
    ]
    calibrate_people(sparse)
    with pytest.raises(CalibrationError, match=r"alice: trial lab/stopped: the tool moved \d+ mm and reached 4\d % of"):
        calibrate_people(rest + [stopped])


def _along(waypoints, n: int, until: float = 1.0) -> np.ndarray:
    """(n, 2) points walked along the polyline ``waypoints`` at an even pace up to the share ``until`` of its length
    (then held there)."""
    w = np.asarray(waypoints, dtype=float)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(w, axis=0), axis=1))])
    s = np.minimum(np.linspace(0.0, cum[-1], n), until * cum[-1])
    return np.stack([np.interp(s, cum, w[:, 0]), np.interp(s, cum, w[:, 1])], axis=1)


def test_the_progress_is_read_along_the_plans_segments_whatever_its_vertices(alice):
    """Hand-built plans and tools (alice's recordings otherwise): a plan of three waypoints, stopped at 26 % of it, is
    refused as 26 % (its nearest vertex, half-way, had read 50 %); a plan that doubles back on itself, followed to its
    end, is accepted (on a tie the later vertex: the return leg; it had read 38 %); a tool that moves 4 cm between two
    samples (a trial recorded at a few hertz) is followed (it had read about half)."""

    def trial(base, waypoints, *, held=False, until=1.0, every=1, tool=None):
        """``base`` with the plan ``waypoints`` (walked densely, or each waypoint held a share of the trial) and the
        tool walked along it (or along the waypoints ``tool``) up to ``until`` (a new position every ``every``
        samples)."""
        n = base.n_samples
        w = np.asarray(waypoints, dtype=float)
        ref = base.reference.copy()
        ref[:, :2] = w[np.minimum(np.arange(n) * len(w) // n, len(w) - 1)] if held else _along(w, n)
        pose = base.pose.copy()
        pose[:, :2] = np.repeat(_along(w if tool is None else tool, -(-n // every), until), every, axis=0)[:n]
        return _trial(base, reference=ref, pose=pose)

    bases = [t.trial for t in alice]
    three = [(0.0, 0.0), (0.25, 0.0), (0.25, 0.25)]
    plans = [Named(f"lab/three-{i}", trial(b, three, held=True)) for i, b in enumerate(bases[:3])]
    calibrate_people(plans)
    stopped = Named("lab/three-stopped", trial(bases[3], three, held=True, until=0.26))
    with pytest.raises(
        CalibrationError, match=r"lab/three-stopped: the tool moved \d+ mm and reached 26 % of the plan"
    ):
        calibrate_people([*plans, stopped])
    back = [(0.0, 0.0), (0.3, 0.0), (0.1, 0.0), (0.1, 0.3)]
    calibrate_people([Named(f"lab/back-{i}", trial(b, back)) for i, b in enumerate(bases[:3])])
    line = [(0.0, 0.0), (0.5, 0.0)]  # the tool on by about 4 cm every 170th sample
    calibrate_people([Named(f"lab/coarse-{i}", trial(b, line, every=170)) for i, b in enumerate(bases[:3])])
    # a detour round the Z's diagonal back along its first leg (a large obstacle passed on the far side), then down
    # and along the last leg to the target: followed sample by sample the progress read going back along the first
    # leg (48 % of a simulated Z trial that ended at its target); a tool that ends at the plan's end reached it
    zig = [(0.0, 0.0), (0.3, 0.0), (0.0, -0.3), (0.35, -0.3)]
    round_back = [(0.0, 0.0), (0.3, 0.0), (-0.05, 0.01), (-0.05, -0.3), (0.35, -0.3)]
    calibrate_people([Named(f"lab/z-{i}", trial(b, zig, tool=round_back)) for i, b in enumerate(bases[:3])])
    stopped = Named("lab/z-stopped", trial(bases[3], zig, tool=round_back, until=0.7))  # held on the way down
    with pytest.raises(CalibrationError, match=r"lab/z-stopped: the tool moved \d+ mm and reached \d+ % of the plan"):
        calibrate_people(
            [*[Named(f"lab/z-{i}", trial(b, zig, tool=round_back)) for i, b in enumerate(bases[:3])], stopped]
        )


def test_a_sensor_spike_a_copy_and_a_recording_cut_short_are_refused_naming_them(alice):
    first = alice[0].trial
    w = first.wrench.copy()
    w[500, 0] += 300.0  # one sample: a sensor spike (the thesis lab's recordings: isolated samples of 2 N at most)
    with pytest.raises(CalibrationError, match=r"alice: trial lab/spike: at sample 500 the hand force is 300 N out of"):
        calibrate_people([*alice, Named("lab/spike", _trial(first, wrench=w))])
    w[500, 0] -= 285.0  # 15 N: a person may, at most, jerk the handle so
    calibrate_people([*alice, Named("lab/jerk", _trial(first, wrench=w))])
    with pytest.raises(
        CalibrationError, match=r"alice: trials lab/alice-linear-0 and lab/copy hold the same recording"
    ):
        calibrate_people([*alice, Named("lab/copy", first)])
    # the same start and line, the plan 45 % shorter: the recording was stopped early, and the line says so
    n = int(0.55 * first.n_samples)
    cut = Trial(
        meta=first.meta, time=first.time[:n], pose=first.pose[:n], velocity=first.velocity[:n],
        wrench=first.wrench[:n], reference=first.reference[:n], effort_r=first.effort_r[:n],
    )  # fmt: skip
    with pytest.raises(
        CalibrationError, match=r"trial lab/cut's stops short; was its recording stopped before the end"
    ):
        calibrate_people([*alice, Named("lab/cut", cut)])
    # the short one first, on a plan that turns (the curve): the same line (it had been "follows another nominal path …
    # start every trial from the same place", sending a lab to move the arm's start for nothing: review, 2026-12-06)
    zs = _run(ALICE, "manual-probe", [32, 33, 34], task="curved")
    z = zs[0].trial
    n = int(0.4 * z.n_samples)  # its plan 0.41 of 0.60 m: the rest of the curve 3.2 cm off its last vertex's normal
    cut_z = Trial(
        meta=z.meta, time=z.time[:n], pose=z.pose[:n], velocity=z.velocity[:n], wrench=z.wrench[:n],
        reference=z.reference[:n], effort_r=z.effort_r[:n],
    )  # fmt: skip
    for order in ([Named("lab/cut-z", cut_z), *zs[1:]], [*zs[1:], Named("lab/cut-z", cut_z)]):
        with pytest.raises(
            CalibrationError, match=r"trial lab/cut-z's stops short; was its recording stopped before the end"
        ):
            calibrate_people(order)


def test_the_arm_is_measured_on_a_rigid_object_and_used_only_where_it_says_enough(alice, monkeypatch):
    """Probe trials on the board (its mount twists in series with the arm) are left out of the arm's fit, and said;
    a measurement at the bound of a person's range (identify_arm clips to it) gives the typical arm, and says why, as
    the study's calibration block does (measured_arm)."""
    from coassist.experiments import person_calibration
    from coassist.scenario.arm_identification import ArmEstimate

    board = _run(ALICE, "manual-probe", range(40, 43), obj="board")
    (c,) = calibrate_people([*alice, *board])
    assert c.fit.arm == identify_arm([t.trial for t in alice]) and c.probe_trials == 7  # the handle's four alone
    line = summary_line(c)
    assert "measured by the probe in 4 trial(s) (3 probe trial(s) on the board left out of the arm's fit" in line
    (c,) = calibrate_people(board)
    assert c.fit.arm == ASSUMED_ARM
    assert (
        "arm ASSUMED, not measured (K̂ 800 N/m, Ĉ 10.0 N·s/m): 3 probe trial(s) on the board left out" in summary_line(c)
    )
    # a world that holds every object rigidly (the MuJoCo UR5): no twist in series, the board's probes measure the arm
    # (they were left out there too, and the line asked for the handle: a review, 2026-12-07)
    from coassist.data import TrialMeta

    rigid = [
        Named(t.id, replace(t.trial, meta=TrialMeta(**{**t.trial.meta.to_dict(), "origin": "mujoco"}))) for t in board
    ]
    (c,) = calibrate_people(rigid)
    assert c.fit.arm == identify_arm([t.trial for t in rigid]) and c.fit.arm.method == "probe-iv"
    assert "left out" not in summary_line(c)
    assert person_calibration.probes_for_arm([t.trial for t in rigid]) == ([t.trial for t in rigid], "")
    clipped = ArmEstimate(
        stiffness=5000.0, damping=20.0, stiffness_se=800.0, damping_se=3.0, trials=4, method="probe-iv"
    )
    monkeypatch.setattr(person_calibration, "identify_arm", lambda trials: clipped)
    (c,) = calibrate_people(alice)
    assert c.fit.arm == ASSUMED_ARM
    assert summary_line(c).startswith(
        "alice (linear, 4 trials): arm ASSUMED (K̂ 800 N/m, Ĉ 10.0 N·s/m): the probe measured K = 5000 ± 800 N/m, "
        "C = 20.0 ± 3.0 N·s/m from 4 trials: at the bound of a person's range;"
    )


def test_the_main_jobs_fits_decide_the_arm_as_calibrate_does(alice, monkeypatch):
    """fit_people (the report's calibrations) uses a measured arm only where calibrate would: the report's person
    model is the one a lab gets. A measurement at the bound of a person's range gives the typical arm there too."""
    from coassist.scenario import person_model
    from coassist.scenario.arm_identification import ArmEstimate

    trials = [t.trial for t in alice]
    (fit,) = person_model.fit_people(trials).values()
    assert fit.arm == identify_arm(trials) and fit.arm.method == "probe-iv"
    clipped = ArmEstimate(
        stiffness=120.0, damping=-100.0, stiffness_se=30.0, damping_se=9.0, trials=4, method="probe-iv"
    )
    monkeypatch.setattr(person_model, "identify_arm", lambda trials: clipped)
    (fit,) = person_model.fit_people(trials).values()
    assert fit.arm == ASSUMED_ARM


def test_a_figure_that_cannot_be_written_leaves_the_model_there_was(alice, tmp_path):
    data = write_dataset([t.trial for t in alice], tmp_path / "cal", "cal")
    out = tmp_path / "my model"
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(out)])
    assert res.exit_code == 0 and f"--intent '{out}'" in res.output  # quoted: a path with a space copies whole
    before = (out / "person-model.json").read_bytes()
    (out / "person-model.png").unlink()
    (out / "person-model.png").mkdir()
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(out), "--overwrite"])
    assert res.exit_code == 2 and "person-model.png is a folder" in res.output
    assert (out / "person-model.json").read_bytes() == before and [
        p.name for p in out.iterdir() if p.name.startswith(".")
    ] == []
    # a model that cannot be written: the folder as it was, the figure too
    (out / "person-model.png").rmdir()
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output
    figure = (out / "person-model.png").read_bytes()
    (out / "person-model.json").unlink()
    (out / "person-model.json").mkdir()  # in the way of the model's write
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(out), "--overwrite"])
    assert res.exit_code == 1 and "cannot write person-model.json" in res.output and "nothing changed" in res.output
    assert (out / "person-model.png").read_bytes() == figure


def test_the_command_writes_a_person_model_drive_can_load(alice, bob, tmp_path):
    data = write_dataset([t.trial for t in (*alice, *bob)], tmp_path / "cal", "cal")
    out = tmp_path / "model"
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(out)])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[0].startswith("alice (linear, 4 trials): arm K̂ ") and "measured by the probe" in lines[0]
    assert lines[1].startswith("bob (linear, 3 trials): arm ASSUMED")
    assert f"--intent {out}" in res.output
    # and the figure of what was learnt, beside the model
    figure = out / "person-model.png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"{figure}: each person's paths and arm" in res.output
    source = read_person_model(out)
    direct = calibrate_people(alice)[0].fit
    assert source.arms["alice"] == direct.arm and source.arms["bob"] == ASSUMED_ARM
    assert np.array_equal(source.paths["alice"].weights, direct.paths.weights)
    # a second run does not replace it silently; bad options are told before any work
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(out)])
    assert res.exit_code == 2 and "already holds a person model; pass --overwrite" in res.output
    assert runner.invoke(app, ["calibrate", str(data), "--out", str(out), "--overwrite"]).exit_code == 0
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(tmp_path / "m2"), "--min-trials", "0"])
    assert res.exit_code == 2 and "--min-trials must be >= 1" in res.output
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(tmp_path / "m3"), "--min-trials", "4"])
    assert res.exit_code == 2 and "error: bob: 3 trial(s) of task 'linear'" in res.output
    assert "a person model needs at least 4 (--min-trials)" in " ".join(res.output.split())  # the option named
    assert not (tmp_path / "m3").exists()
    res = runner.invoke(app, ["calibrate", str(tmp_path / "nothing"), "--out", str(tmp_path / "m4")])
    assert res.exit_code == 2 and "nothing: no such file or folder" in res.output


def test_calibrate_refuses_what_would_be_a_model_worse_than_none(alice, tmp_path):
    """From a review of a lab's flow: trials that never left the plan gave a model holding the tool to it (12.6 mm of
    overshoot against MG's 2.2 and nominal's 10.7); trials of two worlds were fitted into one; MuJoCo trials got the
    board's yaw mode, which the MuJoCo UR5 (every object held rigidly) does not have (the tool's jerk about doubled);
    an --out holding another intent folder's marker wrote a model --intent never read."""
    from coassist.data import TrialMeta
    from coassist.scenario.intent_registry import INTENT_FOLDERS
    from coassist.scenario.person_model import PERSON_FILTER, read_person_model

    def retagged(trials, **meta):
        return [replace(t.trial, meta=TrialMeta(**{**t.trial.meta.to_dict(), **meta})) for t in trials]

    # along the plan every trial: the pose is the reference (no way round)
    flat = [replace(t.trial, pose=t.trial.reference[:, : t.trial.pose.shape[1]].copy()) for t in alice]
    data = write_dataset(flat, tmp_path / "flat", "flat")
    res = runner.invoke(app, ["calibrate", str(data), "--out", str(tmp_path / "m-flat")])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and "alice: none of their 4 trials went round the obstacle" in said, res.output
    assert not (tmp_path / "m-flat" / "person-model.json").exists()

    mixed = write_dataset(retagged(alice[:2], origin="mujoco") + [t.trial for t in alice[2:]], tmp_path / "mx", "mx")
    res = runner.invoke(app, ["calibrate", str(mixed), "--out", str(tmp_path / "m-mixed")])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and "the trials come from more than one world (mujoco: " in said and "sim: " in said

    # worlds of one filter go together: a UR's exported bags ("real") beside its drive trials ("ur5")
    ur = write_dataset(retagged(alice[:2], origin="real") + retagged(alice[2:], origin="ur5"), tmp_path / "ur", "ur")
    assert runner.invoke(app, ["calibrate", str(ur), "--out", str(tmp_path / "m-ur")]).exit_code == 0
    arm = write_dataset(retagged(alice, origin="mujoco"), tmp_path / "mj", "mj")
    res = runner.invoke(app, ["calibrate", str(arm), "--out", str(tmp_path / "m-mj")])
    assert res.exit_code == 0, res.output
    assert read_person_model(tmp_path / "m-mj").settings == replace(PERSON_FILTER, object_yaw=False)
    sim = write_dataset([t.trial for t in alice], tmp_path / "sim", "sim")
    assert runner.invoke(app, ["calibrate", str(sim), "--out", str(tmp_path / "m-sim")]).exit_code == 0
    assert read_person_model(tmp_path / "m-sim").settings == PERSON_FILTER
    # a simulation's trials beside an arm's (one filter, but a simulated hand measured the arm): refused; the model
    # records the worlds its trials came from, and a run in a world of another kind refuses it (a point-mass or a
    # browser calibration went to a real arm: a review, 2026-12-07)
    sim_ur = write_dataset(retagged(alice[:2], origin="ur5") + [t.trial for t in alice[2:]], tmp_path / "su", "su")
    res = runner.invoke(app, ["calibrate", str(sim_ur), "--out", str(tmp_path / "m-su")])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and "the trials come from more than one world (sim: " in said and "ur5: " in said
    from coassist.scenario.assistance import check_person_world

    assert read_person_model(tmp_path / "m-ur").origins == ("real", "ur5")
    assert read_person_model(tmp_path / "m-sim").origins == ("sim",)
    check_person_world(read_person_model(tmp_path / "m-sim"), "sim", "point-mass", "m-sim")  # its own kind: taken
    check_person_world(read_person_model(tmp_path / "m-ur"), "franka", "franka", "m-ur")  # an arm's: taken at an arm
    for model, origin, world in (("m-sim", "ur5", "ur"), ("m-sim", "franka", "franka"), ("m-ur", "sim", "play")):
        with pytest.raises(
            ValueError, match=rf"intent {model}: the person model was calibrated on trials of .*not of "
        ):
            check_person_world(read_person_model(tmp_path / model), origin, world, model)

    # collect with the model for a simulated person it does not hold: refused before any trial (drive and play
    # refuse theirs; collect ran them on the extrapolated present estimate, 7.4 mm of overshoot against MG's 2.7)
    from coassist.scenario.populations import population_profile

    held = population_profile("thesis", 0).name
    who = population_profile("thesis", 1).name
    write_dataset(retagged(alice, user=held), tmp_path / "as-user-0", "u0")  # alice's trials as the simulated user 0's
    assert (
        runner.invoke(app, ["calibrate", str(tmp_path / "as-user-0"), "--out", str(tmp_path / "m-u0")]).exit_code == 0
    )
    res = runner.invoke(
        app,
        [
            "collect",
            "--out",
            str(tmp_path / "c"),
            "--trials",
            "1",
            "--users",
            "0,1",
            "--intent",
            str(tmp_path / "m-u0"),
        ],
    )
    said = " ".join(res.output.split())
    assert (
        res.exit_code == 2
        and f"--users 1: intent {tmp_path / 'm-u0'}: the person model holds no calibration of" in said
    )
    assert f"{who!r} (it holds {held})" in said and not (tmp_path / "c").exists()
    # on a task whose plan the paths were not recorded on: said (collect ran it on the present estimate silently,
    # its trials naming the person model), and not on the task they were
    for task, other in (("curved", True), ("linear", False)):
        res = runner.invoke(
            app,
            ["collect", "--out", str(tmp_path / f"c-{task}"), "--trials", "1", "--tasks", task, "--intent",
             str(tmp_path / "m-u0")],
        )  # fmt: skip
        said = " ".join(res.output.split())
        assert res.exit_code == 0, res.output
        note = f"{held}'s paths were recorded on another plan than task {task}'s: those trials get the present estimate"
        assert (note in said) == other, said

    shared = tmp_path / "shared"
    shared.mkdir()
    marker = INTENT_FOLDERS["path-hypotheses"].marker
    (shared / marker).write_text("{}")
    res = runner.invoke(app, ["calibrate", str(sim), "--out", str(shared)])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and f"holds {marker}" in said and "a folder of its own" in said
    assert not (shared / "person-model.json").exists()


def test_the_figure_draws_each_persons_demonstrations_by_way_round_and_says_their_arm(alice, bob):
    import matplotlib.pyplot as plt
    from movement_primitives.promp import ProMP

    from coassist.experiments.person_figure import WAY_COLOURS, calibration_panels, person_figure

    people = calibrate_people([*alice, *bob])
    fig = person_figure(calibration_panels(people))
    try:
        axes = [ax for ax in fig.axes if ax.get_visible()]
        assert len(axes) == 2
        for ax, c in zip(axes, people):
            model = c.fit.paths
            lines = {line.get_gid(): line for line in ax.get_lines() if line.get_gid()}
            np.testing.assert_array_equal(lines["plan"].get_xydata(), model.nominal)
            for j, (demo, side) in enumerate(zip(model.demonstrations(), model.sides.tolist())):
                np.testing.assert_array_equal(lines[f"demo-{j}"].get_xydata(), demo)
                assert lines[f"demo-{j}"].get_color() == WAY_COLOURS[side]
            # each way taken: its mean path is the primitive of its demonstrations' mean weights (the ProMP's mean),
            # rendered here by movement_primitives itself on the model's phases (0 … 1, settings.samples of them)
            promp = ProMP(n_dims=2, n_weights_per_dim=model.settings.n_basis)
            phases = np.linspace(0.0, 1.0, model.settings.samples)
            for way in set(model.sides.tolist()):
                mean = promp.trajectory_from_weights(phases, model.weights[model.sides == way].mean(axis=0))
                np.testing.assert_allclose(lines[f"way{way}"].get_xydata(), mean, rtol=0, atol=1e-12)
                assert lines[f"way{way}"].get_color() == WAY_COLOURS[way]
        a, b = (ax.get_title() for ax in axes)
        arm = people[0].fit.arm
        assert a.startswith("alice (linear, 4 trials)") and f"K̂ {arm.stiffness:.0f} ± {arm.stiffness_se:.0f} N/m" in a
        assert b.startswith("bob (linear, 3 trials)") and "arm assumed: K̂ 800 N/m" in b
    finally:
        plt.close(fig)
    with pytest.raises(ValueError, match="at least one"):
        person_figure([])


def test_a_way_shown_in_fewer_than_three_trials_is_named_with_what_to_record():
    assert thin_ways(np.array([1, 1, 1, -1, 1, 1, 1, 1])) == (
        "the right way shown in 1 trial only: the model follows that path alone there; record more going right (asked: --ask-way right)"
    )
    assert thin_ways(np.array([1, -1, 1, -1, 0])) == (
        "the left way shown in 2 trials only: the model follows those 2 paths alone there; record more going left (asked: --ask-way left); "
        "the right way shown in 2 trials only: the model follows those 2 paths alone there; record more going right (asked: --ask-way right)"
    )
    # every way shown three times or more, or never (the present estimate's rows there, not a path of one trial)
    assert thin_ways(np.array([1, 1, 1, -1, -1, -1])) == thin_ways(np.array([1, 1, 1, 0])) == ""
    # a person the model does not lead (the twin check) is followed along no path: only what to record is said
    assert thin_ways(np.array([1, 1, 1, -1, 1, 1, 1, 1]), led=False) == (
        "the right way shown in 1 trial only; record more going right (asked: --ask-way right)"
    )


def test_a_calibration_asks_for_each_thin_way_within_its_budget():
    # a way shown once or twice is asked for until FEW_PATHS (3) paths show it, left first, within the budget; a way
    # never shown is not asked for (the person did not choose it)
    assert ways_to_ask(np.array([1, 1, 1, -1, 1, 1, 1, 1]), 2) == [(-1, 2)]
    assert ways_to_ask(np.array([1, -1, 1, -1, 0]), 2) == [(1, 1), (-1, 1)]
    assert ways_to_ask(np.array([1, -1, 1, -1, 0]), 1) == [(1, 1)]
    assert ways_to_ask(np.array([-1, 1, 1, 1]), 8) == [(-1, 2)]
    assert ways_to_ask(np.array([1, 1, 1, 1]), 8) == ways_to_ask(np.array([-1, 1, 1, 1]), 0) == []
    with pytest.raises(ValueError, match="room"):
        ways_to_ask(np.array([1]), -1)


def test_the_summary_says_how_many_paths_were_asked_for(alice):
    (c,) = calibrate_people(alice)
    paths = c.fit.paths
    asked = replace(c, fit=replace(c.fit, paths=replace(paths, asked=np.arange(len(paths.sides)) < 2)))
    assert f"right ({2} asked for, not in the prior); fit" in summary_line(asked)
    # turned away by the twin check, with a way shown once: the line said "present estimate held" and "the model
    # follows that path alone there" at once (review, 2026-12-06)
    from coassist.scenario.person_model import LeadCheck

    sides = np.where(np.arange(len(paths.sides)) == 0, -1, 1)
    held = replace(
        c,
        fit=replace(
            c.fit,
            paths=replace(paths, sides=sides),
            lead=LeadCheck(follow=False, folds=3, person_mm=6.0, mg_mm=2.0, low_mm=1.5),
        ),
    )
    line = summary_line(held)
    assert "the right way shown in 1 trial only; record more going right" in line and "follows that path" not in line
    assert "asked for" not in summary_line(c)


def _asked(named: Named, way) -> Named:
    meta = TrialMeta(
        **{
            **{k: getattr(named.trial.meta, k) for k in named.trial.meta.__dataclass_fields__},
            "extra": {**named.trial.meta.extra, "asked_way": way},
        }
    )
    return Named(named.id, _trial(named.trial, meta=meta))


def test_a_trial_that_went_the_other_way_than_asked_counts_as_chosen(alice):
    """A path asked for one way joins that way but not the prior; one that went the other way is what the person
    chose against the asking: in the prior, and the summary says so. Against the hand count of the fit's own
    sides (Laplace's rule over the chosen paths)."""
    (plain,) = calibrate_people(alice)
    sides = plain.fit.paths.sides.tolist()
    assert all(s != 0 for s in sides)
    # trials 0 and 1 asked for the way they took, trial 2 asked for the other
    trials = [_asked(alice[0], sides[0]), _asked(alice[1], sides[1]), _asked(alice[2], -sides[2]), alice[3]]
    (c,) = calibrate_people(trials)
    paths = c.fit.paths
    assert paths.sides.tolist() == sides and paths.asked.tolist() == [True, True, False, False]
    assert c.asked_other_way == 1
    chosen = [sides[2], sides[3]]
    left = chosen.count(1)
    assert paths.ways() == pytest.approx({1: (left + 1) / 4, -1: (2 - left + 1) / 4}, abs=1e-12)
    assert "(2 asked for, not in the prior; 1 asked for a way but went the other: counted as chosen)" in (
        summary_line(c)
    )
    # every asked trial went the other way: no path is asked for, the model is the plain one's
    (d,) = calibrate_people([_asked(t, -s) for t, s in zip(alice, sides)])
    assert not d.fit.paths.asked.any() and d.asked_other_way == 4
    assert d.fit.paths.ways() == plain.fit.paths.ways()


@pytest.mark.parametrize("way", [1.0, "left", True, 2, None])
def test_a_bad_asked_way_is_refused_naming_the_trial(alice, way):
    with pytest.raises(CalibrationError, match=r"alice: trial lab/alice-linear-1: meta.extra\['asked_way'\] must be"):
        calibrate_people([alice[0], _asked(alice[1], way), *alice[2:]])


def test_the_summary_names_a_thin_way(alice):
    (c,) = calibrate_people(alice)
    sides = c.fit.paths.sides
    thin = replace(c, fit=replace(c.fit, paths=replace(c.fit.paths, sides=np.where(np.arange(len(sides)) == 0, -1, 1))))
    assert summary_line(thin).endswith(
        "; the right way shown in 1 trial only: the model follows that path alone there; record more going right (asked: --ask-way right)"
    )
    assert ("record more" in summary_line(c)) == bool(thin_ways(sides))


def test_the_summary_says_whether_the_model_leads_the_person(alice):
    from coassist.scenario.person_model import LeadCheck

    (c,) = calibrate_people(alice)
    # these trials name no control preset: not replayed against a twin, the person led, and the line says why
    assert c.fit.lead is not None and c.fit.lead.follow and c.fit.lead.folds == 0
    assert "lead not checked" in summary_line(c) and "control preset" in summary_line(c)
    held = replace(c, fit=replace(c.fit, lead=LeadCheck(follow=False, folds=4, person_mm=5.04, mg_mm=1.96)))
    assert (
        "; present estimate held (the lead did not pay): their twin overshot 5.0 mm with the lead, 2.0 mm under MG "
        "(4 trials replayed)" in summary_line(held)
    )


def test_a_trial_the_safety_layer_held_to_its_limits_is_refused_naming_it(alice):
    """A probe trial whose motion the safety layer limited on half its ticks (a low --tool-speed) was fitted as if
    the arm had answered the probe: K̂ 453 N/m where the same trials unlimited gave 727 (review, 2026-12-06). More
    than MAX_LIMITED of its ticks limited: refused, naming the trial, the share and the limits; a few: fitted."""
    from coassist.experiments.person_calibration import MAX_LIMITED
    from coassist.interfaces import Fault

    first = _run(ALICE, "manual-probe", [7])[0].trial  # a fifth trial (a copy of one of the four is refused)
    n = first.n_samples
    fault = np.zeros(n, dtype=np.int64)
    fault[: n // 2] = int(Fault.TOOL_SPEED_LIMIT)
    fault[n // 2 : n // 2 + 10] = int(Fault.JOINT_ACCELERATION_LIMIT | Fault.PREDICTION_STALE)
    with pytest.raises(
        CalibrationError,
        match=r"alice: trial lab/slow: the safety layer limited the tool's motion on 50 % of its ticks "
        r"\(JOINT_ACCELERATION_LIMIT, TOOL_SPEED_LIMIT\)",
    ):
        calibrate_people([*alice, Named("lab/slow", _trial(first, fault=fault))])
    few = np.zeros(n, dtype=np.int64)
    few[: int(MAX_LIMITED * n)] = int(Fault.TOOL_SPEED_LIMIT)  # a clip at a fast turn: fitted
    few[-50:] = int(Fault.PREDICTION_STALE)  # not a limit of the motion
    calibrate_people([*alice, Named("lab/clip", _trial(first, fault=few))])
