"""Nothing lost: kills in the middle of every write, concurrent writers, modes, resumes.

Two kinds of kill, both real:

- *SIGKILL*: a child process runs the write and sends itself SIGKILL at a chosen point
  (no ``finally``, no ``atexit``; the same as ``kill -9`` or the OOM killer), then the
  test checks what is on disk;
- *injected exception*: the write is interrupted by an exception at each of its steps
  in turn (every trial file, the manifest, the swap).

After each, the old dataset or model must still load, equal to what was there, and
what the dead writer left (``*.tmp`` files, ``*.new`` folders) is removed by the next
write. A second run on a locked output gets one clear error; files and folders get
the user's umask; ``collect`` and ``train`` continue where a killed run stopped, with
the result of a run never stopped.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from coassist import _io
from coassist._io import OutputBusyError, OutputLock, atomic_write, atomic_write_bytes, partial_folder, remove_stale
from coassist.cli import app
from coassist.data import datasets, read_dataset, write_dataset

from ..intent.conftest import TINY, labeled, make_trial

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals, flock and renameat2")


def run_child(code: str, *, expect_kill: bool = True, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter; with ``expect_kill`` it must die of SIGKILL."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    res = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=timeout, env=env
    )
    if expect_kill:
        assert res.returncode == -signal.SIGKILL, res.stderr
    else:
        assert res.returncode == 0, res.stderr
    return res


KILL = "os.kill(os.getpid(), signal.SIGKILL)"


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith((".tmp", ".new", ".old")))


# --------------------------------------------------------------------------- one file


@pytest.mark.parametrize("step", ["write", "fsync", "replace"])
def test_atomic_write_interrupted_at_each_step_keeps_the_old_file(tmp_path, monkeypatch, step):
    path = tmp_path / "f.json"
    atomic_write_bytes(path, b"old")

    def boom(*args, **kwargs):
        raise RuntimeError(f"injected at {step}")

    if step == "write":
        writer = lambda fh: (fh.write(b"ne"), boom())  # noqa: E731 (half written, then the failure)
    else:
        writer = lambda fh: fh.write(b"new")  # noqa: E731
        monkeypatch.setattr(os, {"fsync": "fsync", "replace": "replace"}[step], boom)
    with pytest.raises(RuntimeError, match="injected"):
        atomic_write(path, writer)
    monkeypatch.undo()
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.json"]


def test_atomic_write_killed_mid_write_keeps_the_old_file_and_the_next_write_sweeps_the_temp(tmp_path):
    path = tmp_path / "f.bin"
    atomic_write_bytes(path, b"old")
    run_child(f"""
        import os, signal
        from coassist._io import atomic_write
        def half(fh):
            fh.write(b"x" * 1_000_000)
            fh.flush()
            {KILL}
        atomic_write({str(path)!r}, half)
    """)
    assert path.read_bytes() == b"old"
    stray = leftovers(tmp_path)
    assert len(stray) == 1 and stray[0].startswith(".f.bin.") and stray[0].endswith(".tmp")  # a dead writer's
    assert (tmp_path / stray[0]).stat().st_size == 1_000_000
    atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"new" and leftovers(tmp_path) == []


def test_remove_stale_spares_a_live_writer(tmp_path):
    mine = tmp_path / f".f.{os.getpid()}.0123abcd.tmp"
    mine.write_bytes(b"being written")
    dead = tmp_path / ".f.999999999.0123abcd.tmp"  # above any pid_max: no such process
    dead.write_bytes(b"left behind")
    assert remove_stale(tmp_path) == [dead]
    assert mine.exists() and not dead.exists()


# --------------------------------------------------------------------------- datasets


def trials(n: int, seed0: int = 0):
    return [make_trial(seed0 + i, n=60) for i in range(n)]


@pytest.fixture
def old_dataset(tmp_path) -> Path:
    return write_dataset(trials(6), tmp_path / "D", "OLD")


@pytest.fixture
def new_source(tmp_path) -> Path:
    """The trials of the NEW dataset, for a child to read (it need not import torch)."""
    return write_dataset(trials(5, seed0=100), tmp_path / "src", "NEW")


def assert_old(folder: Path) -> None:
    ds = read_dataset(folder)
    assert ds.id == "OLD" and len(ds) == 6
    assert all(t.equals(u) for t, u in zip(ds.trials, trials(6)))


@pytest.mark.parametrize("at", [f"trial {i}" for i in range(5)] + ["manifest", "swap"])
def test_overwrite_interrupted_at_each_step_keeps_the_old_dataset(old_dataset, monkeypatch, at):
    calls = {"n": 0}
    real_write_trial, real_manifest, real_swap = datasets.write_trial, datasets._write_manifest, _io.swap_in

    def write_trial(trial, path):
        if at == f"trial {calls['n']}":
            raise RuntimeError("injected")
        calls["n"] += 1
        return real_write_trial(trial, path)

    def manifest(folder, m):
        if at == "manifest":
            raise RuntimeError("injected")
        real_manifest(folder, m)

    def swap(staging, dest):
        if at == "swap":
            raise RuntimeError("injected")
        return real_swap(staging, dest)

    monkeypatch.setattr(datasets, "write_trial", write_trial)
    monkeypatch.setattr(datasets, "_write_manifest", manifest)
    monkeypatch.setattr(_io, "swap_in", swap)
    with pytest.raises(RuntimeError, match="injected"):
        write_dataset(trials(5, seed0=100), old_dataset, "NEW", overwrite=True)
    monkeypatch.undo()
    assert_old(old_dataset)
    assert leftovers(old_dataset.parent) == [] and leftovers(old_dataset) == []


@pytest.mark.parametrize("after_files", [0, 2, 4])
def test_overwrite_killed_mid_way_keeps_the_old_dataset(old_dataset, new_source, after_files):
    """The issue's case: 13 of 30 files replaced and the folder no longer loads. Now the
    new files go to a folder beside, so any kill leaves the old dataset whole."""
    run_child(f"""
        import os, signal
        from coassist.data import datasets
        new = datasets.read_dataset({str(new_source)!r}).trials
        real, n = datasets.write_trial, [0]
        def write_trial(trial, path):
            if n[0] == {after_files}:
                {KILL}
            n[0] += 1
            return real(trial, path)
        datasets.write_trial = write_trial
        datasets.write_dataset(new, {str(old_dataset)!r}, "NEW", overwrite=True)
    """)
    assert_old(old_dataset)
    assert len(leftovers(old_dataset.parent)) == 1  # the dead writer's .new folder ...
    write_dataset(trials(2, seed0=50), old_dataset, "NEXT", overwrite=True)  # ... swept by the next write of D
    assert leftovers(old_dataset.parent) == [] and read_dataset(old_dataset).id == "NEXT"


@pytest.mark.parametrize(
    ("exchange", "kill_at_rename"),
    [(True, 1), (False, 1), (False, 2)],
    ids=["renameat2-after-exchange", "fallback-before-first-rename", "fallback-between-renames"],
)
def test_swap_killed_between_its_renames(old_dataset, new_source, exchange, kill_at_rename):
    """Kill inside swap_in: after the exchange (or the fallback's first rename) and before
    the next rename. The destination then holds the old or the new dataset, whole, and
    the next sweep leaves nothing behind (the fallback's .old folder is put back)."""
    run_child(f"""
        import os, signal, sys
        from coassist import _io
        from coassist.data import read_dataset, write_dataset
        new = read_dataset({str(new_source)!r}).trials
        if not {exchange}:
            _io._exchange = lambda a, b: False
        real, n = os.rename, [0]
        def rename(a, b):
            if "swap_in" in [f.f_code.co_name for f in [sys._getframe(1)]]:
                n[0] += 1
                if n[0] == {kill_at_rename}:
                    {KILL}
            return real(a, b)
        os.rename = rename
        write_dataset(new, {str(old_dataset)!r}, "NEW", overwrite=True)
    """)
    if (exchange, kill_at_rename) == (False, 2):
        assert not old_dataset.exists()  # the worst moment: the old folder is aside, the new not yet in place
    remove_stale(old_dataset.parent)
    ds = read_dataset(old_dataset)
    if ds.id == "OLD":
        assert_old(old_dataset)
    else:
        assert ds.id == "NEW" and all(t.equals(u) for t, u in zip(ds.trials, trials(5, seed0=100)))
    # With renameat2 the first rename after the exchange moves the old folder aside: the new one is in place.
    if exchange:
        assert ds.id == "NEW"
    assert leftovers(old_dataset.parent) == []


# --------------------------------------------------------------------------- models


@pytest.fixture(scope="module")
def two_models():
    from coassist.intent.training import train_model

    data = labeled(3)
    a = train_model(data, TINY, replace(TINY.train, epochs=1))
    b = train_model(data, TINY, replace(TINY.train, epochs=1, seed=7))
    return a, b


def same_weights(m1, m2) -> bool:
    s1, s2 = m1.net.state_dict(), m2.net.state_dict()
    return s1.keys() == s2.keys() and all(torch.equal(s1[k], s2[k]) for k in s1)


@pytest.mark.parametrize("fail_on", ["weights.safetensors", "ridge.safetensors", "model.json"])
def test_model_save_interrupted_between_its_files_keeps_the_old_model(tmp_path, monkeypatch, two_models, fail_on):
    """The issue's case: a crash between the weights and model.json destroyed the old model."""
    from coassist.intent import load_model, save_model
    from coassist.intent import model as model_mod

    old, new = two_models
    save_model(old, tmp_path / "m")
    real = model_mod.atomic_write_bytes

    def write(path, data):
        if Path(path).name == fail_on:
            raise RuntimeError("injected")
        return real(path, data)

    monkeypatch.setattr(model_mod, "atomic_write_bytes", write)
    with pytest.raises(RuntimeError, match="injected"):
        save_model(new, tmp_path / "m")
    monkeypatch.undo()
    assert same_weights(load_model(tmp_path / "m"), old) and not same_weights(old, new)
    assert leftovers(tmp_path) == []


def test_model_save_killed_between_weights_and_sidecar_keeps_the_old_model(tmp_path, two_models):
    from coassist.intent import load_model, save_model

    old, new = two_models
    save_model(old, tmp_path / "m")
    save_model(new, tmp_path / "new")
    run_child(f"""
        import os, signal
        from coassist.intent import load_model, save_model
        from coassist.intent import model as model_mod
        real = model_mod.atomic_write_bytes
        def write(path, data):
            if path.name == "model.json":
                {KILL}
            return real(path, data)
        model_mod.atomic_write_bytes = write
        save_model(load_model({str(tmp_path / "new")!r}), {str(tmp_path / "m")!r})
    """)
    assert same_weights(load_model(tmp_path / "m"), old)
    save_model(new, tmp_path / "m")  # the next save sweeps the dead one's folder
    assert same_weights(load_model(tmp_path / "m"), new) and leftovers(tmp_path) == []


def test_train_refuses_an_existing_model_before_any_work(tmp_path, two_models):
    from coassist.intent import load_model, save_model

    old, _ = two_models
    save_model(old, tmp_path / "m")
    write_dataset([make_trial(i, n=220) for i in range(5)], tmp_path / "D0", "D0")
    runner = CliRunner()
    args = [
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
    ]
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and "--overwrite" in res.output and "Traceback" not in res.output
    assert same_weights(load_model(tmp_path / "m"), old)
    res = runner.invoke(app, [*args, "--overwrite"])
    assert res.exit_code == 0, res.output
    assert not same_weights(load_model(tmp_path / "m"), old)
    assert not partial_folder(tmp_path / "m").exists()  # the run's checkpoint is cleaned up


# --------------------------------------------------------------------------- one writer at a time


def hold_lock_in_child(path: Path, ready: Path) -> subprocess.Popen:
    code = f"""
        import time
        from pathlib import Path
        from coassist._io import OutputLock
        with OutputLock({str(path)!r}):
            Path({str(ready)!r}).write_text("locked")
            time.sleep(60)
    """
    child = subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)])
    for _ in range(600):
        if ready.exists() or child.poll() is not None:
            break
        import time

        time.sleep(0.05)
    assert ready.exists(), "the child never took the lock"
    return child


