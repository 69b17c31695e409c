"""The train / evaluate commands end to end on a tiny written dataset."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import write_dataset

from .conftest import make_trial


def test_train_then_evaluate(tmp_path):
    write_dataset([make_trial(i, n=220) for i in range(5)], tmp_path / "D0", "D0")
    runner = CliRunner()
    res = runner.invoke(
        app,
        [
            "train",
            str(tmp_path / "D0"),
            "--out",
            str(tmp_path / "m"),
            "--epochs",
            "1",
            "--threads",
            "1",
            "--batch-size",
            "256",
        ],
    )
    assert res.exit_code == 0, res.output
    hist = json.loads((tmp_path / "m" / "history.json").read_text())
    assert len(hist) == 1 and (tmp_path / "m" / "loss.png").stat().st_size > 1000
    res = runner.invoke(app, ["evaluate", "--model", str(tmp_path / "m"), "--data", str(tmp_path / "D0")])
    assert res.exit_code == 0, res.output
    out = json.loads((tmp_path / "m" / "evaluation.json").read_text())
    assert set(out["results"]) == {"model", "nominal", "constant_velocity", "constant_acceleration", "ridge"}
    side = json.loads((tmp_path / "m" / "model.json").read_text())
    assert out["trials"] == side["test_trials"] and len(out["trials"]) == 1  # the held-out trial only


def test_bad_options_are_reported(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["train", str(tmp_path), "--out", str(tmp_path / "m"), "--preset", "huge"])
    assert res.exit_code != 0 and "--preset 'huge': no such intent-model preset" in res.output
    res = runner.invoke(app, ["train", str(tmp_path), "--out", str(tmp_path / "m"), "--init", "warm:x"])
    assert res.exit_code != 0 and "--init must be" in res.output and "train.init" not in res.output


def test_train_command_sets_the_torch_threads_it_is_given(tmp_path):
    # train_model leaves torch's global state alone; the command is where --threads applies.
    import torch

    write_dataset([make_trial(i, n=220) for i in range(3)], tmp_path / "D0", "D0")
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        res = CliRunner().invoke(
            app,
            [
                "train",
                str(tmp_path / "D0"),
                "--out",
                str(tmp_path / "m"),
                "--epochs",
                "1",
                "--threads",
                "2",
                "--batch-size",
                "256",
            ],
        )
        assert res.exit_code == 0, res.output
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_train_says_when_its_threads_would_share_busy_cores(tmp_path, monkeypatch):
    """Two torch threads beside other work wait for each other at every step: `coassist train` ran 80 s where one
    thread took 18 s (a review, 2026-12-06). The command says so where the cores are busy, and changes nothing."""
    from coassist.cli import _threads

    write_dataset([make_trial(i, n=220) for i in range(3)], tmp_path / "D0", "D0")
    args = ["train", str(tmp_path / "D0"), "--epochs", "1", "--batch-size", "256"]
    said = {}
    for idle in (0.3, 2.0):
        monkeypatch.setattr(_threads, "idle_cores", lambda idle=idle: idle)
        res = CliRunner().invoke(app, [*args, "--out", str(tmp_path / f"m{idle}")])
        assert res.exit_code == 0, res.output
        said[idle] = " ".join(res.output.split())
    assert "note: 0.3 of this machine's" in said[0.3] and "--threads 1 trains alone on one" in said[0.3]
    assert "note:" not in said[2.0]
    res = CliRunner().invoke(app, [*args, "--threads", "1", "--out", str(tmp_path / "one")])  # one thread: nothing
    assert res.exit_code == 0 and "note:" not in res.output
    monkeypatch.undo()
    measured = _threads.idle_cores(0.05)  # the measurement itself: a number of cores, where /proc/stat is read
    import os

    assert measured is None or -1e-9 <= measured <= (os.cpu_count() or 1) + 1e-9


def test_a_model_another_run_writes_meanwhile_is_not_replaced(tmp_path, monkeypatch):
    """Two trainings into one --out: the check for a model there ran before the lock, so the second to take it
    replaced the first's finished model without --overwrite (review, 2026-12-06). Checked again under the lock."""
    import shutil

    from coassist.cli import intent as intent_cli

    write_dataset([make_trial(i, n=220) for i in range(3)], tmp_path / "D0", "D0")
    args = ["train", str(tmp_path / "D0"), "--epochs", "1", "--batch-size", "256", "--threads", "1"]
    first = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "other")])
    assert first.exit_code == 0, first.output
    out = tmp_path / "m"

    def the_other_run_finishes(threads, option="--threads"):  # between the check and the lock
        shutil.copytree(tmp_path / "other", out)

    monkeypatch.setattr(intent_cli, "busy_cores_hint", the_other_run_finishes)
    res = CliRunner().invoke(app, [*args, "--seed", "5", "--out", str(out)])
    assert res.exit_code == 2 and "another coassist run wrote a model there meanwhile" in res.output, res.output
    assert (out / "model.json").read_bytes() == (tmp_path / "other" / "model.json").read_bytes()  # kept


