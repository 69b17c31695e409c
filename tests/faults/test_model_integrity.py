"""A model whose sidecar cannot be verified is refused (issue 37).

The probe re-saved a model's weights with ``safetensors``' own ``save_file`` (which keeps
the tensors and drops coassist's ``sidecar_sha256`` metadata), set ``weights_sha256`` to
the new file's hash and scaled ``target_scaler`` ×30: the model loaded with a warning
and pushed 100 N in the point-mass world. Every model coassist writes carries the record,
so refusing one without it loses no model the project made.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from coassist.intent import ModelFileError, load_model, save_model

from ..intent.conftest import TINY, labeled


def _resaved_without_metadata(model_dir: Path, tmp_path: Path, scale: float = 1.0) -> Path:
    """The model, its weights re-saved by safetensors.torch.save_file and the sidecar's hash updated to match."""
    from safetensors.torch import load_file, save_file

    folder = Path(shutil.copytree(model_dir, tmp_path / "m"))
    weights = folder / "weights.safetensors"
    save_file(load_file(weights), weights)  # the library's own writer: no __metadata__
    side = json.loads((folder / "model.json").read_text())
    side["weights_sha256"] = hashlib.sha256(weights.read_bytes()).hexdigest()
    sc = side["target_scaler"]
    side["target_scaler"] = {**sc, "lo": [scale * v for v in sc["lo"]], "hi": [scale * v for v in sc["hi"]]}
    (folder / "model.json").write_text(json.dumps(side))
    return folder


@pytest.mark.parametrize("scale", [1.0, 30.0])
def test_weights_resaved_without_the_sidecar_hash_are_refused(model_dir, tmp_path, scale):
    """Old code: loaded with a warning, the ×30 scaler included. Now: one line naming the file and the fix."""
    from safetensors import safe_open

    folder = _resaved_without_metadata(model_dir, tmp_path, scale)
    with safe_open(str(folder / "weights.safetensors"), "pt") as f:
        assert not (f.metadata() or {}).get("sidecar_sha256")  # the library's reader: the record is gone
    with pytest.raises(ModelFileError) as err:
        load_model(folder)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(f"{folder / 'weights.safetensors'}: carries no 'sidecar_sha256'")
    assert "model.json cannot be verified" in msg and "retrain" in msg and "re-export it with coassist" in msg


def test_every_model_coassist_writes_carries_the_record_and_loads(model_dir, tmp_path):
    """train (write_model), a re-save of a loaded model (transfer/finetune start, the predictor's copy), and a
    training checkpoint: each weights file holds the record, and each loads to the same predictions."""
    from safetensors import safe_open

    from coassist._io import partial_folder
    from coassist.intent.training import train_model

    def recorded(folder: Path) -> str | None:
        with safe_open(str(folder / "weights.safetensors"), "pt") as f:
            return (f.metadata() or {}).get("sidecar_sha256")

    trained = load_model(model_dir)
    resaved = save_model(trained, tmp_path / "copy")
    ckpt_out = tmp_path / "ckpt"
    train_model(labeled(3), TINY, replace(TINY.train, epochs=2), checkpoint_to=ckpt_out)
    # the per-epoch checkpoint stays until write_model completes the run
    for folder in (model_dir, resaved, partial_folder(ckpt_out)):
        assert recorded(folder), folder
        load_model(folder)
    x = np.random.default_rng(0).normal(size=(4, trained.history, trained.net.config.n_features)).astype(np.float32)
    np.testing.assert_array_equal(load_model(resaved).predict_batch(x), trained.predict_batch(x))


@pytest.mark.parametrize("key", ["ridge_sha256", "weights_sha256"])
def test_a_sidecar_without_a_digest_key_is_refused_in_one_line(model_dir, tmp_path, key):
    """A model.json edited by hand to drop a digest key: once a KeyError traceback for the ridge's."""
    folder = Path(shutil.copytree(model_dir, tmp_path / "m"))
    side = json.loads((folder / "model.json").read_text())
    del side[key]
    (folder / "model.json").write_text(json.dumps(side))
    with pytest.raises(ModelFileError) as err:
        load_model(folder)
    assert "\n" not in str(err.value) and f"{key!r} must be a hex digest" in str(err.value)


def test_a_sidecar_too_large_is_refused_as_that(model_dir, tmp_path):
    """The size refusal is said as it is (it had been wrapped as "malformed JSON: …" by the JSON refusals' handler)."""
    from coassist.intent.model import MAX_SIDECAR_BYTES

    folder = Path(shutil.copytree(model_dir, tmp_path / "m"))
    with open(folder / "model.json", "r+b") as f:
        f.truncate(MAX_SIDECAR_BYTES + 1)  # sparse: nothing read before the size is
    with pytest.raises(ModelFileError) as err:
        load_model(folder)
    assert str(err.value) == (
        f"{folder / 'model.json'}: larger than {MAX_SIDECAR_BYTES // 2**20} MiB: not a model sidecar"
    )


@pytest.mark.parametrize("key, value", [("n_dof", float("nan")), ("dt", float("inf")), ("foo", float("-inf"))])
def test_a_sidecar_holding_nan_or_infinity_is_refused_in_one_line(model_dir, tmp_path, key, value):
    """``"n_dof": NaN`` written by hand: once a bare ValueError from hashing the sidecar (allow_nan=False), and
    `coassist evaluate` printed its traceback. A sidecar coassist writes never holds one (save_model refuses them)."""
    from typer.testing import CliRunner

    from coassist.cli import app

    folder = Path(shutil.copytree(model_dir, tmp_path / "m"))
    side = json.loads((folder / "model.json").read_text())
    side[key] = value
    (folder / "model.json").write_text(json.dumps(side))  # json writes NaN / Infinity / -Infinity
    constant = json.dumps(value)
    with pytest.raises(ModelFileError) as err:
        load_model(folder)
    assert str(err.value) == (f"{folder / 'model.json'}: malformed JSON: {constant} is not a number a file may hold")
    res = CliRunner().invoke(app, ["evaluate", "--model", str(folder), "--data", str(tmp_path)])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and isinstance(res.exception, (SystemExit, type(None))), res.output
    assert f"{constant} is not a number a file may hold" in " ".join(res.output.split()), res.output