def test_a_second_writer_gets_a_clear_error_and_a_dead_ones_lock_is_free(tmp_path, old_dataset):
    """The issue's case: two `collect --overwrite` into one folder both printed "wrote"."""
    child = hold_lock_in_child(old_dataset, tmp_path / "ready")
    try:
        with pytest.raises(
            OutputBusyError, match=rf"{old_dataset} is being written by another coassist run \(pid {child.pid}\)"
        ):
            write_dataset(trials(2, seed0=100), old_dataset, "NEW", overwrite=True)
        res = CliRunner().invoke(
            app,
            [
                "collect",
                "--out",
                str(old_dataset),
                "--overwrite",
                "--trials",
                "1",
                "--tasks",
                "linear",
                "--workers",
                "1",
            ],
        )
        assert (
            res.exit_code == 1 and f"pid {child.pid}" in res.output.replace("\n", "") and "Traceback" not in res.output
        )
        assert_old(old_dataset)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    # Killed while holding it: the kernel released the lock, the next writer proceeds.
    write_dataset(trials(2, seed0=100), old_dataset, "NEW", overwrite=True)
    assert read_dataset(old_dataset).id == "NEW"
    assert not (old_dataset.parent / ".D.lock").exists()


def test_a_second_train_into_the_same_folder_gets_a_clear_error(tmp_path):
    write_dataset([make_trial(i, n=220) for i in range(5)], tmp_path / "D0", "D0")
    child = hold_lock_in_child(tmp_path / "m", tmp_path / "ready")
    try:
        res = CliRunner().invoke(
            app, ["train", str(tmp_path / "D0"), "--out", str(tmp_path / "m"), "--epochs", "1", "--threads", "1"]
        )
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert f"is being written by another coassist run (pid {child.pid})" in res.output.replace("\n", "")
    assert not (tmp_path / "m").exists()


