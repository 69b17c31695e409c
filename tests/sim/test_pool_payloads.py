"""A job's trials travel from a pool's worker through a file in shared memory (coassist.sim.pool, issue 44)."""

from __future__ import annotations

import errno
import os
import pickle

import numpy as np
import pytest

from coassist.sim import pool as P


def _payloads() -> P.Payloads:
    rng = np.random.default_rng(3)
    return P.Payloads(
        [
            (
                {"trial": 0, "extra": {"ended": "target"}},
                {
                    "prediction": rng.standard_normal((2200, 50, 2)),  # 1.8 MB, a trial's predictions
                    "fault": rng.integers(0, 2**40, 2200),
                    "intent": None,
                    "empty": np.zeros((0, 50, 2)),
                    "strided": rng.standard_normal((40, 6))[:, ::2],  # not contiguous
                    "flags": np.array([True, False]),
                    "f32": rng.standard_normal(7).astype(np.float32),
                },
            ),
            ({"trial": 1}, {"time": np.arange(5) * 0.008, "prediction": None}),
        ]
    )


def _assert_same(a: list, b: list) -> None:
    assert type(b) is P.Payloads and len(a) == len(b)
    for (meta_a, arrays_a), (meta_b, arrays_b) in zip(a, b):
        assert meta_a == meta_b and list(arrays_a) == list(arrays_b)
        for name, x in arrays_a.items():
            y = arrays_b[name]
            if x is None:
                assert y is None
                continue
            # bit for bit: the same bytes, dtype and shape (NaN-safe, unlike ==)
            assert y.dtype == x.dtype and y.shape == x.shape and y.tobytes() == np.ascontiguousarray(x).tobytes()


def test_payloads_go_through_a_file_and_come_back_bit_for_bit(tmp_path, monkeypatch):
    items = _payloads()
    monkeypatch.setattr(P, "_worker_folder", tmp_path)  # as in a pool's worker
    sent = pickle.dumps(items)
    assert len(sent) < 2_000  # the file's name, the shapes and the metas; the arrays (1.8 MB) are in the file
    assert [p.suffix for p in tmp_path.iterdir()] == [".payload"]
    monkeypatch.setattr(P, "_worker_folder", None)  # the parent
    _assert_same(items, pickle.loads(sent))
    assert not list(tmp_path.iterdir())  # read once, then removed


def test_payloads_are_pickled_inline_where_there_is_no_folder_or_the_write_fails(tmp_path, monkeypatch):
    items = _payloads()
    inline = pickle.dumps(items)  # no pool (the parent, Ray's workers)
    assert len(inline) > 1_700_000
    _assert_same(items, pickle.loads(inline))
    monkeypatch.setattr(P, "_worker_folder", tmp_path / "gone")  # the pool's folder removed
    assert len(pickle.dumps(items)) > 1_700_000

    def full(fd, *args, **kwargs):  # a full tmpfs: the write fails with ENOSPC
        os.close(fd)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(P, "_worker_folder", tmp_path)
    monkeypatch.setattr(P.os, "fdopen", full)
    sent = pickle.dumps(items)
    assert len(sent) > 1_700_000 and not list(tmp_path.iterdir())  # inline, the half-written file removed
    _assert_same(items, pickle.loads(sent))
    # anything that is not a plain payload is pickled as it is
    odd = P.Payloads([({"trial": 0}, {"x": np.array(["a", "b"], dtype=object)})])
    monkeypatch.undo()
    monkeypatch.setattr(P, "_worker_folder", tmp_path)
    back = pickle.loads(pickle.dumps(odd))
    assert back[0][1]["x"].tolist() == ["a", "b"] and not list(tmp_path.iterdir())


def test_a_payload_file_that_is_gone_is_named_in_the_error(tmp_path, monkeypatch):
    monkeypatch.setattr(P, "_worker_folder", tmp_path)
    sent = pickle.dumps(_payloads())
    for f in tmp_path.iterdir():
        f.unlink()
    with pytest.raises(RuntimeError, match="which is gone"):
        pickle.loads(sent)


def test_a_pools_workers_send_through_its_folder_which_goes_with_the_pool(tmp_path):
    if not P.SHARED_MEMORY.is_dir():
        pytest.skip(f"no {P.SHARED_MEMORY} on this system: payloads are pickled inline (tested above)")
    # as a run that died leaves it: its pid above Linux's largest, so its process is gone
    stale = P.SHARED_MEMORY / f".{P.FOLDER_NAME}.{2**22 + 1}.0123abcd.new"
    stale.mkdir(exist_ok=True)
    (stale / "left.payload").write_bytes(b"0" * 10)
    items = _payloads()
    mine = f".{P.FOLDER_NAME}.{os.getpid()}.*.new"
    before = set(P.SHARED_MEMORY.glob(mine))
    with P.worker_pool(1) as pool:
        assert not stale.exists()  # a folder of a run that died is removed by the next pool
        (folder,) = set(P.SHARED_MEMORY.glob(mine)) - before
        assert pool.payload_folder == folder
        # the worker pickles the payloads it was given: through the pool's folder, as a job's result is
        sent = pool.submit(pickle.dumps, items).result()
        assert len(sent) < 2_000 and len(list(folder.iterdir())) == 1
        _assert_same(items, pickle.loads(sent))
        assert not list(folder.iterdir())
        # and a job's own result comes back through it, the same
        _assert_same(items, pool.submit(P.Payloads, items).result())
        assert not list(folder.iterdir())
    assert not folder.exists()


def test_a_trial_travels_whole_its_arms_joints_too():
    """trial_payload listed the fields to ship by hand and left out ``joints`` and ``joint_velocity``: a MuJoCo
    trial run in a worker arrived without its arm's joints. Every array field of Trial goes, bit for bit."""
    import dataclasses

    from coassist.data import Trial, TrialMeta

    rng = np.random.default_rng(5)
    n = 50
    arrays = {
        "time": np.arange(n) * 0.008,
        "pose": rng.standard_normal((n, 2)),
        "velocity": rng.standard_normal((n, 2)),
        "wrench": rng.standard_normal((n, 2)),
        "reference": rng.standard_normal((n, 2)),
        "prediction": rng.standard_normal((n, 4, 2)),
        "intent": rng.standard_normal((n, 2)),
        "effort_h": rng.standard_normal((n, 2)),
        "effort_r": rng.standard_normal((n, 2)),
        "fault": rng.integers(0, 2**20, n),
        "joints": rng.standard_normal((n, 6)),
        "joint_velocity": rng.standard_normal((n, 6)),
        "alpha": rng.uniform(0.0, 1.0, n),
    }
    assert set(arrays) == {f.name for f in dataclasses.fields(Trial)} - {"meta"}  # every field of Trial, set
    meta = TrialMeta(
        user="u0", task="linear", object="handle", controller="manual", model_id=None, seed=1, origin="sim", dt=0.008
    )
    trial = Trial(meta=meta, **arrays)
    back = P.trial_from_payload(pickle.loads(pickle.dumps(P.Payloads([P.trial_payload(trial)])))[0])
    assert back.equals(trial)
    for name, x in arrays.items():
        assert getattr(back, name).tobytes() == x.tobytes(), name
