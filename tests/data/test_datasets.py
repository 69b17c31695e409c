"""Trial files and dataset folders: exact round trips, errors naming file and column."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import coassist
from coassist.data import (
    Trial,
    TrialFileError,
    TrialMeta,
    append_to_dataset,
    read_dataset,
    read_trial,
    write_dataset,
    write_trial,
)
from coassist.data.trial_file import META_KEY, VERSION_KEY


def full_trial(n: int = 50, d: int = 2, h: int = 5, seed: int = 0, **meta_changes) -> Trial:
    """A trial with every optional field set, values that stress exactness."""
    rng = np.random.default_rng(seed)
    pred = rng.normal(size=(n, h, d))
    pred[:2] = np.nan  # no prediction during the first ticks
    pose = rng.normal(size=(n, d))
    pose[0, 0] = -0.0  # the sign bit of zero must survive
    pose[1, 0] = 5e-324  # a denormal must survive
    pose[2, 0] = np.nextafter(1.0, 2.0)
    meta = dict(
        user="user-0",
        task="curved",
        object="board",
        controller="cooperative",
        model_id="M2",
        seed=seed,
        origin="sim",
        dt=0.008,
        extra={"target": [0.4, 0.1], "obstacle": {"lo": [0.1, 0.0], "hi": [0.2, 0.05]}},
    )
    meta.update(meta_changes)
    return Trial(
        meta=TrialMeta(**meta),
        time=np.arange(n) * 0.008,
        pose=pose,
        velocity=rng.normal(size=(n, d)),
        wrench=rng.normal(size=(n, d)) * 10,
        reference=rng.normal(size=(n, d)),
        prediction=pred,
        intent=rng.normal(size=(n, d)),
        effort_h=rng.normal(size=(n, d)),
        effort_r=rng.normal(size=(n, d)),
        fault=rng.integers(0, 4, size=n),
        alpha=rng.uniform(0.0, 1.0, size=n),
    )


def minimal_trial(n: int = 20, d: int = 2) -> Trial:
    rng = np.random.default_rng(1)
    return Trial(
        meta=TrialMeta(
            user="user-a",
            task="real",
            object="unknown",
            controller="unknown",
            model_id=None,
            seed=None,
            origin="real",
            dt=0.007999973999999632,
        ),
        time=np.cumsum(rng.uniform(0.007, 0.013, size=n)) - 0.01,
        pose=rng.normal(size=(n, d)),
        velocity=rng.normal(size=(n, d)),
        wrench=rng.normal(size=(n, d)),
        reference=rng.normal(size=(n, d)),
    )


def test_columns_and_schema(tmp_path):
    path = write_trial(full_trial(n=50, d=2, h=5), tmp_path / "t.parquet")
    schema = pq.read_schema(path)
    expected = [
        "time",
        "pose_x",
        "pose_y",
        "vel_x",
        "vel_y",
        "wrench_x",
        "wrench_y",
        "ref_x",
        "ref_y",
        "intent_x",
        "intent_y",
        "effort_h_x",
        "effort_h_y",
        "effort_r_x",
        "effort_r_y",
        "fault",
        "alpha",
        "prediction_x",
        "prediction_y",
    ]
    assert schema.names == expected
    assert schema.field("prediction_x").type == pa.list_(pa.float64(), 5)
    assert schema.field("fault").type == pa.int64()
    assert schema.field("pose_x").type == pa.float64()
    assert schema.metadata[VERSION_KEY] == b"1"
    meta = json.loads(schema.metadata[META_KEY])
    assert meta["user"] == "user-0" and meta["model_id"] == "M2" and meta["extra"]["target"] == [0.4, 0.1]


@pytest.mark.parametrize("d", [1, 2, 3, 6])
def test_round_trip_is_bit_exact(tmp_path, d):
    trial = full_trial(d=d, seed=d)
    back = read_trial(write_trial(trial, tmp_path / "t.parquet"))
    assert back.equals(trial)
    # equals compares bytes; spot-check the tricky values explicitly too
    assert np.signbit(back.pose[0, 0]) and back.pose[0, 0] == 0.0
    assert back.pose[1, 0] == 5e-324
    assert np.isnan(back.prediction[:2]).all()
    assert back.meta == trial.meta and back.meta.dt == 0.008


def test_round_trip_without_optional_fields(tmp_path):
    trial = minimal_trial()
    back = read_trial(write_trial(trial, tmp_path / "sub" / "t.parquet"))
    assert back.equals(trial)
    assert back.prediction is None and back.intent is None and back.fault is None
    assert back.meta.dt == 0.007999973999999632
    assert pq.read_schema(tmp_path / "sub" / "t.parquet").names == [
        "time",
        "pose_x",
        "pose_y",
        "vel_x",
        "vel_y",
        "wrench_x",
        "wrench_y",
        "ref_x",
        "ref_y",
    ]


def test_write_is_atomic_and_leaves_no_temp_files(tmp_path, monkeypatch):
    path = tmp_path / "t.parquet"
    write_trial(minimal_trial(), path)
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(pq, "write_table", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        write_trial(full_trial(), path)
    # the old file is untouched and the temp file was removed
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.parquet"]


def test_missing_metadata_key_names_file(tmp_path):
    path = tmp_path / "plain.parquet"
    pq.write_table(pa.table({"time": [0.0, 1.0]}), path)
    with pytest.raises(TrialFileError, match=r"plain\.parquet.*coassist\.trial_meta"):
        read_trial(path)


@pytest.mark.parametrize("column", ["wrench_y", "time", "ref_x", "intent_y", "prediction_y"])
def test_missing_column_names_file_and_column(tmp_path, column):
    path = write_trial(full_trial(), tmp_path / "t.parquet")
    table = pq.read_table(path)
    table = table.drop_columns([column])
    pq.write_table(table, path)  # schema metadata is kept
    with pytest.raises(TrialFileError, match=rf"t\.parquet: missing column '{column}'"):
        read_trial(path)


def test_newer_format_version_is_refused(tmp_path):
    path = write_trial(minimal_trial(), tmp_path / "t.parquet")
    table = pq.read_table(path)
    md = dict(table.schema.metadata)
    md[VERSION_KEY] = b"99"
    pq.write_table(table.replace_schema_metadata(md), path)
    with pytest.raises(TrialFileError, match="format version 99"):
        read_trial(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.parquet"):
        read_trial(tmp_path / "nope.parquet")


def test_dataset_round_trip_and_manifest(tmp_path):
    trials = [full_trial(seed=s, task=task) for s, task in enumerate(["linear", "curved", "sinusoidal"])]
    folder = write_dataset(trials, tmp_path / "D0", "D0", description="nominal, no model")
    ds = read_dataset(folder)
    assert ds.id == "D0" and ds.description == "nominal, no model" and len(ds) == 3
    assert all(a.equals(b) for a, b in zip(ds.trials, trials))
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["dataset_id"] == "D0"
    assert manifest["coassist_version"] == coassist.__version__
    assert manifest["n_trials"] == 3
    assert [e["file"] for e in manifest["trials"]] == [f"trial_{i:05d}.parquet" for i in range(3)]
    assert [e["meta"]["task"] for e in manifest["trials"]] == ["linear", "curved", "sinusoidal"]
    assert manifest["created"].endswith("+00:00")
    assert sorted(p.name for p in folder.iterdir()) == ["manifest.json"] + [f"trial_{i:05d}.parquet" for i in range(3)]


def test_dataset_refuses_non_empty_folder_unless_overwrite(tmp_path):
    folder = write_dataset([full_trial(seed=s) for s in range(3)], tmp_path / "D", "D1")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_dataset([minimal_trial()], folder, "D1b")
    assert read_dataset(folder).id == "D1"  # untouched
    (folder / "notes.txt").write_text("keep me")
    write_dataset([minimal_trial()], folder, "D1b", overwrite=True)
    ds = read_dataset(folder)
    assert ds.id == "D1b" and len(ds) == 1 and ds.trials[0].equals(minimal_trial())
    # stale trial files of the old dataset are gone; files no manifest listed are kept
    assert sorted(p.name for p in folder.iterdir()) == ["manifest.json", "notes.txt", "trial_00000.parquet"]


def test_an_overwrite_leaves_the_replaced_trials_companions_behind(tmp_path):
    """``play --mcap`` keeps ``trial_00000.mcap`` beside ``trial_00000.parquet``; an overwrite carried the old MCAP
    beside the new trial of that name, where it looked like the new trial's own. Files of no trial's name (notes)
    are carried as before."""
    folder = write_dataset([full_trial(seed=s) for s in range(2)], tmp_path / "D", "D1")
    (folder / "trial_00000.mcap").write_bytes(b"the old trial's recording")
    (folder / "trial_00001.png").write_bytes(b"the old trial's figure")
    (folder / "notes.txt").write_text("keep me")
    write_dataset([minimal_trial()], folder, "D1b", overwrite=True)
    assert sorted(p.name for p in folder.iterdir()) == ["manifest.json", "notes.txt", "trial_00000.parquet"]


def test_a_dataset_reached_through_a_symlink_is_written_where_it_is_and_locked_as_itself(tmp_path):
    """A dataset kept on another disk, reached through a link: an overwrite swapped the link itself for a new folder
    (the linked data left as they were, the link gone), and a writer through the link took another lock than one
    through the folder's own path, so two could write it at once."""
    from coassist._io import OutputLock

    real = write_dataset([full_trial(seed=0)], tmp_path / "store" / "D", "D1")
    link = tmp_path / "D"
    link.symlink_to(real)
    assert OutputLock(link).lock_file == OutputLock(real).lock_file
    write_dataset([minimal_trial()], link, "D1b", overwrite=True)
    assert link.is_symlink() and link.resolve() == real.resolve()
    assert read_dataset(real).id == "D1b" and len(read_dataset(link)) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D", "store"]  # nothing staged or left beside the link
    append_to_dataset([full_trial(seed=1)], link)
    assert len(read_dataset(real)) == 2