def test_lock_nests_within_a_process(tmp_path):
    with OutputLock(tmp_path / "x"), OutputLock(tmp_path / "x"):
        assert (tmp_path / ".x.lock").read_text().strip() == str(os.getpid())
    assert not (tmp_path / ".x.lock").exists()


# --------------------------------------------------------------------------- modes


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_outputs_follow_the_umask(tmp_path, two_models, umask):
    from coassist.intent import save_model

    old_umask = os.umask(umask)
    try:
        folder = write_dataset(trials(2), tmp_path / "D", "D")
        model = save_model(two_models[0], tmp_path / "m")
    finally:
        os.umask(old_umask)
    for path in [
        folder / "manifest.json",
        folder / "trial_00000.parquet",
        model / "model.json",
        model / "weights.safetensors",
    ]:
        assert path.stat().st_mode & 0o777 == 0o666 & ~umask, path
    for path in (folder, model):
        assert path.stat().st_mode & 0o777 == 0o777 & ~umask, path


# --------------------------------------------------------------------------- collect continues


COLLECT = dict(controller="cooperative", users=[0], tasks=["linear"], objects=["handle"], trials=4, seed=3)


def test_collect_killed_after_two_trials_continues_and_matches_an_unbroken_run(tmp_path):
    from coassist.sim import collect as collect_mod
    from coassist.sim.collect import collect_dataset

    out = tmp_path / "D"
    run_child(f"""
        import os, signal
        from coassist.data import datasets
        from coassist.sim.collect import collect_dataset
        real, n = datasets.DatasetWriter.add, [0]
        def add(self, index, trial):
            path = real(self, index, trial)
            n[0] += 1
            if n[0] == 2:
                {KILL}
            return path
        datasets.DatasetWriter.add = add
        collect_dataset({str(out)!r}, workers=1, progress=False, **{COLLECT!r})
    """)
    assert not out.exists()
    partial = partial_folder(out)
    # the trials run in lockstep and are written as each ends: the two shortest, whichever they are
    kept = sorted(p.name for p in partial.glob("trial_*.parquet"))
    assert len(kept) == 2 and set(kept) <= {f"trial_{i:05d}.parquet" for i in range(4)}
    missing = [i for i in range(4) if f"trial_{i:05d}.parquet" not in kept]

    said, ran = [], []
    real_run = collect_mod.run_trials

    def counting_run(specs, **kw):
        ran.extend(specs)
        return real_run(specs, **kw)

    collect_mod.run_trials = counting_run
    try:
        collect_dataset(out, workers=1, progress=False, say=said.append, **COLLECT)
    finally:
        collect_mod.run_trials = real_run
    assert said == [f"continuing: 2 of 4 trials were already written in {partial}"]
    assert [s.seed for s in ran] == [3 + i for i in missing]  # only the two trials the killed run had not written
    assert not partial.exists()
    unbroken = collect_dataset(tmp_path / "U", workers=1, progress=False, **COLLECT)
    a, b = read_dataset(out), read_dataset(unbroken)
    assert len(a) == 4 and all(x.equals(y) for x, y in zip(a.trials, b.trials))


def test_collect_with_other_options_neither_reuses_nor_silently_removes_a_partial_folder(tmp_path):
    """Another collection's unfinished trials in the destination were removed with a line said after the fact (an
    hour's trials lost to a mistyped option): refused naming them and what they were, then discarded only when told
    (overwrite)."""
    from coassist.data import DatasetWriter
    from coassist.sim.collect import collect_dataset

    out = tmp_path / "D"
    with DatasetWriter(out, "D", n_trials=4, key="another collection", description="simulated: 4 board trials") as w:
        w.add(0, make_trial(0))  # then "killed": no finish()
    said = []
    with pytest.raises(FileExistsError) as err:
        collect_dataset(out, workers=1, progress=False, say=said.append, **{**COLLECT, "trials": 1})
    assert str(err.value).startswith(
        f"{partial_folder(out)} holds 1 of 4 finished trials of another, unfinished collection (simulated: 4 board "
        "trials): the command that started it continues it"
    )
    assert str(err.value).endswith("pass overwrite=True") and said == []
    assert (partial_folder(out) / "trial_00000.parquet").is_file()  # nothing lost
    collect_dataset(out, workers=1, progress=False, say=said.append, overwrite=True, **{**COLLECT, "trials": 1})
    assert said == [f"removed the unfinished trials of a different collection in {partial_folder(out)}"]
    assert read_dataset(out).trials[0].meta.task == "linear"


