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
