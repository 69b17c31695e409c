"""A path-hypotheses calibration is bounded like a limit (issue 42): every field in the range a person
(and a filter for people) can have, numbers only, the file hashed; and no calibration inside the
ranges makes the robot push harder than the robot with no prediction or with the default calibration.

The issue's probe (bdc84ed): ``arm.stiffness = 1e-300`` or ``arm.damping = 1e300`` made the robot push
about 100 N (10.7 N normally); ``sigma``, ``divergence`` or ``shape_grid`` at 1e±300 26–32 N; a
``shape_grid`` of 10 000 factors crashed after 70 s; ``search_window = 1e300`` cost 7× the compute;
the string ``"0.03"`` was taken as a number. Each is refused here, naming the field.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from coassist.control.presets import get_preset, make_controller
from coassist.runtime.episode import run_episode
from coassist.scenario.objects import get_object
from coassist.scenario.operator import operator_profile
from coassist.scenario.path_hypotheses import (
    CALIBRATION_FILE,
    CALIBRATION_RANGES,
    MAX_SHAPE_GRID,
    ArmGuess,
    FilterSettings,
    PathHypothesesIntent,
    PersonShape,
    calibrate,
    read_calibration,
    write_calibration,
)
from coassist.scenario.tasks import task_for_seed
from coassist.sim.trial_runner import build_trial

CLASSES = (PersonShape, ArmGuess, FilterSettings)


def _build(name: str, value):
    cls = {c.__name__: c for c in CLASSES}[name.split(".")[0]]
    return cls(**{name.split(".")[1]: value})


def _rewrite(folder, edit) -> None:
    """Edit a calibration file's content and hash it again (as a writer that means it would)."""
    from coassist._io import HASH_KEY, read_hashed_json, write_hashed_json

    path = folder / CALIBRATION_FILE
    fmt = json.loads(path.read_text())["format"]
    doc = read_hashed_json(path, format=fmt)
    edit(doc)
    assert HASH_KEY not in doc
    write_hashed_json(path, doc, format=fmt)


# -------------------------------------------------------------------------- the ranges


def test_every_field_has_a_range_and_every_calibration_the_project_writes_is_inside():
    fields = {f"{c.__name__}.{f.name}" for c in CLASSES for f in dataclasses.fields(c)}
    assert set(CALIBRATION_RANGES) == fields
    for cls in CLASSES:  # the defaults
        for f in dataclasses.fields(cls):
            lo, hi = CALIBRATION_RANGES[f"{cls.__name__}.{f.name}"]
            values = f.default if f.name != "shape_grid" else FilterSettings().shape_grid
            assert all(lo <= v <= hi for v in np.atleast_1d(values)), f.name
    # calibrate() on fit_detour's grids (5 mm–8 cm, 3–30 cm; 13 values each), at their extremes
    for fits in ([(1, 0.005, 0.03)] * 3, [(-1, 0.08, 0.30)], [(1, 0.005, 0.30), (-1, 0.08, 0.03)] * 50):
        shape = calibrate(fits)
        assert shape == PersonShape(shape.clearance, shape.anticipation, shape.left_preference, shape.trials)
    # the simulated population's own shapes (clearance 1–5 cm, anticipation 5–20 cm)
    for user in range(40):
        p = operator_profile(user)
        PersonShape(p.clearance, p.anticipation, min(max(p.left_preference, 0.01), 0.99))


@pytest.mark.parametrize("name", sorted(CALIBRATION_RANGES))
def test_each_field_takes_its_range_and_refuses_beyond_it_and_any_non_number(name):
    lo, hi = CALIBRATION_RANGES[name]
    field = name.split(".")[1]
    if name == "FilterSettings.shape_grid":
        for grid in ((lo, 1.0), (1.0, hi), (lo, 1.0, hi)):
            assert _build(name, grid).shape_grid == grid
        bad = [(math.nextafter(lo, 0.0), 1.0), (1.0, math.nextafter(hi, 9.0)), ("0.5", 1.0), (True, 1.0)]
    elif name == "PersonShape.trials":
        assert _build(name, int(lo)).trials == lo and _build(name, int(hi)).trials == hi
        bad = [int(lo) - 1, int(hi) + 1, 3.0, "3", True]
    elif name == "PersonShape.left_preference":
        assert _build(name, 1e-9).left_preference == 1e-9
        bad = [0.0, 1.0, "0.5", True]
    else:
        assert getattr(_build(name, lo), field) == lo and getattr(_build(name, hi), field) == hi
        bad = [math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf), math.nan, math.inf, "0.03", True, None]
    for value in bad:
        with pytest.raises(ValueError, match=name.replace(".", r"\.")):
            _build(name, value)