def test_a_collection_loaded_as_written_is_the_dataset_read_back(tmp_path):
    """``collect_dataset(read=True)`` hands over the trials it wrote instead of reading them back (issue 44): the
    same dataset as ``read_dataset`` of its folder, bit for bit, whether it simulated every trial, continued an
    interrupted run (those trials come from their files) or found the collection complete."""
    from coassist.data import DatasetWriter
    from coassist.sim.collect import collect_dataset

    def same(a, b) -> bool:
        return (
            (a.id, a.files, a.skipped) == (b.id, b.files, b.skipped)
            and a.manifest == b.manifest
            and len(a.trials) == len(b.trials)
            and all(x.equals(y) for x, y in zip(a.trials, b.trials))
        )

    out = tmp_path / "D"
    loaded = collect_dataset(out, workers=1, progress=False, read=True, **COLLECT)
    assert same(loaded, read_dataset(out)) and len(loaded) == 4
    assert same(collect_dataset(out, workers=1, progress=False, read=True, **COLLECT), loaded)  # complete: read
    # an interrupted writer's two trials, then a writer of the same collection adds the rest: two from their
    # files, two as written
    again = tmp_path / "E"
    with DatasetWriter(again, "E", n_trials=4, key="k") as w:
        w.add(1, loaded.trials[1])
        w.add(3, loaded.trials[3])
    with DatasetWriter(again, "E", n_trials=4, key="k", keep=True) as w:
        assert w.resumed == [1, 3]
        w.add(0, loaded.trials[0])
        w.add(2, loaded.trials[2])
        with pytest.raises(RuntimeError, match="before finish"):
            w.dataset()
        w.finish()
        resumed = w.dataset()
    assert same(resumed, read_dataset(again))
    assert resumed.trials[0] is loaded.trials[0] and resumed.trials[1] is not loaded.trials[1]


def test_collect_checks_the_output_before_simulating(tmp_path):
    (tmp_path / "afile").write_text("x")
    res = CliRunner().invoke(app, ["collect", "--out", str(tmp_path / "afile" / "sub"), "--trials", "1"])
    assert res.exit_code != 0 and "is a file" in res.output and "Traceback" not in res.output


# --------------------------------------------------------------------------- train continues


def _weights(model) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in model.net.state_dict().items()}


@pytest.mark.parametrize("optimizer", ["adam", pytest.param("sgd", marks=pytest.mark.slow)])
def test_train_two_epochs_then_resume_two_equals_four(tmp_path, optimizer):
    """A 4-epoch run killed (SIGKILL) after epoch 2 and resumed ends bit-identical to an
    unbroken 4-epoch run. Tolerance: none. On the CPU with a fixed thread count the resumed
    run replays the same floating-point operations in the same order (same weights,
    Adam/momentum state, learning-rate step, batch order and mirror signs), so any
    difference is a resume bug. A GPU run may need a tolerance (non-deterministic kernels);
    not tested here. Control: resuming without the optimizer state does differ."""
    from coassist.intent.training import train_model

    data = labeled(4)
    cfg = replace(TINY.train, epochs=4, optimizer=optimizer, mirror=True)
    unbroken = _weights(train_model(data, TINY, cfg))
    out = tmp_path / "m"
    run_child(f"""
        import os, signal, sys
        from dataclasses import replace
        sys.path.insert(0, {str(Path(__file__).parents[1])!r})
        from intent.conftest import TINY, labeled
        from coassist.intent.training import train_model
        def on_epoch(record):
            if record["epoch"] == 2:
                {KILL}
        cfg = replace(TINY.train, epochs=4, optimizer={optimizer!r}, mirror=True)
        train_model(labeled(4), TINY, cfg, checkpoint_to={str(out)!r}, on_epoch=on_epoch)
    """)
    ckpt = json.loads((partial_folder(out) / "checkpoint.json").read_text())
    assert ckpt["epoch"] == 2 and ckpt["scheduler"]["last_epoch"] > 0
    resumed = train_model(data, TINY, replace(cfg, init=f"resume:{out}"), checkpoint_to=out)
    assert [r["epoch"] for r in resumed.info["training_history"]] == [1, 2, 3, 4]
    assert resumed.info["continued_after_epoch"] == [2] and resumed.info["init"] == "scratch"
    got = _weights(resumed)
    assert all(torch.equal(unbroken[k], got[k]) for k in unbroken)

    # Control: the same weights at epoch 2 without the optimizer/schedule/RNG state do not get there.
    (partial_folder(out) / "checkpoint.json").unlink()
    naive = _weights(train_model(data, TINY, replace(cfg, epochs=2, init=f"resume:{partial_folder(out)}")))
    assert max(float((unbroken[k] - naive[k]).abs().max()) for k in unbroken) > 1e-4


def _stopped_after_epoch_1(out, trials=None):
    """A 3-epoch training of ``trials`` (default: four labeled trials), stopped after its first epoch (its checkpoint
    beside ``out``); returns its training configuration."""
    from coassist.intent.training import train_model

    class Stop(Exception):
        pass

    def stop(record):
        if record["epoch"] == 1:
            raise Stop

    cfg = replace(TINY.train, epochs=3)
    with pytest.raises(Stop):
        train_model(labeled(4) if trials is None else trials, TINY, cfg, checkpoint_to=out, on_epoch=stop)
    return cfg


