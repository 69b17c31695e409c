"""A pool worker keeps the trials of the dataset folders it last trained on (coassist.experiments.pipeline.KeptTrials)."""

from __future__ import annotations

import os

import pytest

from coassist.data import write_dataset
from coassist.experiments import pipeline

from ..data.test_datasets import full_trial


def _dataset(folder, seed: int):
    trials = [full_trial(n=20, seed=seed + k) for k in range(2)]
    write_dataset(trials, folder, dataset_id=folder.name, overwrite=True)
    return trials


def test_the_same_folders_are_read_once_and_anything_new_is_read_again(tmp_path, monkeypatch):
    import coassist.intent as intent

    a, b = tmp_path / "A", tmp_path / "B"
    _dataset(a, 1)
    _dataset(b, 2)
    reads = []
    real = intent.load_trials

    def counting(paths, **kwargs):
        reads.append(tuple(str(p) for p in paths))
        return real(paths, **kwargs)

    monkeypatch.setattr(intent, "load_trials", counting)
    kept = pipeline.KeptTrials()
    first = kept.load([a, b])
    again = kept.load([str(a), str(b)])  # the same folders, named otherwise
    assert len(reads) == 1 and again == first and again is not first  # a list of its own
    fresh = real([a, b])
    assert [t.id for t in again] == [t.id for t in fresh]
    for x, y in zip(again, fresh):
        assert x.trial.equals(y.trial)  # what load_trials gives, bit for bit
    kept.load([b])  # other folders: read, and kept instead
    assert len(reads) == 2
    kept.load([b])
    assert len(reads) == 2
    # a dataset written anew (its manifest and files) is read anew
    new = _dataset(b, 3)
    got = kept.load([b])
    assert len(reads) == 3 and got[0].trial.equals(new[0])
    # a trial file changed under the same manifest: its size or time differs, read again
    f = next(p for p in b.iterdir() if p.suffix == ".parquet")
    st = f.stat()
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    kept.load([b])
    assert len(reads) == 4
    # a path that is not a dataset folder is read every time, and not kept (the kept folders stay kept)
    kept.load([f])
    kept.load([f])
    assert len(reads) == 6
    kept.load([b])
    assert len(reads) == 6


class _Stop(Exception):
    pass


def test_a_pool_workers_trainings_load_through_the_kept_trials_and_the_runs_own_do_not(tmp_path, monkeypatch):
    import torch

    import coassist.intent as intent
    from coassist.experiments.reproduce_config import REPRODUCE_PRESETS

    cfg = REPRODUCE_PRESETS.lookup("tiny")
    folder = tmp_path / "A"
    _dataset(folder, 1)
    workspaces = []
    monkeypatch.setattr(pipeline, "train_and_score", lambda ws, *args, **kwargs: workspaces.append(ws))
    threads = torch.get_num_threads()
    try:
        pipeline.train_in_worker(cfg, tmp_path, "m", [folder], init="scratch", epochs=1)
    finally:
        torch.set_num_threads(threads)  # train_in_worker sets one thread, as a pool worker has
    (worker,) = workspaces
    own = pipeline.Workspace(cfg, tmp_path, progress=False)
    assert worker.keep_trials and not own.keep_trials

    kept, read = [], []

    class Kept:
        def load(self, paths):
            kept.append(list(paths))
            raise _Stop

    def load_trials(paths, **kwargs):
        read.append(list(paths))
        raise _Stop

    monkeypatch.setattr(pipeline, "KEPT_TRIALS", Kept())
    monkeypatch.setattr(intent, "load_trials", load_trials)
    for ws in (worker, own):
        with pytest.raises(_Stop):
            ws.train("m", [folder], init="scratch", epochs=1)
    assert kept == [[folder]] and read == [[folder]]