def test_dataset_into_empty_existing_folder(tmp_path):
    (tmp_path / "E").mkdir()
    assert len(read_dataset(write_dataset([minimal_trial()], tmp_path / "E", "E"))) == 1


def test_append_to_dataset(tmp_path):
    folder = write_dataset([full_trial(seed=0)], tmp_path / "D", "D2")
    append_to_dataset([full_trial(seed=1), minimal_trial()], folder)
    ds = read_dataset(folder)
    assert ds.id == "D2" and len(ds) == 3
    assert ds.trials[1].equals(full_trial(seed=1)) and ds.trials[2].equals(minimal_trial())
    assert ds.manifest["n_trials"] == 3


def test_read_dataset_detects_hand_edited_folder(tmp_path):
    folder = write_dataset([full_trial(seed=0), full_trial(seed=1)], tmp_path / "D", "D3")
    (folder / "trial_00000.parquet").write_bytes((folder / "trial_00001.parquet").read_bytes())
    with pytest.raises(TrialFileError, match=r"trial_00000\.parquet: meta differs"):
        read_dataset(folder)


def test_read_dataset_missing_trial_file(tmp_path):
    folder = write_dataset([full_trial(seed=0), full_trial(seed=1)], tmp_path / "D", "D4")
    (folder / "trial_00001.parquet").unlink()
    with pytest.raises(FileNotFoundError, match=r"trial_00001\.parquet"):
        read_dataset(folder)


def test_read_dataset_without_manifest(tmp_path):
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        read_dataset(tmp_path)


def test_write_dataset_validates_inputs(tmp_path):
    with pytest.raises(ValueError, match="dataset_id"):
        write_dataset([minimal_trial()], tmp_path / "a", "")
    with pytest.raises(ValueError, match=r"trials\[1\]"):
        write_dataset([minimal_trial(), "nope"], tmp_path / "b", "B")