def test_resume_of_an_interrupted_run_with_other_data_is_refused(tmp_path):
    from coassist.intent.training import train_model

    cfg = _stopped_after_epoch_1(tmp_path / "m")
    with pytest.raises(ValueError, match="interrupted run on 4 other trials"):
        train_model(labeled(4, prefix="X", first_seed=300), TINY, replace(cfg, init=f"resume:{tmp_path / 'm'}"))
    # the same ids holding other data (a dataset collected again under the same id): refused too, where it once
    # continued on the new trials with the old ones' scalers
    again = labeled(4)
    again[2] = again[2]._replace(trial=replace(again[2].trial, pose=again[2].trial.pose + 1e-3))
    with pytest.raises(ValueError, match="other data under the same trial ids"):
        train_model(again, TINY, replace(cfg, init=f"resume:{tmp_path / 'm'}"))


def test_resume_on_trials_with_another_robot_effort_is_refused(tmp_path):
    """The hand_alone label's targets are built from the robot's effort u_r and the rendered plant
    (meta.extra["plant"]): a resume on the same ids and poses with another u_r once went on, on other labels."""
    from coassist.intent import LabeledTrial
    from coassist.intent.checkpoint import trials_digest
    from coassist.intent.training import train_model

    def hand(scale=1.0, damping=50.0):
        out = []
        for lt in labeled(4):
            t = lt.trial
            meta = replace(t.meta, extra={"plant": {"M": [10.0, 10.0], "D": [damping, damping], "K": [0.0, 0.0]}})
            effort = scale * 5.0 * np.sin(np.arange(t.n_samples)[:, None] * 0.05 + np.arange(2))
            out.append(LabeledTrial(lt.id, lt.dataset, replace(t, meta=meta, effort_r=effort, effort_h=effort)))
        return out

    preset = replace(TINY, window=replace(TINY.window, label="hand_alone"))
    cfg = replace(preset.train, epochs=3)

    class Stop(Exception):
        pass

    def stop(record):
        if record["epoch"] == 1:
            raise Stop

    with pytest.raises(Stop):
        train_model(hand(), preset, cfg, checkpoint_to=tmp_path / "m", on_epoch=stop)
    digests = {trials_digest(hand()), trials_digest(hand(-3.0)), trials_digest(hand(damping=60.0))}
    assert len(digests) == 3
    for other in (hand(-3.0), hand(damping=60.0)):
        with pytest.raises(ValueError, match="interrupted run on other data under the same trial ids"):
            train_model(other, preset, replace(cfg, init=f"resume:{tmp_path / 'm'}"))
    resumed = train_model(hand(), preset, replace(cfg, init=f"resume:{tmp_path / 'm'}"))
    assert [r["epoch"] for r in resumed.info["training_history"]] == [1, 2, 3]
    # trials without efforts or plant hash as before they were included: such a checkpoint of an older version
    # still resumes
    assert trials_digest(labeled(1)) == "90b7e161826e2f91bf9a619c9a83b903933ecc125ca07c8c57b093e0d62915e0"


def test_resume_with_an_option_other_than_the_interrupted_runs_is_refused(tmp_path):
    """The interrupted run continues on its own configuration: --epochs 6 --lr 0.05 were once silently ignored."""
    from coassist.intent import load_trials
    from coassist.intent.training import train_model

    write_dataset([make_trial(i, n=220) for i in range(4)], tmp_path / "D0", "D0")
    out = tmp_path / "m"
    cfg = _stopped_after_epoch_1(out, load_trials([tmp_path / "D0"]))
    with pytest.raises(ValueError) as err:  # the library: the fields the caller chose (given)
        train_model(
            load_trials([tmp_path / "D0"]), TINY, replace(cfg, epochs=6, init=f"resume:{out}"), given=["epochs"]
        )
    assert str(err.value).startswith(f"train.epochs 6 asked, but {partial_folder(out)} is an interrupted run with ")
    args = ["train", str(tmp_path / "D0"), "--out", str(out), "--init", f"resume:{out}", "--threads", "1"]
    res = CliRunner().invoke(app, [*args, "--lr", "0.05", "--epochs", "3"])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert " ".join(res.output.split()) == (
        f"error: --lr 0.05 asked, but {partial_folder(out)} is an interrupted run with --lr 0.003: continue it "
        "without --lr (it keeps its own), or start a new stage from it with finetune:"
    )
    assert not out.exists() and (partial_folder(out) / "checkpoint.json").is_file()  # the run is still there
    # a preset other than its own was ignored without a word (the run continued on its own: a review, 2026-12-07)
    res = CliRunner().invoke(app, [*args, "--preset", "intent"])
    assert res.exit_code == 2 and " ".join(res.output.split()) == (
        f"error: --preset intent: --init resume:{out} continues an interrupted run on its own settings (preset "
        "tiny): drop --preset, or start a new stage from it with finetune:"
    ), res.output
    res = CliRunner().invoke(app, [*args, "--epochs", "3", "--batch-size", "32"])  # its own values: continued
    assert res.exit_code == 0, res.output
    assert [r["epoch"] for r in json.loads((out / "history.json").read_text())] == [1, 2, 3]


def test_a_rerun_of_an_interrupted_training_says_it_starts_again_and_how_to_continue(tmp_path):
    """The command that was stopped, run again as it was (``--init scratch``), trains from scratch and replaces the
    interrupted run's checkpoint: once silently, so a user took it for the continuation. Now it says so, naming the
    epochs the checkpoint had done and the option that continues it; a resume says nothing of the kind."""
    from coassist.intent import load_trials

    write_dataset([make_trial(i, n=220) for i in range(4)], tmp_path / "D0", "D0")
    out = tmp_path / "m"
    _stopped_after_epoch_1(out, load_trials([tmp_path / "D0"]))
    args = ["train", str(tmp_path / "D0"), "--out", str(out), "--threads", "1", "--batch-size", "32"]
    res = CliRunner().invoke(app, [*args, "--epochs", "2"])
    said = " ".join(res.output.split())
    assert res.exit_code == 0, res.output
    assert (
        f"note: {partial_folder(out)} holds the checkpoint of an interrupted training, 1 of 3 epochs done; this run "
        f"starts again and replaces it (to continue it instead: --init resume:{out})"
    ) in said
    assert [r["epoch"] for r in json.loads((out / "history.json").read_text())] == [1, 2]
    out2 = tmp_path / "m2"
    _stopped_after_epoch_1(out2, load_trials([tmp_path / "D0"]))
    args2 = ["train", str(tmp_path / "D0"), "--out", str(out2), "--threads", "1", "--epochs", "3", "--batch-size", "32"]
    res = CliRunner().invoke(app, [*args2, "--init", f"resume:{out2}"])
    assert res.exit_code == 0 and "interrupted training" not in res.output, res.output