def test_a_start_the_training_cannot_take_or_would_not_honour_is_refused(tmp_path):
    """--init from a linear model ended in torch's "optimizer got an empty parameter list"; --preset intent (or
    linear) with --init resume: trained the starting model's network on its own label without a word (review,
    2026-12-06). Both refused in one line; a preset of the same label gives its training settings, as before."""
    write_dataset([make_trial(i, n=220) for i in range(3)], tmp_path / "D0", "D0")
    base = ["train", str(tmp_path / "D0"), "--epochs", "1", "--batch-size", "256", "--threads", "1"]
    for name, preset in (("lin", "linear"), ("net", "default")):
        made = CliRunner().invoke(app, [*base, "--preset", preset, "--out", str(tmp_path / name)])
        assert made.exit_code == 0, made.output
    res = CliRunner().invoke(app, [*base, "--init", f"transfer:{tmp_path / 'lin'}", "--out", str(tmp_path / "a")])
    assert (
        res.exit_code == 2
        and "is a linear model (the tuned ridge alone, closed form): nothing to transfer" in res.output
    )
    for preset in ("intent", "linear"):
        res = CliRunner().invoke(
            app, [*base, "--preset", preset, "--init", f"resume:{tmp_path / 'net'}", "--out", str(tmp_path / "b")]
        )
        said = " ".join(res.output.split())
        assert (
            res.exit_code == 2
            and f"--preset {preset}: --init resume: keeps the starting model's network and label" in said
        )
    res = CliRunner().invoke(
        app, [*base, "--preset", "lstm", "--init", f"finetune:{tmp_path / 'net'}", "--out", str(tmp_path / "c")]
    )
    assert res.exit_code == 0, res.output  # the same label: its training settings


def test_tune_makes_its_database_folder_and_prints_the_command_it_measured(tmp_path):
    """A --storage SQLite file in a folder not made yet ended in a traceback ("unable to open database file"), and
    the printed train command left out the study's --preset and --epochs: it trained another configuration than the
    one scored (review, 2026-12-06)."""
    write_dataset([make_trial(i, n=220) for i in range(4)], tmp_path / "D0", "D0")
    db = tmp_path / "new" / "deeper" / "study.db"
    res = CliRunner().invoke(
        app,
        [
            "tune",
            str(tmp_path / "D0"),
            "--trials",
            "1",
            "--epochs",
            "1",
            "--preset",
            "lstm",
            "--storage",
            f"sqlite:///{db}",
        ],
    )
    assert res.exit_code == 0, res.output
    assert db.is_file()
    line = next(x for x in res.output.splitlines() if x.startswith("train with them:"))
    assert " --preset lstm --epochs 1 " in line, line


def test_one_recording_given_twice_under_two_ids_is_refused(tmp_path):
    """A dataset and one of its own files (ids labA/trial_00001 and Dx/trial_00001) trained on one copy and tested on
    the other (review, 2026-12-06): refused naming both. (Copies of one recording in two files are not looked for.)"""
    write_dataset([make_trial(i, n=220) for i in range(3)], tmp_path / "Dx", "labA")
    res = CliRunner().invoke(
        app,
        ["train", str(tmp_path / "Dx"), str(tmp_path / "Dx" / "trial_00001.parquet"), "--epochs", "1",
         "--out", str(tmp_path / "m")],
    )  # fmt: skip
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and f"trial_00001.parquet is one of the trials of {tmp_path / 'Dx'}, given too" in said, (
        said
    )
