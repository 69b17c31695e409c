"""A pool worker keeps the trials of the dataset folders it last trained on (coassist.experiments.pipeline.KeptTrials)."""

from __future__ import annotations

import os

import numpy as np

from coassist.data import Trial, TrialMeta, write_dataset
from coassist.experiments import pipeline


def _dataset(folder, seed: int):
    rng = np.random.default_rng(seed)
    trials = []
    for k in range(2):
        n = 20
        trials.append(
            Trial(
                meta=TrialMeta(
                    user="user-0",
                    task="linear",
                    object="handle",
                    controller="manual",
                    model_id=None,
                    seed=seed + k,
                    origin="sim",
                    dt=0.008,
                ),
                time=np.arange(n) * 0.008,
                pose=rng.standard_normal((n, 2)),
                velocity=rng.standard_normal((n, 2)),
                wrench=rng.standard_normal((n, 2)),
                reference=rng.standard_normal((n, 2)),
            )
        )
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


def test_only_a_pool_workers_workspace_keeps_trials(tmp_path):
    from coassist.experiments.reproduce_config import REPRODUCE_PRESETS

    cfg = REPRODUCE_PRESETS.lookup("tiny")
    assert not pipeline.Workspace(cfg, tmp_path, progress=False).keep_trials  # the run's own process
    assert pipeline.Workspace(cfg, tmp_path, progress=False, keep_trials=True).keep_trials