def test_resume_of_a_finished_model_into_its_own_folder_needs_overwrite(tmp_path):
    """`--init resume:M --out M` of a finished M once replaced it without --overwrite (its lineage then naming
    itself); only an interrupted run (a checkpoint beside M) is continued in place without it."""
    from coassist.intent import load_model

    write_dataset([make_trial(i, n=220) for i in range(4)], tmp_path / "D0", "D0")
    out = tmp_path / "m"
    base = ["train", str(tmp_path / "D0"), "--out", str(out), "--epochs", "1", "--threads", "1", "--batch-size", "256"]
    res = CliRunner().invoke(app, base)
    assert res.exit_code == 0, res.output
    before = load_model(out)
    res = CliRunner().invoke(app, [*base, "--init", f"resume:{out}"])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert "already holds files; pass --overwrite to replace it" in " ".join(res.output.split())
    assert same_weights(load_model(out), before) and load_model(out).info["init"] == "scratch"
    res = CliRunner().invoke(app, [*base, "--init", f"resume:{out}", "--overwrite"])  # a new stage, asked for
    assert res.exit_code == 0, res.output
    after = load_model(out)
    assert after.info["init"] == f"resume:{out}" and [r["epoch"] for r in after.info["training_history"]] == [1, 2]


def test_train_overwrite_replaces_a_model_not_a_folder_of_other_files(tmp_path, monkeypatch):
    """`train --out F --overwrite` of a folder holding other files than a model (a thesis.tex, notes/) swapped it out
    whole and deleted them; `--out .` trained, then failed to swap the current folder in (EBUSY) and left a partial
    folder. Both refused before any work now, naming why; every file kept."""
    write_dataset([make_trial(i, n=220) for i in range(4)], tmp_path / "D0", "D0")
    mine = tmp_path / "p4"
    (mine / "notes").mkdir(parents=True)
    (mine / "thesis.tex").write_text("important")
    args = ["train", str(tmp_path / "D0"), "--epochs", "1", "--threads", "1", "--batch-size", "256", "--overwrite"]
    res = CliRunner().invoke(app, [*args, "--out", str(mine)])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert "holds files but no model (no model.json), which --overwrite would delete" in " ".join(res.output.split())
    assert (mine / "thesis.tex").read_text() == "important" and (mine / "notes").is_dir()
    monkeypatch.chdir(mine / "notes")
    for here in (".", ".."):
        res = CliRunner().invoke(app, [*args, "--out", here])
        assert res.exit_code == 2 and "is the current folder or holds it" in " ".join(res.output.split()), res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D0", "p4"]  # no partial folder, nothing trained
    # a starting model that is no model folder: the refusal names --init (it named the file alone)
    res = CliRunner().invoke(app, [*args[:-1], "--out", str(tmp_path / "m"), "--init", f"transfer:{mine}"])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and f"--init transfer:{mine}: {mine / 'model.json'}: not found" in said, said


def test_train_overwrite_of_a_model_keeps_the_files_beside_it_that_no_model_holds(tmp_path):
    """A model folder the lab also kept notes in: `--overwrite` swapped the folder out whole with them. Refused now,
    naming them; the model's own files (what train and evaluate write: MODEL_FILES) are replaced as before."""
    from coassist.cli._model_out import MODEL_FILES
    from coassist.intent import load_model

    write_dataset([make_trial(i, n=220) for i in range(4)], tmp_path / "D0", "D0")
    out = tmp_path / "m"
    args = ["train", str(tmp_path / "D0"), "--out", str(out), "--epochs", "1", "--threads", "1", "--batch-size", "256"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["evaluate", "--model", str(out), "--data", str(tmp_path / "D0")])
    assert res.exit_code == 0, res.output
    written = {p.name for p in out.iterdir()}
    assert "evaluation.json" in written and written <= MODEL_FILES, written - MODEL_FILES
    (out / "notes.md").write_text("subject 3 tired")
    before = load_model(out)
    res = CliRunner().invoke(app, [*args, "--overwrite", "--seed", "1"])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and "holds files a model does not (notes.md), which --overwrite would delete" in said
    assert (out / "notes.md").read_text() == "subject 3 tired" and same_weights(load_model(out), before)
    (out / "notes.md").unlink()
    res = CliRunner().invoke(app, [*args, "--overwrite", "--seed", "1"])
    assert res.exit_code == 0, res.output
    assert not same_weights(load_model(out), before)


@pytest.mark.parametrize(
    "field, value, says",
    [
        ("epoch", "x", "'epoch' must be an integer"),
        ("epoch", 1_000_000, "its contents are not those written"),
        ("epoch", 2, "its contents are not those written"),  # review of 3063e1e: resumed, history [1, 3]
        ("scheduler.last_epoch", 0, "its contents are not those written"),  # review of 3063e1e: other weights
        ("optimizer.param_groups.0.lr", 0.5, "its contents are not those written"),
        ("numpy_rng.state.state", 12345, "its contents are not those written"),
    ],
)
def test_a_checkpoint_edited_by_hand_is_refused_naming_it(tmp_path, field, value, says):
    """checkpoint.json's values are checked (once a string epoch was a traceback, and a huge one wrote a run stopped
    at epoch 1 of 3 out as finished), and since the review of 3063e1e its record carries its own SHA-256: an epoch
    count, a learning rate, a schedule's position or the generator's state edited resumed without a word, to
    weights no unbroken run has."""
    import json

    from coassist._io import partial_folder
    from coassist.intent.checkpoint import CHECKPOINT_JSON
    from coassist.intent.training import train_model

    cfg = _stopped_after_epoch_1(tmp_path / "m")
    path = partial_folder(tmp_path / "m") / CHECKPOINT_JSON
    record = json.loads(path.read_text())
    *parents, last = field.split(".")
    at = record
    for key in parents:
        at = at[int(key)] if isinstance(at, list) else at[key]
    at[last] = value
    path.write_text(json.dumps(record))
    with pytest.raises(ValueError, match="unusable checkpoint") as err:
        train_model(labeled(4), TINY, replace(cfg, init=f"resume:{tmp_path / 'm'}"))
    assert says in str(err.value) and "\n" not in str(err.value)


