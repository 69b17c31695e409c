"""The fault probe's file and CLI cases (issue 22 §3): each one failed before its fix.

Model sidecars checked against their own recorded hash and sizes, trial files against
their checksum, ``drive``'s time limit and output, and ``collect``: resumed after a
kill, no orphaned workers, a closing summary whose memory does not grow per trial.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import Trial, TrialFileError, TrialMeta, read_dataset, read_trial, write_dataset, write_trial

RUNNER = CliRunner()


def _one_line_error(result, *pieces: str) -> str:
    assert result.exit_code != 0 and "Traceback" not in result.output, result.output
    lines = [ln for ln in result.output.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, result.output
    assert all(p in lines[0] for p in pieces), lines[0]
    return lines[0]


# --------------------------------------------------------------------------- model sidecars
def _copy(model_dir: Path, tmp_path: Path) -> Path:
    import shutil

    return Path(shutil.copytree(model_dir, tmp_path / "m"))


def _edit(folder: Path, change) -> None:
    path = folder / "model.json"
    path.write_text(json.dumps(change(json.loads(path.read_text()))))


def test_a_tampered_target_scaler_is_refused(model_dir, tmp_path):
    """The probe's case: target_scaler ×30 made the point-mass robot push 100 N for 1 035 ticks."""
    from coassist.intent import ModelFileError, load_model

    load_model(model_dir)  # the untouched model loads
    folder = _copy(model_dir, tmp_path)

    def times30(m):
        sc = m["target_scaler"]
        return {**m, "target_scaler": {**sc, "lo": [30 * v for v in sc["lo"]], "hi": [30 * v for v in sc["hi"]]}}

    _edit(folder, times30)
    with pytest.raises(ModelFileError, match=r"m/model\.json: its content does not match the hash recorded"):
        load_model(folder)


