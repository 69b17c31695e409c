"""Iterative (two rounds) and transfer studies with simulated participants: the models train in a background
process while the next trials wait, and each equals what ``coassist train`` makes from the same trials."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("torch", reason="the study's models need the learn extra")

from safetensors.numpy import load_file  # noqa: E402

from coassist.cli import app  # noqa: E402
from coassist.data import read_dataset  # noqa: E402
from coassist.study.folder import init_study  # noqa: E402
from coassist.study.runner import ParticipantRun  # noqa: E402

TRAINING = """
[training]
preset = "default"
epochs = 1
seed = 0
threads = 1
layers = 1
hidden = 8
fc = [8]
"""
TRIALS = """
[trials]
tasks = ["linear", "curved"]
per_condition = 1
practice = 0
motion_time = 3.0
dwell = 1.0

[rest]
between_conditions = 30.0
"""
TRAIN_OPTIONS = ["--preset", "default", "--epochs", "1", "--seed", "0", "--threads", "1"]
SIZES = ["--layers", "1", "--hidden", "8", "--fc", "8"]


def _same_weights(a: Path, b: Path) -> None:
    """The network's weights and the ridge baseline's, tensor by tensor, bit for bit."""
    for name in ("weights.safetensors", "ridge.safetensors"):
        wa, wb = load_file(str(a / name)), load_file(str(b / name))
        assert wa.keys() == wb.keys() and wa
        for k in wa:
            assert np.array_equal(wa[k], wb[k]), f"{name}: {k}"


def _cli_train(*args: str) -> None:
    result = CliRunner().invoke(app, ["train", *args])
    assert result.exit_code == 0, result.output


def test_an_iterative_study_of_two_rounds_trains_what_coassist_train_trains(tmp_path):
    plan = tmp_path / "iterative.toml"
    plan.write_text(
        '[study]\nname = "iter"\nprotocol = "iterative"\nworld = "play"\nparticipants = 1\n\n'
        "[iterative]\nrounds = 2\ntrials_per_round = 3\ntolerance = 1e-9\n" + TRIALS + TRAINING
    )
    study = init_study(plan, tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
        assert run.complete
    pf = study.participant("S01")
    lines = pf.progress()
    kinds = [r["kind"] for r in lines]
    # each round rated before its stop check (a check that ends the protocol left the converged round unrated)
    assert kinds == ["trial"] * 3 + ["questionnaire", "train", "rest"] + ["trial"] * 3 + [
        "questionnaire",
        "check",
        "train",
    ]
    train0 = lines[4]
    assert train0["model"] == "M0" and train0["init"] == "scratch"
    assert train0["ready_when_recorded"] is False  # the runner went on while M0 trained in its own process
    first_of_round1 = lines[6]
    assert first_of_round1["model"] == "M0"  # round 1 collected with M0 in the loop, once it was ready
    round1 = read_dataset(pf.block("round-1")).trials
    assert all(t.meta.model_id and t.meta.model_id.startswith("M0@") for t in round1)
    assert all(t.meta.model_id is None for t in read_dataset(pf.block("round-0")).trials)  # D0: the nominal plan
    check = lines[10]
    assert check["round"] == 1 and check["met"] is False  # the criterion of eq. 4.13 (a tolerance nobody meets)
    assert abs(check["e_rms"] - check["e_rms_before"]) == pytest.approx(check["delta"])
    # the models equal coassist train's from the same trials
    m0, m1 = pf.folder / "models" / "M0", pf.folder / "models" / "M1"
    # the session estimate's count of training windows is the one M0 trained on (its kept trials' ticks)
    import json

    from coassist.study.preflight import training_windows

    meta = json.loads((m0 / "model.json").read_text())
    ds = read_dataset(pf.block("round-0"))
    kept = [t.n_samples for f, t in zip(ds.files, ds.trials) if f"S01/round-0/{Path(f).stem}" in meta["train_trials"]]
    assert 1 <= len(kept) < 3
    assert training_windows(kept, 125, 50, 4, 0.0) == meta["n_train_windows"]
    _cli_train(str(pf.block("round-0")), "--out", str(tmp_path / "cli-M0"), *TRAIN_OPTIONS, *SIZES)
    _same_weights(m0, tmp_path / "cli-M0")
    _cli_train(str(pf.block("round-1")), "--out", str(tmp_path / "cli-M1"), "--init", f"resume:{m0}", *TRAIN_OPTIONS)
    _same_weights(m1, tmp_path / "cli-M1")
    assert lines[11]["command"][:2] == ["coassist", "train"] and f"resume:{m0}" in lines[11]["command"]
    from coassist.study.report import write_report

    html, _ = write_report(study.folder)
    assert "the stop criterion (eq. 4.13)" in html.read_text() and "M1" in html.read_text()


def _contents(folder: Path) -> dict[str, bytes]:
    return {str(f.relative_to(folder)): f.read_bytes() for f in sorted(folder.rglob("*")) if f.is_file()}


@pytest.fixture(scope="module")
def _source_model(tmp_path_factory) -> Path:
    """A small model of the default preset's window (1 x 8 LSTM) trained by coassist train on a simulated study's trials.

    Made once for the module (a simulated study and a training): the tests that use it only read it, and
    :func:`source_model` checks that they did."""
    tmp_path = tmp_path_factory.mktemp("source-model")
    plan = tmp_path / "collect.toml"
    plan.write_text(
        '[study]\nname = "d0"\nprotocol = "comparison"\nworld = "play"\nparticipants = 1\n\n'
        '[[condition]]\nname = "a"\ncontroller = "cooperative"\n[[condition]]\nname = "m"\ncontroller = "manual"\n'
        + TRIALS.replace("per_condition = 1", "per_condition = 3")
    )
    study = init_study(plan, tmp_path / "d0")
    with ParticipantRun(study, "S09", simulate=True) as run:
        run.run()
    pf = study.participant("S09")
    _cli_train(str(pf.block("a")), str(pf.block("m")), "--out", str(tmp_path / "source"), *TRAIN_OPTIONS, *SIZES)
    return tmp_path / "source"


@pytest.fixture
def source_model(_source_model) -> Iterator[Path]:
    """The module's source model (:func:`_source_model`); after the test, its folder must be as it was."""
    before = _contents(_source_model)
    yield _source_model
    assert _contents(_source_model) == before, "a test changed the shared source model"


