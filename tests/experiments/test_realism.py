"""The realism statistics and report."""

import numpy as np
import pytest

from coassist.data import Trial, TrialMeta, default_real_data
from coassist.experiments.realism import (
    family_table,
    population_table,
    run_realism,
    summary_table,
    trial_stats,
    turn_stats,
    write_report,
)

REAL = default_real_data() / "user-a"


def _trial():
    t = np.arange(0, 2.0, 0.01)
    ref = np.column_stack([t * 0.25, np.zeros_like(t)])  # 0.5 m along x
    pose = ref.copy()
    pose[:, 1] = 0.05 * np.sin(np.pi * t / 2.0)  # up to 5 cm off the path
    wrench = np.zeros((len(t), 2))
    wrench[:, 0] = 3.0
    wrench[50, 1] = 4.0  # one tick of |f| = 5 N
    meta = TrialMeta(
        user="u", task="linear", object="handle", controller="c", model_id=None, seed=None, origin="real", dt=0.01
    )
    return Trial(meta=meta, time=t, pose=pose, velocity=np.zeros_like(pose), wrench=wrench, reference=ref)


def test_trial_stats_by_hand():
    s = trial_stats(_trial())
    assert s["duration"] == pytest.approx(1.99)
    assert s["peak_force"] == pytest.approx(5.0)
    assert s["mean_force"] == pytest.approx((3.0 * 199 + 5.0) / 200)
    assert s["peak_deviation"] == pytest.approx(0.05, abs=2e-3)
    expected_length = np.sum(np.linalg.norm(np.diff(_trial().pose, axis=0), axis=1))
    assert s["path_length"] == pytest.approx(expected_length)


def test_turn_stats_by_hand():
    # a circle of radius 0.1 m at 0.05 m/s: sideways acceleration v²/R = 0.025 m/s² (a cubic Savitzky-Golay
    # filter differentiates the circle to ~1e-4 relative over a 0.2 s window: 0.5 % tolerance)
    t = np.arange(0.0, 6.0, 0.008)
    R, v = 0.1, 0.05
    circle = R * np.column_stack([np.cos(v / R * t), np.sin(v / R * t)])
    s = turn_stats(t, circle, np.zeros(len(t)))
    assert s["peak_sideways_accel"] == pytest.approx(v * v / R, rel=5e-3)
    assert s["submovements"] == 0  # constant speed: no peak
    # two minimum-jerk strokes one after the other: two speed peaks; a straight line: no sideways acceleration
    tau = np.clip(t / 3.0, 0, 1)
    stroke = tau**3 * (10 - 15 * tau + 6 * tau**2)
    x = 0.1 * stroke + 0.1 * np.clip(np.where(t > 3.0, (t - 3.0) / 3.0, 0.0), 0, 1) ** 3 * (
        10 - 15 * np.clip((t - 3.0) / 3.0, 0, 1) + 6 * np.clip((t - 3.0) / 3.0, 0, 1) ** 2
    )
    line = np.column_stack([x, np.zeros_like(x)])
    s = turn_stats(t, line, np.zeros(len(t)))
    assert s["submovements"] == 2 and s["peak_sideways_accel"] == pytest.approx(0.0, abs=1e-9)
    # return overshoot: out to +5 cm, back through the path to −1.2 cm, then on it
    dev = np.interp(t, [0, 2, 4, 5, 6], [0.0, 0.05, -0.012, 0.0, 0.0])
    assert turn_stats(t, line, dev)["return_overshoot"] == pytest.approx(0.012, abs=1e-12)
    assert turn_stats(t, line, -dev)["return_overshoot"] == pytest.approx(0.012, abs=1e-12)  # the other side alike


@pytest.mark.real_data
@pytest.mark.skipif(not REAL.exists(), reason="real recordings not available")
def test_realism_report(tmp_path):
    result = run_realism(
        REAL, presets=("thesis-evaluation",), tasks=("linear",), trials_per_task=1, workers=1, progress=False
    )
    assert len(result.real) == 15 and len(result.sim["thesis-evaluation"]["linear"]) == 1
    table = summary_table(result)
    assert "peak ‖f‖" in table and "thesis-evaluation" in table
    out = write_report(result, tmp_path / "realism.md", notes="## Notes\n\nhello")
    text = out.read_text()
    assert text.startswith("# Realism check") and "hello" in text


@pytest.mark.real_data
@pytest.mark.skipif(not REAL.exists(), reason="real recordings not available")
def test_realism_of_the_populations(tmp_path):
    result = run_realism(
        REAL,
        presets=(),
        tasks=("linear",),
        trials_per_task=1,
        workers=1,
        progress=False,
        populations=("varied", "held-out"),
        population_users=(0, 1),
        population_trials=1,
    )
    assert [f for f, _ in result.populations["varied"]] == ["asymmetric", "skewed"]
    assert [f for f, _ in result.populations["held-out"]] == ["corrective", "hesitant"]
    table = population_table(result)
    assert "varied (n = 2)" in table and "held-out (n = 2)" in table and "sub-movements" in table
    families = family_table(result)
    assert "| held-out | hesitant | 1 |" in families and "| real user-a | — | 15 |" in families
    text = write_report(result, tmp_path / "realism.md").read_text()
    assert "--population varied --population held-out --population-users 0,1" in text
    with pytest.raises(ValueError, match="population must be one of"):
        run_realism(REAL, presets=(), tasks=("linear",), progress=False, populations=("all",))


def test_realism_replaces_only_an_earlier_report(tmp_path):
    """`realism --out data.csv` overwrote the lab's data with the report (review, 2026-12-06): only a file the command
    wrote is replaced (the repository's docs/realism.md is one), and a name must end in .md; refused before any work."""
    from pathlib import Path

    from typer.testing import CliRunner

    from coassist.cli import app
    from coassist.experiments.realism import is_realism_report

    docs = Path(__file__).resolve().parents[2] / "docs" / "realism.md"
    assert is_realism_report(docs)
    notes = tmp_path / "notes.md"
    notes.write_text("# my notes\n")
    real = tmp_path / "real"
    real.mkdir()
    for out, says in ((notes, "is not a file this command wrote"), (tmp_path / "data.csv", "give a .md file")):
        res = CliRunner().invoke(app, ["realism", "--out", str(out), "--real", str(real), "--trials", "1"])
        assert res.exit_code != 0 and says in " ".join(res.output.split()), res.output
    assert notes.read_text() == "# my notes\n" and not is_realism_report(notes)
