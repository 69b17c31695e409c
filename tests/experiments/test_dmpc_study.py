"""The dMPC study reproduces the thesis' three observations (§5.2.1), and its checker can say no."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.experiments.dmpc_study import CaseResult, SweepConfig, check_observations, run_sweep


@pytest.fixture(scope="module")
def result():
    return run_sweep(SweepConfig())


def error(result, alpha, R_r, horizon):
    (case,) = [c for c in result.cases if (c.alpha, c.R_r, c.horizon) == (alpha, R_r, horizon)]
    return case.rms_error_human


def test_higher_alpha_tracks_the_human_reference_more_closely(result):
    for R_r in (0.01, 5e-4, 1e-4):
        for horizon in (5, 20, 50):
            e = [error(result, a, R_r, horizon) for a in (0.2, 0.5, 0.9)]
            assert e[0] > e[1] > e[2], (R_r, horizon, e)


def test_lower_robot_effort_weight_tracks_better(result):
    for alpha in (0.2, 0.5, 0.9):
        for horizon in (5, 20, 50):
            e = [error(result, alpha, R_r, horizon) for R_r in (0.01, 5e-4, 1e-4)]
            assert e[0] > e[1] > e[2], (alpha, horizon, e)


def test_longer_horizon_tracks_better(result):
    for alpha in (0.2, 0.5, 0.9):
        for R_r in (0.01, 5e-4, 1e-4):
            e = [error(result, alpha, R_r, h) for h in (5, 20, 50)]
            assert e[0] > e[1] > e[2], (alpha, R_r, e)


def test_effects_are_large_with_scaling_and_tiny_in_si_units(result):
    # α = 0.9 at Np = 50, R_r = 1e-4 tracks sin t within a few cm; at Np = 5, R_r = 0.01 it barely moves.
    assert error(result, 0.9, 1e-4, 50) < 0.06
    assert error(result, 0.9, 0.01, 5) > 0.6
    si = [c.rms_error_human for c in result.si_cases]
    assert min(si) > 0.6 and max(si) < 0.7  # in SI units the tip hardly follows sin t in any case
    # with α = 0.9 the tip settles near the α-weighted target 0.95 sin t (cooperative compromise)
    x = result.trajectories[(0.9, 1e-4, 50)]
    t = result.time
    late = t > 5
    assert np.max(np.abs(x[late] - 0.95 * np.sin(t[late]))) < 0.08


def test_observation_checker_reports_a_counterexample():
    cfg = SweepConfig(alphas=(0.2, 0.9), robot_effort_weights=(0.01,), horizons=(5,))
    cases = (
        CaseResult(0.2, 0.01, 5, rms_error_human=0.1, rms_error_robot=0, rms_effort_human=0, rms_effort_robot=0),
        CaseResult(0.9, 0.01, 5, rms_error_human=0.2, rms_error_robot=0, rms_effort_human=0, rms_effort_robot=0),
    )
    verdict = check_observations(cfg, cases)
    assert not verdict["higher_alpha_tracks_human_reference"]["holds"]
    assert verdict["higher_alpha_tracks_human_reference"]["counterexamples"] == [[0.01, 5]]


def test_sweep_command_writes_the_figure_and_summary(tmp_path):
    out = tmp_path / "sweep"
    res = CliRunner().invoke(app, ["sweep", "--out", str(out), "--duration", "2"])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["cases"]) == 27 and len(summary["si_units"]["cases"]) == 27
    assert {"rms_error_human", "rms_error_robot"} <= set(summary["cases"][0])
    assert (out / "dmpc_sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sweep_command_rejects_bad_options(tmp_path):
    res = CliRunner().invoke(app, ["sweep", "--out", str(tmp_path), "--duration", "-1"])
    assert res.exit_code != 0
    assert "duration" in res.output


def test_observation_on_a_single_valued_axis_is_not_applicable():
    cfg = SweepConfig(alphas=(0.5,), robot_effort_weights=(0.01,), horizons=(5, 20))
    cases = tuple(
        CaseResult(0.5, 0.01, h, rms_error_human=e, rms_error_robot=0, rms_effort_human=0, rms_effort_robot=0)
        for h, e in ((5, 0.3), (20, 0.2))
    )
    verdict = check_observations(cfg, cases)
    assert verdict["higher_alpha_tracks_human_reference"]["holds"] is None
    assert verdict["longer_horizon_tracks_better"]["holds"] is True


@pytest.mark.parametrize(
    "field, value",
    [
        ("alphas", (1.5,)),
        ("alphas", "0.5"),
        ("alphas", ()),
        ("horizons", (0,)),
        ("horizons", (5.5,)),
        ("horizons", (float("nan"),)),
        ("robot_effort_weights", (float("inf"),)),
        ("position_scale", 0.0),
        ("position_scale", 1e20),  # finite, but the game's Hessian is no longer positive definite (a traceback once)
        ("velocity_weight", float("nan")),
        ("human_amplitude", float("inf")),
    ],
)
def test_config_validation(field, value):
    with pytest.raises(ValueError, match=field):
        SweepConfig(**{field: value})