def test_a_checkpoints_tensors_changed_in_place_are_refused(tmp_path):
    """The review of 3063e1e: 200 floats of the optimizer's moments rewritten in checkpoint.safetensors, its size
    kept, resumed without a word to weights 506 away from the unbroken run's. The record keeps the tensors' SHA-256."""
    from coassist.intent.checkpoint import CHECKPOINT
    from coassist.intent.training import train_model

    cfg = _stopped_after_epoch_1(tmp_path / "m")
    path = partial_folder(tmp_path / "m") / CHECKPOINT
    raw = bytearray(path.read_bytes())
    raw[-16:] = bytes(16)  # the last four float32 of the last tensor zeroed: still a readable safetensors file
    path.write_bytes(bytes(raw))
    with pytest.raises(ValueError, match="unusable checkpoint") as err:
        train_model(labeled(4), TINY, replace(cfg, init=f"resume:{tmp_path / 'm'}"))
    assert f"{CHECKPOINT} is not the file written with it" in str(err.value) and "finetune:" in str(err.value)


@pytest.mark.parametrize("model_of, checkpoint_of", [(1, 2), (2, 1)])
def test_a_folder_mixing_two_epochs_is_refused_naming_it(tmp_path, model_of, checkpoint_of):
    """The model files of one epoch beside the checkpoint of another (a folder copied by hand, or read while the
    run swapped in its next epoch) once resumed silently: epoch-1 weights with the epoch-2 optimizer state and
    epoch count, a history [1, 3] and weights no unbroken run has. The checkpoint records the SHA-256 of the
    weights it was written with and the model's last epoch; a resume checks both against the files beside it."""
    import shutil

    from coassist.intent.checkpoint import CHECKPOINT, CHECKPOINT_JSON
    from coassist.intent.training import train_model

    class Stop(Exception):
        pass

    out, kept = tmp_path / "m", {}

    def keep(record):  # each epoch's partial folder, as it was after that epoch's save
        kept[record["epoch"]] = shutil.copytree(partial_folder(out), tmp_path / f"e{record['epoch']}")
        if record["epoch"] == 2:
            raise Stop

    cfg = replace(TINY.train, epochs=3)
    with pytest.raises(Stop):
        train_model(labeled(4), TINY, cfg, checkpoint_to=out, on_epoch=keep)
    mixed = partial_folder(out)
    shutil.rmtree(mixed)
    shutil.copytree(kept[model_of], mixed)
    for name in (CHECKPOINT_JSON, CHECKPOINT):
        shutil.copy(kept[checkpoint_of] / name, mixed / name)
    with pytest.raises(ValueError) as err:
        train_model(labeled(4), TINY, replace(cfg, init=f"resume:{out}"))
    said = str(err.value)
    assert said.startswith(f"{mixed}: unusable checkpoint: {CHECKPOINT_JSON} was not written with the model files ")
    assert f"their history ends at epoch {model_of}, the checkpoint at epoch {checkpoint_of}" in said
    assert "weights' SHA-256" in said and "finetune:" in said and "\n" not in said
    # each epoch's own folder, unmixed, still continues
    shutil.rmtree(mixed)
    shutil.copytree(kept[checkpoint_of], mixed)
    resumed = train_model(labeled(4), TINY, replace(cfg, init=f"resume:{out}"))
    assert [r["epoch"] for r in resumed.info["training_history"]] == [1, 2, 3]


def test_a_checkpoint_of_an_older_version_is_refused_saying_so(tmp_path):
    """A checkpoint written before checkpoints recorded their weights cannot be told apart from one beside
    other weights: refused, saying why (the project has no released checkpoints to keep)."""
    from coassist.intent.checkpoint import CHECKPOINT_JSON
    from coassist.intent.training import train_model

    cfg = _stopped_after_epoch_1(tmp_path / "m")
    path = partial_folder(tmp_path / "m") / CHECKPOINT_JSON
    record = json.loads(path.read_text())
    del record["weights_sha256"], record["model_epoch"]
    path.write_text(json.dumps(record))
    with pytest.raises(ValueError) as err:
        train_model(labeled(4), TINY, replace(cfg, init=f"resume:{tmp_path / 'm'}"))
    said = str(err.value)
    assert said.startswith(f"{path}: unusable checkpoint (written by an older coassist, before a checkpoint ")
    assert f"finetune:{partial_folder(tmp_path / 'm')}" in said and "\n" not in said


def test_resume_of_a_run_another_process_is_writing_is_refused(tmp_path):
    """resume:A -o B reads A's partial folder under A's lock (held by the run writing A from start to end):
    refused while that run goes on, where it could read one epoch's model beside the next one's checkpoint."""
    cfg = _stopped_after_epoch_1(tmp_path / "m")
    child = hold_lock_in_child(tmp_path / "m", tmp_path / "ready")
    from coassist.intent.training import train_model

    try:
        with pytest.raises(OutputBusyError, match=f"pid {child.pid}"):
            train_model(labeled(4), TINY, replace(cfg, init=f"resume:{tmp_path / 'm'}"), checkpoint_to=tmp_path / "b")
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    resumed = train_model(labeled(4), TINY, replace(cfg, init=f"resume:{tmp_path / 'm'}"), checkpoint_to=tmp_path / "b")
    assert [r["epoch"] for r in resumed.info["training_history"]] == [1, 2, 3]