def test_a_transfer_study_trains_the_frozen_lstm_transfer_as_coassist_train(tmp_path, source_model):
    plan = tmp_path / "transfer.toml"
    plan.write_text(
        '[study]\nname = "tl"\nprotocol = "transfer"\nworld = "play"\nparticipants = 2\n\n'
        f'[transfer]\nsource_model = "{source_model}"\ntrials = 3\n' + TRIALS + TRAINING
    )
    study = init_study(plan, tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    pf = study.participant("S01")
    lines = pf.progress()
    assert [r["kind"] for r in lines][:5] == ["trial"] * 3 + ["train", "rest"]
    assert lines[3]["init"] == f"transfer:{source_model}" and lines[3]["ready_when_recorded"] is False
    # the transfer set was collected with the source model in the loop
    assert all(t.meta.model_id.startswith("source@") for t in read_dataset(pf.block("transfer-set")).trials)
    # then the transferred model against the source model, blinded: each a condition with its own label
    labels = study.labels
    assert sorted(labels) == ["source", "transferred"] and sorted(labels.values()) == ["A", "B"]
    trials = {c: read_dataset(pf.block(c)).trials[0] for c in ("source", "transferred")}
    assert trials["transferred"].meta.model_id.startswith("transferred@")
    assert trials["source"].meta.extra["controller_name"] == labels["source"]
    _cli_train(
        str(pf.block("transfer-set")),
        "--out",
        str(tmp_path / "cli-TL"),
        "--init",
        f"transfer:{source_model}",
        *TRAIN_OPTIONS,
    )
    _same_weights(pf.folder / "models" / "transferred", tmp_path / "cli-TL")
    # the frozen LSTM is the source's, bit for bit; the FC head was trained
    src = load_file(str(source_model / "weights.safetensors"))
    tl = load_file(str(pf.folder / "models" / "transferred" / "weights.safetensors"))
    lstm = [k for k in src if k.startswith("lstm")]
    assert lstm and all(np.array_equal(src[k], tl[k]) for k in lstm)
    assert any(not np.array_equal(src[k], tl[k]) for k in src if k.startswith("head"))
    from coassist.study.report import write_report

    html, summary = write_report(study.folder)
    assert "transferred (" in html.read_text() and "transfer-set" in html.read_text()
    # the collection names the model in its loop, the source folder the plan named (it said None: review, 2026-12-06)
    import json

    models = json.loads(summary.read_text())["collections"]["S01"]["transfer-set"]["models"]
    assert len(models) == 3 and all(m.startswith("source@") for m in models), models


def test_online_adaptation_never_delays_the_loop_and_meets_the_offline_transfer(tmp_path, source_model):
    plan = tmp_path / "online.toml"
    plan.write_text(
        '[study]\nname = "online"\nprotocol = "online"\nworld = "play"\nparticipants = 2\n\n'
        f'[online]\nsource_model = "{source_model}"\ntrials = 4\n' + TRIALS + TRAINING
    )
    study = init_study(plan, tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
    pf = study.participant("S01")
    lines = pf.progress()
    adaptation = [r for r in lines if r["kind"] == "trial" and r["block"] == "adaptation"]
    updates = [r for r in lines if r["kind"] == "train" and r["model"].startswith("online-")]
    assert len(adaptation) == 4 and len(updates) == 3
    started = set()
    for r in lines:
        if r["kind"] == "train" and not r.get("deferred"):
            started.add(r["model"])
        if r in adaptation:
            assert r["waited_for_model_s"] < 0.1  # a trial takes the newest model ready, it never waits
            assert r["model"] is None or r["model"] in started  # the source, or an update started before it
    first = updates[0]
    assert not first.get("deferred") and first["init"] == f"transfer:{source_model}"
    assert first["data"] == [str(pf.block("adaptation") / "trial_00000.parquet")]  # the trials so far, as files
    freeze = next(r for r in lines if r["kind"] == "freeze")
    offline = next(r for r in lines if r["kind"] == "train" and r["model"] == "offline")
    assert offline["init"] == f"transfer:{source_model}" and len(offline["data"]) == 4
    # the online and the offline models are each coassist train's on the same trial files
    _cli_train(
        *first["data"], "--out", str(tmp_path / "cli-online-1"), "--init", f"transfer:{source_model}", *TRAIN_OPTIONS
    )
    _same_weights(pf.folder / "models" / "online-1", tmp_path / "cli-online-1")
    _cli_train(
        *offline["data"], "--out", str(tmp_path / "cli-offline"), "--init", f"transfer:{source_model}", *TRAIN_OPTIONS
    )
    _same_weights(pf.folder / "models" / "offline", tmp_path / "cli-offline")
    # then the last online model against the offline transfer, blinded
    online = read_dataset(pf.block("online")).trials[0]
    assert online.meta.model_id.startswith(f"{freeze['model_from']}@")
    assert read_dataset(pf.block("offline")).trials[0].meta.model_id.startswith("offline@")
    from coassist.study.report import write_report

    _, summary = write_report(study.folder)
    assert '"blocks": [\n  "online",\n  "offline"\n ]' in summary.read_text()


def _children(pid: int) -> dict[int, str]:
    """The processes whose parent is ``pid``: pid → command line (Linux /proc)."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == pid:
                out[int(stat.parent.name)] = (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, ValueError, IndexError):
            continue
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="finds the worker through Linux's /proc")
def test_the_training_worker_dies_with_its_run_and_a_resume_follows_at_once(tmp_path):
    """bdc84ed: after a kill -9 of the study run alone, its training worker trained on, then blocked for good
    holding the memory, the model's lock and the pipe; a resume right away was refused ("being written by
    another coassist run")."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from coassist._io import OutputLock

    plan = tmp_path / "iterative.toml"
    plan.write_text(
        '[study]\nname = "iter"\nprotocol = "iterative"\nworld = "play"\nparticipants = 1\n\n'
        "[iterative]\nrounds = 2\ntrials_per_round = 1\n\n[questionnaire]\ntlx = false\nlikert = []\n"
        + TRIALS
        + TRAINING.replace("epochs = 1", "epochs = 1000")  # trains for many seconds
    )
    study = init_study(plan, tmp_path / "study")
    src = Path(__file__).resolve().parents[2] / "src"
    env = {**os.environ, "PYTHONPATH": f"{src}{os.pathsep}{os.environ.get('PYTHONPATH', '')}", "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "coassist.cli", "study", "run", str(study.folder), "-p", "S01", "--simulate"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    pf = study.participant("S01")
    workers: list[int] = []
    try:
        t_end = time.monotonic() + 300  # generous: a busy machine starts processes slowly
        lock = pf.folder / "models" / ".M0.lock"  # taken by the job, once the worker (and its watch) started
        while not (workers and lock.exists()):
            assert proc.poll() is None and time.monotonic() < t_end, "the run did not start M0's training"
            if any(r["kind"] == "train" for r in pf.progress()):
                workers = [p for p, cmd in _children(proc.pid).items() if "spawn_main" in cmd]
            time.sleep(0.05)
        assert not (pf.folder / "models" / "M0" / "model.json").exists()  # M0 is training
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        # the worker checks its parent every 0.2 s; unfixed, it trains on for many seconds, then blocks for good
        t_end = time.monotonic() + 10.0
        while any(_alive(w) for w in workers) and time.monotonic() < t_end:
            time.sleep(0.05)
        assert not any(_alive(w) for w in workers), "the training worker outlived its run"
        # nobody holds the model that was being trained. Polled: a process whose leader /proc shows as a zombie
        # may still be closing its files while its other threads exit (the lock goes with the last of them).
        from coassist._io import OutputBusyError

        while True:
            try:
                with OutputLock(pf.folder / "models" / "M0"):
                    break
            except OutputBusyError:
                assert time.monotonic() < t_end, "the dead worker's lock on M0 outlived it"
                time.sleep(0.05)
        with ParticipantRun(study, "S01", simulate=True) as run:  # a resume right away: not refused
            assert [r["kind"] for r in run.done] == ["trial", "train"]
    finally:
        proc.kill()
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)


def test_an_online_study_stopped_while_an_update_trains_resumes_and_freezes_the_last_update(tmp_path, source_model):
    """A kill -9 while an online update trained (its line recorded, its model not written) left a participant who
    could never go on: every resume stopped at the freeze with "no online model was trained", or, where an earlier
    update had finished, froze that one instead of the last (review, 2026-12-06)."""
    plan = tmp_path / "online.toml"
    plan.write_text(
        '[study]\nname = "online"\nprotocol = "online"\nworld = "play"\nparticipants = 1\n\n'
        f'[online]\nsource_model = "{source_model}"\ntrials = 2\n' + TRIALS + TRAINING
    )
    study = init_study(plan, tmp_path / "study")
    pf = study.participant("S01")
    with pytest.raises(KeyboardInterrupt):  # the stop: right after the last update's line, while training goes on
        with ParticipantRun(study, "S01", simulate=True) as run:
            append = run.folder.append

            def append_then_stop(record):
                append(record)
                if record["kind"] == "train" and record["model"] == "online-1":  # two trials: one update
                    raise KeyboardInterrupt

            run.folder.append = append_then_stop  # type: ignore[method-assign]
            run.run()
    lines = pf.progress()
    assert lines[-1]["kind"] == "train" and lines[-1]["model"] == "online-1"
    started = [r["model"] for r in lines if r["kind"] == "train" and not r.get("deferred")]
    assert started == ["online-1"] and not (pf.folder / "models" / started[-1] / "model.json").exists()  # cut off
    with ParticipantRun(study, "S01", simulate=True) as run:
        run.run()
        assert run.complete
    freeze = next(r for r in pf.progress() if r["kind"] == "freeze")
    assert freeze["model_from"] == started[-1]  # the last update started, trained again
    assert (pf.folder / "models" / started[-1] / "model.json").is_file()
    online = read_dataset(pf.block("online")).trials[0]
    assert online.meta.model_id.startswith(f"{started[-1]}@")