def test_a_deeply_nested_sidecar_is_one_clear_error(model_dir, tmp_path):
    from coassist.intent import ModelFileError, load_model

    folder = _copy(model_dir, tmp_path)
    (folder / "model.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ModelFileError, match=r"model\.json: JSON nested too deeply"):
        load_model(folder)


@pytest.mark.parametrize(
    "hidden, says",
    [
        (
            100_000,
            r"model\.json: .*network: 40,004,800,188 parameters .* more than the 100,000,000",
        ),  # any model's bound
        # under it, over its weights
        (2_000, r"weights\.safetensors: holds \d+ bytes, too few for the network in model\.json .* \d+ parameters"),
    ],
)
def test_a_huge_network_is_refused_before_any_allocation(model_dir, tmp_path, hidden, says):
    """hidden = 100 000 would be a 160 GB allocation: refused from the sizes alone, at once."""
    from coassist.intent import ModelFileError, load_model

    folder = _copy(model_dir, tmp_path)
    _edit(folder, lambda m: {**m, "network": {**m["network"], "hidden": hidden}})
    tracemalloc.start()
    try:
        with pytest.raises(ModelFileError, match=says):
            load_model(folder)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50 * 2**20  # nothing of the network's size was allocated


def test_truncated_weights_are_named_as_the_damaged_file(model_dir, tmp_path):
    """A weights file cut short was reported as a model.json problem (a review, 2026-12-07)."""
    from coassist.intent import ModelFileError, load_model

    folder = _copy(model_dir, tmp_path)
    weights = folder / "weights.safetensors"
    weights.write_bytes(weights.read_bytes()[:200])
    with pytest.raises(ModelFileError, match=r"m/weights\.safetensors: holds 200 bytes, too few .* truncated"):
        load_model(folder)


def test_the_parameter_count_from_sizes_matches_the_network():
    from coassist.intent.network import IntentNet, NetworkConfig

    for cfg in (
        NetworkConfig(8, 20, lstm_layers=2, hidden=7, fc=(5, 3)),
        NetworkConfig(8, 20, lstm_layers=0, skip_inputs=16),
        NetworkConfig(8, 20, lstm_layers=1, hidden=4, fc=(), skip_inputs=24),
        NetworkConfig(8, 20, lstm_layers=2, hidden=6, fc=(5,), hypotheses=3),
    ):
        assert cfg.n_parameters == sum(p.numel() for p in IntentNet(cfg).parameters())


# --------------------------------------------------------------------------- trial files
FIELDS = ("time", "pose", "velocity", "wrench", "reference", "effort_h", "effort_r", "prediction")


def _trial(n: int = 400, seed: int = 0, horizon: int = 0) -> Trial:
    rng = np.random.default_rng(seed)
    meta = TrialMeta(
        user="u",
        task="linear",
        object="handle",
        controller="impedance",
        model_id=None,
        seed=seed,
        origin="sim",
        dt=0.008,
    )
    arr = lambda: rng.normal(size=(n, 2))  # noqa: E731
    pred = rng.normal(size=(n, horizon, 2)) if horizon else None
    return Trial(
        meta=meta,
        time=np.arange(n) * 0.008,
        pose=arr(),
        velocity=arr(),
        wrench=arr(),
        reference=arr(),
        effort_h=arr(),
        effort_r=arr(),
        prediction=pred,
    )


def test_random_bytes_in_a_trial_file_never_load_as_other_values(tmp_path):
    """The probe wrote 4 000 random bytes into a trial file: 13 of 20 loaded (wrenches up
    to 6e307 N). Now every try either is refused or reads back the very values written."""
    trial = _trial(n=800, horizon=50)  # a collect trial's size: ~0.7 MB of values, mostly the prediction
    clean = write_trial(trial, tmp_path / "clean.parquet").read_bytes()
    rng = np.random.default_rng(1)
    outcomes = []
    for i in range(20):
        raw = bytearray(clean)
        at = int(rng.integers(0, len(raw) - 4000))
        raw[at : at + 4000] = rng.integers(0, 256, 4000, dtype=np.uint8).tobytes()
        path = tmp_path / f"t{i}.parquet"
        path.write_bytes(bytes(raw))
        try:
            back = read_trial(path)
        except TrialFileError as exc:
            assert str(path) in str(exc)
            outcomes.append("refused")
            continue
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(back, name), getattr(trial, name))
        outcomes.append("intact")
    assert outcomes.count("refused") >= 15, outcomes  # (all 20 here; intact would be bytes in unused padding)


def test_an_implausible_value_without_a_checksum_is_refused(tmp_path):
    """Files written before the checksum: a finite 6e307 N wrench is still no recording."""
    import pyarrow.parquet as pq

    from coassist.data.trial_file import CHECKSUM_KEY

    path = write_trial(_trial(), tmp_path / "t.parquet")
    table = pq.read_table(path)
    wrench = table.column("wrench_x").to_numpy().copy()
    wrench[7] = 6e307
    table = table.set_column(table.column_names.index("wrench_x"), "wrench_x", [wrench])
    md = {k: v for k, v in table.schema.metadata.items() if k != CHECKSUM_KEY}
    pq.write_table(table.replace_schema_metadata(md), path)
    with pytest.raises(TrialFileError, match=r"t\.parquet: wrench holds 6e\+307, beyond any recording"):
        read_trial(path)


# --------------------------------------------------------------------------- drive's options
@pytest.mark.parametrize("limit", ["inf", "1e9", "nan"])
def test_drive_time_limit_inf_or_huge_is_one_line(limit):
    res = RUNNER.invoke(app, ["drive", "--time-limit", limit, "--out", "never.parquet"])
    _one_line_error(res, "--time-limit", "600")


def test_drive_out_refuses_to_replace_a_trial_without_overwrite(tmp_path):
    out = tmp_path / "trial.parquet"
    out.write_bytes(b"an earlier run")
    res = RUNNER.invoke(app, ["drive", "--out", str(out)])
    _one_line_error(res, "--out", "exists", "--overwrite")
    assert out.read_bytes() == b"an earlier run"