@pytest.mark.parametrize(
    "name, value",
    [
        ("ArmGuess.stiffness", 1e-300),
        ("ArmGuess.damping", 1e300),
        ("FilterSettings.sigma", 1e-300),
        ("FilterSettings.sigma", 1e300),
        ("FilterSettings.divergence", 1e300),
        ("FilterSettings.divergence", 1e-300),
        ("FilterSettings.shape_grid", (1.0, 1e300)),
        ("FilterSettings.shape_grid", (1e-300, 1.0)),
        ("FilterSettings.shape_grid", tuple(np.linspace(0.5, 2.0, 10_000))),
        ("FilterSettings.search_window", 1e300),
        ("PersonShape.clearance", "0.03"),
        ("ArmGuess.damping", True),
    ],
)
def test_the_issue_s_values_are_refused_in_one_line_naming_the_field(name, value):
    with pytest.raises(ValueError, match=name.replace(".", r"\.")) as info:
        _build(name, value)
    assert "\n" not in str(info.value) and len(str(info.value)) < 300


def test_a_shape_grid_must_span_the_person_s_own_shape_with_at_most_nine_factors():
    with pytest.raises(ValueError, match="span the person's own shape"):
        FilterSettings(shape_grid=(1.2, 1.6))
    with pytest.raises(ValueError, match=f"1 to {MAX_SHAPE_GRID} factors"):
        FilterSettings(shape_grid=tuple(np.linspace(0.5, 2.0, MAX_SHAPE_GRID + 1)))
    assert len(FilterSettings(shape_grid=tuple(np.linspace(0.5, 2.0, MAX_SHAPE_GRID))).shape_grid) == MAX_SHAPE_GRID


# -------------------------------------------------------------------------- the file


def test_a_calibration_file_is_checked_where_it_is_read(tmp_path):
    folder = write_calibration(tmp_path / "paths", {"p01": PersonShape(0.03, 0.12, 0.7, 4)})
    assert read_calibration(folder).shapes["p01"] == PersonShape(0.03, 0.12, 0.7, 4)
    path = folder / CALIBRATION_FILE
    text = path.read_text()
    # a hand edit, the hash left as it was: refused in one line naming the file
    path.write_text(text.replace('"stiffness": 800.0', '"stiffness": 1e-300'))
    with pytest.raises(ValueError) as info:
        read_calibration(folder)
    assert str(info.value).startswith(f"{path}: its content does not match its 'sha256'")
    path.write_text(text)
    # a file without the hash (written before it, or by hand): refused, saying how to get a good one
    doc = json.loads(text)
    del doc["sha256"]
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="carries no 'sha256'.*write it again with coassist"):
        read_calibration(folder)
    path.write_text(text)
    # hashed again after the edit (a writer that means it): the range and type checks still refuse
    for edit, field in (
        (lambda d: d["arm"].update(stiffness=1e-300), "ArmGuess.stiffness"),
        (lambda d: d["settings"].update(sigma="0.002"), "FilterSettings.sigma"),
        (lambda d: d["shapes"]["p01"].update(clearance=True), "PersonShape.clearance"),
        (lambda d: d["settings"].update(shape_grid=[1.0] + [1.0 + k * 1e-4 for k in range(1, 10_000)]), "shape_grid"),
        (lambda d: d["settings"].update(colour=1), "colour"),
        (lambda d: d["shapes"].update(p02=[0.03]), "shapes\\['p02'\\]"),
        (lambda d: d.update(arm=5), "arm must be an object"),
    ):
        path.write_text(text)
        _rewrite(folder, edit)
        with pytest.raises(ValueError, match=field) as info:
            read_calibration(folder)
        assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)


# -------------------------------------------------------------------------- the robot's force

#: The short trials of the fuzz: (task, trial seed, operator, object), every path once.
SCENARIOS = (
    ("sinusoidal", 5, 1, "board"),
    ("z", 7, 3, "heavy"),
    ("linear", 0, 0, "handle"),
    ("curved", 3, 2, "handle"),
)
#: [s] the planned motion over the 0.5 m paths: 6 s, faster than the thesis' 10–20 s (a harder test, and short)
MOTION_TIME = 6.0
#: [N] what a calibration may add to the worse of the default calibration and no prediction at all: 30 %
#: of the robot's 100 N effort limit (the issue's stiffness of 1e-300 drove the robot to it). The ranges
#: held the slow fuzz's worst to 8.3 N and 12.7 N (docs/precision.md, section 5); below them the arm
#: guess alone exceeds it (150 N/m: +38 N on the Z).
TOLERANCE = 30.0


