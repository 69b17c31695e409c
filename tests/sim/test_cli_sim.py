"""The thin CLI commands over the simulator: collect and show."""

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import default_real_data, read_dataset

REAL = default_real_data() / "user-a" / "trial_1"
runner = CliRunner()


def test_collect_then_show(tmp_path):
    out = tmp_path / "D0"
    res = runner.invoke(
        app,
        [
            "collect",
            "--out",
            str(out),
            "--tasks",
            "linear,curved",
            "--trials",
            "1",
            "--users",
            "0,1",
            "--seed",
            "5",
            "--workers",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    ds = read_dataset(out)
    assert ds.id == "D0" and len(ds) == 4
    assert [t.meta.seed for t in ds.trials] == [5, 6, 7, 8]
    assert [t.meta.user for t in ds.trials] == ["user-0", "user-0", "user-1", "user-1"]
    png = tmp_path / "view.png"
    res = runner.invoke(app, ["show", str(out), "--index", "1", "--out", str(png)])
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 10_000


def test_collect_a_population(tmp_path):
    # --population: the drawn operators, named so, each trial recording its family and the trial's parameters
    out = tmp_path / "varied"
    args = ["collect", "--out", str(out), "--tasks", "linear", "--trials", "1", "--users", "0,1", "--workers", "1"]
    res = runner.invoke(app, [*args, "--population", "varied", "--population-seed", "2"])
    assert res.exit_code == 0, res.output
    ds = read_dataset(out)
    assert [t.meta.user for t in ds.trials] == ["varied-user-0", "varied-user-1"]
    families = [t.meta.extra["operator"]["detour"]["family"] for t in ds.trials]
    assert families == ["asymmetric", "skewed"]
    assert [t.meta.extra["intent_detour"]["family"] for t in ds.trials] == families
    res = runner.invoke(app, [*args, "--population", "tesis", "--out", str(tmp_path / "y")])
    assert res.exit_code != 0 and "--population" in res.output


def test_collect_rejects_bad_options(tmp_path):
    res = runner.invoke(app, ["collect", "--out", str(tmp_path / "x"), "--tasks", "circle"])
    assert res.exit_code != 0 and "tasks" in res.output
    res = runner.invoke(app, ["collect", "--out", str(tmp_path / "x"), "--controller", "nash"])
    assert res.exit_code != 0 and "controller" in res.output


@pytest.mark.real_data
@pytest.mark.skipif(not REAL.exists(), reason="real recordings not available")
def test_show_a_real_recording(tmp_path):
    png = tmp_path / "real.png"
    res = runner.invoke(app, ["show", str(REAL), "--out", str(png)])
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 10_000


def test_a_way_asked_for_is_recorded_and_calibrate_counts_its_paths_but_not_as_the_persons_choice(tmp_path):
    # the lab's flow for a way shown too seldom: more trials with --ask-way, then calibrate all of them
    from coassist.scenario.path_model import ASKED_WAY
    from coassist.scenario.person_model import read_person_model

    args = ["collect", "--controller", "manual-probe", "--tasks", "curved", "--obstacle", "large", "--users", "1"]
    args += ["--workers", "1"]
    res = runner.invoke(app, [*args, "--trials", "3", "--out", str(tmp_path / "chosen")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, [*args, "--trials", "2", "--seed", "50", "--ask-way", "right", "--out", str(tmp_path / "a")]
    )
    assert res.exit_code == 0, res.output
    chosen, asked = read_dataset(tmp_path / "chosen").trials, read_dataset(tmp_path / "a").trials
    assert all(ASKED_WAY not in t.meta.extra for t in chosen)
    assert [(t.meta.extra[ASKED_WAY], t.meta.extra["intent_side"]) for t in asked] == [(-1, -1), (-1, -1)]
    out = tmp_path / "model"
    res = runner.invoke(app, ["calibrate", str(tmp_path / "chosen"), str(tmp_path / "a"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "(2 asked for, not in the prior)" in res.output
    other = runner.invoke(app, ["calibrate", str(tmp_path / "chosen"), "--task", "z", "--out", str(tmp_path / "m2")])
    assert other.exit_code == 2 and "--task z: no trial of task 'z'" in other.output, other.output
    paths = read_person_model(out).paths["user-1"]
    assert paths.asked.tolist() == [False, False, False, True, True]
    left = int(sum(paths.sides[:3] == 1))
    assert paths.ways() == pytest.approx({1: (left + 1) / 5, -1: (3 - left + 1) / 5})
    res = runner.invoke(app, [*args, "--trials", "1", "--ask-way", "up", "--out", str(tmp_path / "b")])
    assert res.exit_code == 2 and "--ask-way" in res.output and "left" in res.output
    # assisted by the model; the same command again continues (here: finds complete) only the same model's
    # collection: after calibrating again (other trials, another model) it refuses the folder, and collects anew
    # with --overwrite (it once found the old model's trials complete: nothing to do)
    helped = [*args[:2], "cooperative-arbitrated", *args[3:], "--trials", "1", "--seed", "90", "--intent", str(out)]
    helped += ["--out", str(tmp_path / "helped")]
    first = runner.invoke(app, helped)
    again = runner.invoke(app, helped)
    assert first.exit_code == again.exit_code == 0 and "nothing to do" in again.output, again.output
    before = read_dataset(tmp_path / "helped").trials[0]
    res = runner.invoke(app, ["calibrate", str(tmp_path / "chosen"), "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output
    refused = runner.invoke(app, helped)
    assert refused.exit_code == 1 and "--overwrite" in refused.output, refused.output
    anew = runner.invoke(app, [*helped, "--overwrite"])
    assert anew.exit_code == 0 and "nothing to do" not in anew.output, anew.output
    after = read_dataset(tmp_path / "helped").trials[0]
    assert not np.array_equal(after.reference, before.reference) or not np.array_equal(after.pose, before.pose)
