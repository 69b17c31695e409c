"""A trial's origin (issue 43): the field ``origin``, stored under the key ``"source"`` before.

Files written before the rename are built here as that writer wrote them: the current writer's
output with the key renamed back (the meta JSON of a trial file: ``json.dumps(to_dict(),
allow_nan=False, sort_keys=True)``; a manifest's meta: the same dict in field order, the key in
place). The pre-rename writer's own bytes were compared with this construction when the field was
renamed (the commit's message says how).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import fields

import numpy as np
import pyarrow.parquet as pq
import pytest

from coassist.data import Trial, TrialFileError, TrialMeta, append_to_dataset, read_dataset, read_trial, write_trial
from coassist.data.datasets import MANIFEST_NAME, write_dataset
from coassist.data.trial import FORMER_KEYS, ORIGINS
from coassist.data.trial_file import META_CHECKSUM_KEY, META_KEY

FIELDS = [f.name for f in fields(TrialMeta)]


def legacy_meta(meta: TrialMeta) -> dict:
    """The meta dict the pre-rename writer stored: ``"source"`` where ``"origin"`` is, in its place."""
    return {("source" if k == "origin" else k): v for k, v in meta.to_dict().items()}


def legacy_meta_json(meta: TrialMeta) -> bytes:
    """A pre-rename trial file's ``coassist.trial_meta`` (``TrialMeta.to_json`` then)."""
    return json.dumps(legacy_meta(meta), allow_nan=False, sort_keys=True).encode()


def rewrite_meta(path, value: bytes) -> None:
    """Replace a trial file's stored meta, its columns and every other key untouched, as
    :func:`coassist.data.trial_file.write_trial` writes (zstd, no dictionaries); without the metadata's checksum,
    which files of that time did not have."""
    table = pq.read_table(path)
    kept = {k: v for k, v in table.schema.metadata.items() if k != META_CHECKSUM_KEY}
    table = table.replace_schema_metadata({**kept, META_KEY: value})
    pq.write_table(table, path, compression="zstd", use_dictionary=False)


def make_trial(origin: str, seed: int | None, n: int = 30) -> Trial:
    rng = np.random.default_rng(0 if seed is None else seed)
    meta = TrialMeta(
        user="user-0",
        task="curved",
        object="board",
        controller="cooperative",
        model_id=None if seed is None else "M2",
        seed=seed,
        origin=origin,
        dt=0.008,
        extra={"target": [0.4, 0.1], "obstacle": {"lo": [0.1, 0.0], "hi": [0.2, 0.05]}},
    )
    return Trial(
        meta=meta,
        time=np.arange(n) * 0.008,
        pose=rng.normal(size=(n, 2)),
        velocity=rng.normal(size=(n, 2)),
        wrench=rng.normal(size=(n, 2)),
        reference=rng.normal(size=(n, 2)),
        prediction=rng.normal(size=(n, 4, 2)),
        fault=rng.integers(0, 3, size=n),
    )


def same_trial(read: Trial, legacy: dict, written: Trial) -> None:
    """Every meta field of ``read`` is the legacy dict's (origin ↔ source), every array ``written``'s, bit for bit."""
    for name in FIELDS:
        stored = legacy["source" if name == "origin" else name]
        got = read.meta.to_dict()[name]
        assert got == stored and type(got) is type(stored), name
    assert read.meta == written.meta and read.equals(written)


def test_the_field_is_origin_and_the_former_key_source():
    assert "origin" in FIELDS and "source" not in FIELDS and FORMER_KEYS == {"source": "origin"}
    meta = make_trial("mujoco", 3).meta
    stored = json.loads(meta.to_json())
    assert stored["origin"] == "mujoco" and "source" not in stored
    assert set(ORIGINS) == {"sim", "real", "mujoco", "ur5", "franka"}


@pytest.mark.parametrize("origin, seed", [("sim", 3), ("real", None), ("ur5", 8)])
def test_a_trial_file_written_before_the_rename_reads_the_same(tmp_path, origin, seed):
    trial = make_trial(origin, seed)
    new = write_trial(trial, tmp_path / "new.parquet")
    old = tmp_path / "old.parquet"
    shutil.copy(new, old)
    rewrite_meta(old, legacy_meta_json(trial.meta))
    stored = json.loads(pq.read_schema(old).metadata[META_KEY])
    assert "source" in stored and "origin" not in stored  # the file is the old format
    same_trial(read_trial(old), stored, trial)
    assert read_trial(old).equals(read_trial(new))
    # written again, it stores the new key
    again = write_trial(read_trial(old), tmp_path / "again.parquet")
    assert json.loads(pq.read_schema(again).metadata[META_KEY]) == trial.meta.to_dict()


def test_a_dataset_folder_written_before_the_rename_reads_the_same(tmp_path):
    trials = [make_trial("sim", 1), make_trial("real", None), make_trial("franka", 2)]
    folder = write_dataset(trials, tmp_path / "ds", dataset_id="D0")
    manifest = json.loads((folder / MANIFEST_NAME).read_text())
    for entry, trial in zip(manifest["trials"], trials):
        entry["meta"] = legacy_meta(trial.meta)
        rewrite_meta(folder / entry["file"], legacy_meta_json(trial.meta))
    (folder / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2, allow_nan=False) + "\n")
    assert '"source": "franka"' in (folder / MANIFEST_NAME).read_text()
    assert '"origin"' not in (folder / MANIFEST_NAME).read_text()
    ds = read_dataset(folder)
    assert len(ds.trials) == 3
    for read, entry, trial in zip(ds.trials, manifest["trials"], trials):
        same_trial(read, entry["meta"], trial)
    # trials added to an old folder store the new key beside the old entries, which stay as written
    append_to_dataset([make_trial("mujoco", 5)], folder)
    after = json.loads((folder / MANIFEST_NAME).read_text())
    assert after["trials"][:3] == manifest["trials"] and after["trials"][3]["meta"]["origin"] == "mujoco"
    assert [t.meta.origin for t in read_dataset(folder).trials] == ["sim", "real", "franka", "mujoco"]


def test_both_keys_with_different_values_are_refused_naming_both(tmp_path):
    meta = make_trial("sim", 3).meta
    both = {**meta.to_dict(), "source": "real"}
    with pytest.raises(
        ValueError, match=r"TrialMeta\.origin .* as 'origin' \('sim'\) .* former key 'source' \('real'\)"
    ):
        TrialMeta.from_dict(both)
    assert TrialMeta.from_dict({**meta.to_dict(), "source": "sim"}) == meta  # the same value twice: one origin
    path = write_trial(make_trial("sim", 3), tmp_path / "both.parquet")
    rewrite_meta(path, json.dumps(both, sort_keys=True).encode())
    with pytest.raises(TrialFileError, match=r"both\.parquet.*'origin'.*'source'"):
        read_trial(path)


def test_an_unknown_origin_names_the_field_and_the_key_it_was_read_from(tmp_path):
    meta = make_trial("sim", 3).meta
    with pytest.raises(ValueError, match=r"TrialMeta\.origin must be one of .*got 'lab'$"):
        TrialMeta.from_dict({**meta.to_dict(), "origin": "lab"})
    with pytest.raises(
        ValueError, match=r"TrialMeta\.origin must be one of .*'lab' \(read origin under its former key 'source'\)"
    ):
        TrialMeta.from_dict({**legacy_meta(meta), "source": "lab"})
    missing = legacy_meta(meta)
    del missing["source"]
    with pytest.raises(ValueError, match=r"missing field.*origin"):
        TrialMeta.from_dict(missing)