def _peak_force(source, scenario, preset: str = "thesis-evaluation-dm") -> float:
    """The largest robot force |u_r| [N] of a short point-mass trial (cooperative controller)."""
    task, seed, user, obj = scenario
    episode = build_trial(
        task_for_seed(task, seed, motion_time=MOTION_TIME),
        operator_profile(user),
        get_object(obj),
        make_controller("cooperative", get_preset(preset)),
        source,
        seed,
        time_limit=MOTION_TIME + 1.0,
    )
    return float(np.max(np.linalg.norm(run_episode(episode).effort_r, axis=1)))


def _draw(rng: np.random.Generator) -> tuple[PersonShape, ArmGuess, FilterSettings]:
    """A calibration inside the ranges: each field at its lowest, its highest (a quarter of the time
    each) or in between (log-uniform where the range is positive); a shape grid of 1–9 factors."""

    def value(name: str) -> float:
        lo, hi = CALIBRATION_RANGES[name]
        u = rng.random()
        if name == "PersonShape.left_preference":
            return 0.001 if u < 0.25 else 0.999 if u < 0.5 else float(rng.uniform(0.001, 0.999))
        if name == "PersonShape.trials":
            return int(rng.integers(0, 20))
        if u < 0.5:
            return lo if u < 0.25 else hi
        return float(np.exp(rng.uniform(math.log(lo), math.log(hi)))) if lo > 0 else float(rng.uniform(lo, hi))

    lo, hi = CALIBRATION_RANGES["FilterSettings.shape_grid"]
    n = int(rng.integers(1, MAX_SHAPE_GRID + 1))
    grid = tuple(sorted({1.0, *np.exp(rng.uniform(math.log(lo), math.log(hi), n - 1)).tolist()}))
    names = {c: [f.name for f in dataclasses.fields(c) if f.name != "shape_grid"] for c in CLASSES}
    shape = PersonShape(**{f: value(f"PersonShape.{f}") for f in names[PersonShape]})
    arm = ArmGuess(**{f: value(f"ArmGuess.{f}") for f in names[ArmGuess]})
    settings = FilterSettings(**{f: value(f"FilterSettings.{f}") for f in names[FilterSettings]}, shape_grid=grid)
    return shape, arm, settings


def _fuzz(n: int, seed: int, preset: str, scenarios=SCENARIOS) -> list[tuple[float, float, tuple]]:
    """(peak force, the worse of the default calibration and no prediction, calibration) of n calibrations
    drawn from ``seed``, the scenarios in turn."""
    rng = np.random.default_rng(seed)
    ref: dict[tuple, float] = {}
    out = []
    for i in range(n):
        scenario = scenarios[i % len(scenarios)]
        if scenario not in ref:
            ref[scenario] = max(
                _peak_force(PathHypothesesIntent(50), scenario, preset), _peak_force(None, scenario, preset)
            )
        shape, arm, settings = _draw(rng)
        source = PathHypothesesIntent(50, shapes={f"user-{scenario[2]}": shape}, arm=arm, settings=settings)
        out.append((_peak_force(source, scenario, preset), ref[scenario], (scenario, shape, arm, settings)))
    return out


def test_no_calibration_inside_the_ranges_makes_the_robot_push_harder():
    """Six calibrations drawn inside the ranges (corners and between) on the board's sinusoid and the heavy
    load's Z: the robot's peak force stays within TOLERANCE of the worse of the default calibration and no
    prediction; the same trial with a stiffness below the range pushes past it (the bound is not vacuous)."""
    results = _fuzz(6, seed=42, preset="thesis-evaluation-dm", scenarios=SCENARIOS[:2])
    for force, ref, calibration in results:
        assert force <= ref + TOLERANCE, calibration
    z, z_ref = results[1][2][0], results[1][1]
    soft = object.__new__(ArmGuess)  # what the old ranges let through: built past the check
    object.__setattr__(soft, "stiffness", 150.0)
    object.__setattr__(soft, "damping", 10.0)
    assert _peak_force(PathHypothesesIntent(50, arm=soft), z) > z_ref + TOLERANCE


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["thesis-evaluation-dm", "thesis-application-damped"])
def test_no_calibration_inside_the_ranges_makes_the_robot_push_harder_many(preset):
    results = _fuzz(120, seed=7, preset=preset)
    worst = max(results, key=lambda r: r[0] - r[1])
    assert worst[0] <= worst[1] + TOLERANCE, worst
