"""Model files: safetensors + JSON sidecar, round trip, refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coassist.intent import ModelFileError, ModelMismatchError, feature_names, load_model, save_model, train_model
from coassist.intent.training import write_model

from .conftest import make_trial


@pytest.fixture
def trained(trials, tiny):
    return train_model(trials, tiny, tiny.train)


def test_round_trip_gives_bit_identical_outputs(tmp_path, trained, trials):
    write_model(trained, tmp_path / "m")
    files = {p.name for p in (tmp_path / "m").iterdir()}
    assert {"weights.safetensors", "ridge.safetensors", "model.json", "history.json", "loss.png"} <= files
    assert not any(name.endswith((".tmp", ".pt", ".pkl")) for name in files)
    back = load_model(tmp_path / "m", features=feature_names(2), dt=0.008)
    t = trials[-1].trial
    a, b = trained.predict_trial(t), back.predict_trial(t)
    assert np.array_equal(a, b, equal_nan=True)
    assert np.array_equal(trained.ridge.predict_trial(t), back.ridge.predict_trial(t), equal_nan=True)
    side = json.loads((tmp_path / "m" / "model.json").read_text())
    for key in (
        "features",
        "input_scaler",
        "target_scaler",
        "history",
        "horizon",
        "dt",
        "dataset_ids",
        "preset",
        "network",
        "train_trials",
        "test_trials",
        "training_history",
    ):
        assert key in side, key
    assert side["features"] == ["x", "y", "vx", "vy", "fx", "fy", "x_ref", "y_ref"]
    assert back.info["training_history"] == trained.info["training_history"]


def test_refuses_mismatched_features_or_dt(tmp_path, trained):
    save_model(trained, tmp_path / "m")
    with pytest.raises(ModelMismatchError, match="features"):
        load_model(tmp_path / "m", features=feature_names(3))
    with pytest.raises(ModelMismatchError, match=r"dt = 0.002 s \(500 Hz\)"):
        load_model(tmp_path / "m", dt=0.002)
    # A trial at the wrong rate is refused when predicting too.
    with pytest.raises(ModelMismatchError, match="dt"):
        trained.predict_trial(make_trial(0, dt=0.002))
    with pytest.raises(ModelMismatchError, match="features"):
        trained.predict_trial(make_trial(0, d=1))


def test_tensors_of_other_shapes_are_refused_in_one_line(tmp_path, trained):
    import hashlib

    from safetensors import safe_open
    from safetensors.torch import save_file

    save_model(trained, tmp_path / "m")
    weights = tmp_path / "m" / "weights.safetensors"
    with safe_open(str(weights), "pt") as f:
        metadata = f.metadata()
        tensors = {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118 (safe_open is no mapping)
    name = next(k for k, t in tensors.items() if t.ndim == 2 and t.shape[0] != t.shape[1])
    tensors[name] = tensors[name].T.contiguous()  # the same numbers, another shape
    save_file(tensors, str(weights), metadata=metadata)
    side = json.loads((tmp_path / "m" / "model.json").read_text())
    side["weights_sha256"] = hashlib.sha256(weights.read_bytes()).hexdigest()
    (tmp_path / "m" / "model.json").write_text(json.dumps(side))
    with pytest.raises(ModelFileError, match=f"tensors do not fit the network.*size mismatch for {name}") as err:
        load_model(tmp_path / "m")
    assert "\n" not in str(err.value)


def test_refuses_weights_from_another_save(tmp_path, trained, trials, tiny):
    other = train_model(trials, tiny, type(tiny.train)(**{**tiny.train.__dict__, "seed": 5}))
    save_model(trained, tmp_path / "a")
    save_model(other, tmp_path / "b")
    (tmp_path / "a" / "weights.safetensors").write_bytes((tmp_path / "b" / "weights.safetensors").read_bytes())
    with pytest.raises(ModelFileError, match="hash"):
        load_model(tmp_path / "a")
    with pytest.raises(ModelFileError, match="not found"):
        load_model(tmp_path / "nothing-here")