# --------------------------------------------------------------------------- collect
COASSIST = Path(sys.executable).with_name("coassist")
COLLECT = ["collect", "--trials", "6", "--tasks", "linear", "--seed", "3"]


def _env() -> dict[str, str]:
    return {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _wait_for(predicate, timeout: float = 60.0) -> None:
    t_end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > t_end:
            raise TimeoutError("condition not met")
        time.sleep(0.05)


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process table from /proc (Linux)")
def test_an_interrupted_collect_resumes_to_the_same_dataset(tmp_path):
    """SIGKILL after some trials are kept; the same command finishes the run from them, and
    the dataset equals an uninterrupted run's bit for bit (trials are seeded one by one).
    Run once more, the same command finds the dataset complete and does nothing."""
    out = tmp_path / "D"
    partial = tmp_path / ".D.partial"
    proc = subprocess.Popen(
        [str(COASSIST), *COLLECT, "--out", str(out), "--workers", "1"],
        env=_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        _wait_for(lambda: len(list(partial.glob("trial_*.parquet"))) >= 2)
    finally:
        proc.kill()
        proc.wait()
    kept = sorted(p.name for p in partial.glob("trial_*.parquet"))
    assert 2 <= len(kept) < 6 and not out.exists()
    again = subprocess.run(
        [str(COASSIST), *COLLECT, "--out", str(out), "--workers", "1"],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert again.returncode == 0, again.stdout + again.stderr
    assert f"continuing: {len(kept)} of 6 trials" in again.stdout
    whole = subprocess.run(
        [str(COASSIST), *COLLECT, "--out", str(tmp_path / "W"), "--workers", "1"],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert whole.returncode == 0, whole.stderr
    done = subprocess.run(
        [str(COASSIST), *COLLECT, "--out", str(out), "--workers", "1"],
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0 and "this collection, complete" in " ".join(done.stdout.split()), done.stdout
    a, b = read_dataset(out).trials, read_dataset(tmp_path / "W").trials
    assert len(a) == len(b) == 6
    for ta, tb in zip(a, b):
        for name in ("time", "pose", "velocity", "wrench", "reference", "effort_h", "effort_r", "fault"):
            np.testing.assert_array_equal(getattr(ta, name), getattr(tb, name))


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process table from /proc (Linux)")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_killing_collect_leaves_no_worker_running(tmp_path, sig):
    proc = subprocess.Popen(
        [str(COASSIST), "collect", "--trials", "40", "--out", str(tmp_path / "D"), "--workers", "2"],
        env=_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    workers: list[int] = []
    try:

        def two_workers() -> bool:
            workers[:] = [p for p in _children(proc.pid) if "spawn_main" in Path(f"/proc/{p}/cmdline").read_text()]
            return len(workers) >= 2

        _wait_for(two_workers)
    finally:
        proc.send_signal(sig)
        proc.wait()
    try:
        _wait_for(lambda: not any(_alive(p) for p in workers), timeout=10.0)
    finally:
        for p in workers:  # never leave them behind, even when the test fails
            if _alive(p):
                os.kill(p, signal.SIGKILL)


def test_the_collect_summary_reads_one_trial_at_a_time(tmp_path):
    """The closing f_RMS line re-read the whole dataset (606 MB for 60 trials): its peak
    memory must not grow with the number of trials."""
    from coassist.cli.collect import print_forces

    def peak(n: int) -> int:
        folder = write_dataset([_trial(n=20_000, seed=i) for i in range(n)], tmp_path / f"D{n}", dataset_id=f"D{n}")
        tracemalloc.start()
        try:
            print_forces(folder)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    one, eight = peak(1), peak(8)
    # one trial's arrays are ~2.2 MB (7 × 20 000 × 2 float64); eight read at once would be 8×
    assert eight < one + 2 * 2**20, (one, eight)
