"""The network on ONNX Runtime: torch's float32 network to float32 rounding, row for row, every batch size."""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("onnxruntime", reason="the onnx extra (onnxruntime) is not installed")
pytest.importorskip("onnx", reason="the onnx extra (onnx, the exporter's dependency) is not installed")

from coassist.intent import IntentNet, NetworkConfig, train_model  # noqa: E402
from coassist.intent.onnx_network import OnnxIntentModel, OnnxNetwork, onnx_runtime_available  # noqa: E402
from coassist.intent.realtime import ModelIntent, load_model_intent, make_runner  # noqa: E402

from .conftest import TINY, labeled, write_loop_model  # noqa: E402

#: Float32 rounding: both kernels sum dot products of at most 200 terms (the skip's
#: 25 × 8 inputs; the widest LSTM gate sums 2 × 64) in different orders; n·ε = 200 ×
#: 1.19e-7 = 2.4e-5 bounds the difference of one such sum of O(1) terms (gates saturate,
#: the recurrence contracts).
OUTPUT_ATOL = 2.4e-5


def windows(rng, batch: int, steps: int, features: int) -> np.ndarray:
    return rng.uniform(-1.0, 1.0, size=(batch, steps, features)).astype(np.float32)


@pytest.mark.parametrize(
    "config",
    [
        NetworkConfig(
            n_features=8, n_outputs=100, lstm_layers=2, hidden=64, fc=(64,), skip_inputs=25 * 8
        ),  # the lstm preset
        NetworkConfig(n_features=8, n_outputs=20, lstm_layers=1, hidden=8, fc=(8,)),
        NetworkConfig(n_features=8, n_outputs=20, lstm_layers=0, skip_inputs=10 * 8),  # the ridge as a network
        # two hypotheses: their weights softmax(ℓ/T) move by at most |Δℓ|/(4T) = |Δℓ| at T = 0.25 for two, the
        # logits' rounding that of a 64-term sum, times hypotheses O(1) apart: the same bound
        NetworkConfig(
            n_features=8, n_outputs=100, lstm_layers=2, hidden=64, fc=(64,), skip_inputs=25 * 8, hypotheses=2
        ),
    ],
    ids=["lstm-2x64-skip", "lstm-1x8", "linear", "lstm-2x64-skip-2-hypotheses"],
)
def test_outputs_equal_torch_to_float32_rounding_at_every_batch_size(config):
    steps = config.skip_inputs // config.n_features if config.skip_inputs else 25
    net = IntentNet(config, torch.Generator().manual_seed(3)).eval()
    if config.skip_inputs:  # a nonzero skip, so its path is checked too (init_skip zeroes the last FC layer)
        torch.nn.init.normal_(net.skip.weight, std=0.05, generator=torch.Generator().manual_seed(4))
    onnx = OnnxNetwork(net, steps)
    rng = np.random.default_rng(0)
    for batch in (1, 2, 9, 30):
        x = windows(rng, batch, steps, config.n_features)
        with torch.no_grad():
            expected = net(torch.from_numpy(x)).numpy()
        got = onnx(x)
        assert got.shape == expected.shape and got.dtype == np.float32
        np.testing.assert_allclose(got, expected, rtol=0, atol=OUTPUT_ATOL)
        # Row b of a batch is that window alone (to the same rounding): lockstep groups may share a call.
        alone = np.concatenate([onnx(x[b : b + 1]) for b in range(batch)])
        np.testing.assert_allclose(got, alone, rtol=0, atol=OUTPUT_ATOL)
        assert np.array_equal(onnx(x), got)  # same inputs, same batch: the same bits


def test_the_model_predicts_the_same_positions_on_both_backends():
    model = train_model(labeled(3), TINY, TINY.train)
    onnx = OnnxIntentModel(model)
    assert (onnx.history, onnx.horizon, onnx.n_dof) == (model.history, model.horizon, model.n_dof)
    rng = np.random.default_rng(1)
    hist = rng.normal(scale=0.02, size=(6, model.history, 4 * model.n_dof))
    # Positions are lo + (y + 1)/2 · (hi − lo) of the outputs plus a base that does not
    # depend on the network: the output tolerance times the widest scaled range.
    slope = float(np.max(model.target_scaler.hi - model.target_scaler.lo)) / 2
    np.testing.assert_allclose(onnx.predict_batch(hist), model.predict_batch(hist), rtol=0, atol=OUTPUT_ATOL * slope)
    np.testing.assert_allclose(onnx.predict(hist[2]), model.predict(hist[2]), rtol=0, atol=OUTPUT_ATOL * slope)
    with pytest.raises(ValueError, match=r"history must have shape \(B, 20, 8\)"):
        onnx.predict_batch(hist[:, :5])


def test_bad_networks_and_inputs_are_refused():
    net = IntentNet(NetworkConfig(n_features=8, n_outputs=20, lstm_layers=1, hidden=8, fc=(8,)))
    with pytest.raises(ValueError, match="float32"):
        OnnxNetwork(net.double(), 10)
    with pytest.raises(ValueError, match="steps"):
        OnnxNetwork(net.float(), 0)
    onnx = OnnxNetwork(net.float(), 10)
    with pytest.raises(ValueError, match=r"\(B, 10, 8\)"):
        onnx(np.zeros((2, 9, 8), np.float32))


def test_the_simulated_loops_backend_is_chosen_and_recorded(tmp_path):
    path = write_loop_model(tmp_path / "M", horizon=50)
    assert onnx_runtime_available()
    auto, torch_source = load_model_intent(path), load_model_intent(path, backend="torch")
    assert auto.network.startswith("onnxruntime ") and torch_source.network == f"torch {torch.__version__}"
    assert isinstance(auto.batcher, OnnxIntentModel) and torch_source.batcher is torch_source.model
    with pytest.raises(ValueError, match="backend must be 'torch' or 'onnx'"):
        ModelIntent(auto.model, "M@x", backend="tensorrt")
    with pytest.raises(ValueError, match="network backend must be one of"):
        load_model_intent(path, backend="tensorrt")
    # The real-time predictor's "onnx" backend is the same network.
    run = make_runner(auto.model, "onnx")
    hist = np.random.default_rng(2).normal(scale=0.02, size=(auto.history, 8))
    assert np.array_equal(run(hist), auto.predict(hist))