@pytest.mark.slow  # ~11 s: two trainings and a child process; the library test above covers the resume itself
def test_cli_train_resumes_a_killed_run(tmp_path):
    """`coassist train` killed after epoch 1 of 2; the same command with --init resume:<out> finishes it."""
    from coassist.intent import load_model

    write_dataset([make_trial(i, n=220) for i in range(5)], tmp_path / "D0", "D0")
    out = tmp_path / "m"
    args = [
        "train",
        str(tmp_path / "D0"),
        "--out",
        str(out),
        "--preset",
        "lstm",
        "--epochs",
        "2",
        "--threads",
        "1",
        "--batch-size",
        "64",
    ]
    run_child(f"""
        import os, signal
        from coassist.intent import training
        real = training.checkpoint_files
        def files(*a, epoch, **kw):
            if epoch == 2:
                {KILL}
            return real(*a, epoch=epoch, **kw)
        training.checkpoint_files = files
        from coassist.cli import app
        app({args!r}, standalone_mode=False)
    """)
    assert not out.exists() and (partial_folder(out) / "checkpoint.json").is_file()
    res = CliRunner().invoke(app, [*args, "--init", f"resume:{out}"])
    assert res.exit_code == 0, res.output
    resumed = load_model(out)
    assert [r["epoch"] for r in resumed.info["training_history"]] == [1, 2]
    res = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "u")])
    unbroken = load_model(tmp_path / "u")
    assert same_weights(resumed, unbroken)
    assert np.allclose(
        [r["train_loss"] for r in resumed.info["training_history"]],
        [r["train_loss"] for r in unbroken.info["training_history"]],
        rtol=0,
        atol=0,
    )


def test_an_unfinished_training_is_not_evaluated_nor_put_in_the_loop(tmp_path):
    """The checkpoint of a stopped training (``.m.partial``, which train's note names) was scored by evaluate against
    fewer, untuned baselines (21.6 % better than constant velocity, no ridge) and run by collect --intent without a
    word (review, 2026-12-06). Both refuse it in one line."""
    from coassist.scenario.intent_registry import load_intent_source

    _stopped_after_epoch_1(tmp_path / "m")
    partial = partial_folder(tmp_path / "m")
    write_dataset([make_trial(i, n=220) for i in range(2)], tmp_path / "E", "E")
    res = CliRunner().invoke(app, ["evaluate", "--model", str(partial), "--data", str(tmp_path / "E")])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and "an unfinished training (the checkpoint after epoch 1 of 3" in said, res.output
    with pytest.raises(ValueError, match=r"an unfinished training \(the checkpoint after epoch 1 of 3"):
        load_intent_source(str(partial), horizon=TINY.window.horizon)


def test_a_collection_that_fails_before_its_first_trial_leaves_no_partial_folder(tmp_path):
    """A collect refused after its writer opened (a damaged --intent folder, a cluster not reached) left an empty
    .<name>.partial that the next, correct command then refused as "another, unfinished collection" (review,
    2026-12-06). The writer removes the partial it made where no trial was written; one with trials is kept."""
    from coassist.data import DatasetWriter

    out = tmp_path / "D"
    with pytest.raises(RuntimeError, match="before any trial"):
        with DatasetWriter(out, "D", n_trials=2, key="k"):
            raise RuntimeError("failed before any trial")
    assert not partial_folder(out).exists()
    with pytest.raises(RuntimeError, match="after one trial"):
        with DatasetWriter(out, "D", n_trials=2, key="k") as w:
            w.add(0, make_trial(0))
            raise RuntimeError("failed after one trial")
    assert (partial_folder(out) / "trial_00000.parquet").is_file()  # kept, for the same command to continue
    with pytest.raises(RuntimeError, match="again"):
        with DatasetWriter(out, "D", n_trials=2, key="k", keep=True) as w:
            assert w.resumed == [0]
            raise RuntimeError("failed again")
    assert (partial_folder(out) / "trial_00000.parquet").is_file()  # another run's partial is never removed


def test_collect_with_a_damaged_intent_folder_is_refused_in_one_line_leaving_nothing(tmp_path):
    from typer.testing import CliRunner

    folder = tmp_path / "pm"
    folder.mkdir()
    (folder / "person-model.json").write_text("")
    res = CliRunner().invoke(
        app, ["collect", "--out", str(tmp_path / "o" / "x"), "--trials", "1", "--intent", str(folder)]
    )
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and f"--intent {folder}: {folder}/person-model.json: malformed JSON" in said, said
    assert "Traceback" not in res.output and not (tmp_path / "o").exists()


def test_an_unfinished_collection_is_never_read_as_a_folder_of_trial_files(tmp_path):
    """The review of 3063e1e: a killed collect's .<out>.partial (9 of 24 trials) was scored by evaluate and trained
    on by train as a folder of trial files, without a word: some of a collection passing for all of it."""
    from coassist.data import DatasetWriter
    from coassist.intent import load_trials

    out = tmp_path / "D"
    with DatasetWriter(out, "D", n_trials=4, key="k", description="simulated: 4 board trials") as w:
        w.add(0, make_trial(0))
        w.add(2, make_trial(2))  # then "killed": no finish()
    partial = partial_folder(out)
    expected = (
        f"{partial}: an unfinished collection (2 of 4 trials written; simulated: 4 board trials): the command that "
        "started it finishes it (run it again: it resumes), then read the folder it writes"
    )
    with pytest.raises(ValueError) as err:
        load_trials([partial])
    assert str(err.value) == expected
    assert load_trials([partial / "trial_00000.parquet"])[0].trial.equals(make_trial(0))  # one whole trial: read
    for args in (["train", str(partial), "--out", str(tmp_path / "m"), "--epochs", "1"], ["show", str(partial)]):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2 and "an unfinished collection (2 of 4 trials written" in result.output, result
    assert sorted(p.name for p in partial.glob("trial_*")) == ["trial_00000.parquet", "trial_00002.parquet"]
    assert not (tmp_path / "m").exists()
