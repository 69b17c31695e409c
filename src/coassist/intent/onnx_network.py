"""The intent network on ONNX Runtime: the same float32 LSTM+FC, a faster kernel at the loop's batch sizes.

A simulated dataset with a model in the loop calls the network once per tick for a lockstep
group of B trials (B = 9 … 30 in the main job), and that call was most of the group's time.
torch's eager LSTM pays a fixed cost per step and layer that a small batch does not
amortise; ONNX Runtime's LSTM kernel does the same float32 arithmetic with less of it.
One thread, an ``lstm``-preset network (LSTM 2 × 64 over 25 steps, FC 64, the 200-input
skip; M_3 of a main-job run), ``benchmarks/bench_collect.py --only sweep`` on the
project's 2-core machine (median of 200 calls):

====  ===========  ============  =====
B     torch eager  ONNX Runtime  ratio
====  ===========  ============  =====
1     0.86 ms      0.31 ms       2.8×
9     2.13 ms      1.10 ms       1.9×
18    3.42 ms      1.97 ms       1.7×
30    5.22 ms      3.19 ms       1.6×
60    9.75 ms      6.27 ms       1.6×
====  ===========  ============  =====

:class:`OnnxNetwork` is the network exported once (``torch.onnx.export``, a dynamic batch
axis) and run by an ``InferenceSession`` on ``threads`` intra-op threads;
:class:`OnnxIntentModel` is an :class:`~coassist.intent.model.IntentModel`'s
``predict_batch`` / ``predict`` with the network there: the same checks, input frame,
scaling and decoding, only the network's kernel differs.

Exactness. Both evaluate the float32 network; their kernels sum in other orders, so
outputs differ by float32 rounding (≤ 1e-7 measured on outputs scaled to [−1, 1]; the
tests allow 2.4e-5, the worst-case n·ε of the widest float32 dot product, the skip's 200
terms), as torch's own
kernels do between batch sizes (:mod:`coassist.runtime.batched_loops`). For the same inputs
and batch size a session's output is deterministic. A float64 network (converted for an
exactness check) is refused: ONNX Runtime's LSTM kernel is float32 only.

Needs the ``onnx`` extra (``onnx`` for the exporter, ``onnxruntime``); ``./dev``
installs it. :func:`onnx_runtime_available` says whether it is there.
"""

from __future__ import annotations

import importlib.util
import io
import warnings

import numpy as np
import torch

from coassist._checks import check_int
from coassist.intent.model import IntentModel
from coassist.intent.network import IntentNet

__all__ = ["OnnxIntentModel", "OnnxNetwork", "onnx_runtime_available"]


def onnx_runtime_available() -> bool:
    """Whether the ``onnx`` extra is installed: ONNX Runtime and the ``onnx`` package the exporter needs."""
    return all(importlib.util.find_spec(name) is not None for name in ("onnxruntime", "onnx"))


class OnnxNetwork:
    """An :class:`~coassist.intent.network.IntentNet` exported to ONNX and run by ONNX Runtime.

    ``OnnxNetwork(net, steps)(x)``: scaled windows x (B, steps, n_features) float32 →
    outputs (B, n_outputs) float32, what ``net(x)`` gives up to float32 rounding (module
    docstring). The weights are copied into the graph when it is built: later changes to
    ``net`` are not seen. ``threads``: ONNX Runtime's intra-op threads (1: one core, what a
    simulation worker process has).
    """

    def __init__(self, net: IntentNet, steps: int, threads: int = 1) -> None:
        steps = check_int(steps, "steps", 1)
        threads = check_int(threads, "threads", 1)
        if any(p.dtype != torch.float32 for p in net.parameters()):
            raise ValueError("OnnxNetwork runs float32 networks only (ONNX Runtime's LSTM kernel is float32)")
        try:
            import onnxruntime as ort
        except ImportError:
            raise ImportError("the ONNX Runtime backend needs the onnx extra (pip install 'coassist[onnx]')") from None
        self.n_features, self.steps = net.config.n_features, steps
        buf = io.BytesIO()
        was_training = net.training
        net.eval()
        try:
            # The tracer warns about shapes it fixes (``steps`` rows); the batch axis stays free.
            with torch.no_grad(), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                # a file-like object is accepted (torch.onnx.export's docs), not in its annotation
                torch.onnx.export(
                    net,
                    (torch.zeros(2, steps, self.n_features),),
                    buf,  # type: ignore[arg-type]
                    input_names=["x"],
                    output_names=["y"],
                    dynamic_axes={"x": {0: "batch"}, "y": {0: "batch"}},
                    dynamo=False,
                )
        except Exception as exc:  # the exporter reports a missing 'onnx' package this way
            raise ImportError(f"ONNX export failed (is the 'onnx' package installed?): {exc}") from None
        finally:
            net.train(was_training)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        self._session = ort.InferenceSession(buf.getvalue(), opts, providers=["CPUExecutionProvider"])
        #: What evaluates the network, for a trial's record: "onnxruntime <version>".
        self.runtime = f"onnxruntime {ort.__version__}"

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float32)
        if x.ndim != 3 or x.shape[1:] != (self.steps, self.n_features):
            raise ValueError(f"network input must have shape (B, {self.steps}, {self.n_features}), got {x.shape}")
        return self._session.run(None, {"x": x})[0]


class OnnxIntentModel:
    """An :class:`~coassist.intent.model.IntentModel`'s ``predict_batch`` and ``predict`` with
    its network on ONNX Runtime (:class:`OnnxNetwork`): raw histories in, positions (m) out.

    Everything but the network's kernel is the model's own code (history checks, input
    frame, scaling, decoding), so the two differ by the network's float32 rounding only.
    """

    def __init__(self, model: IntentModel, threads: int = 1) -> None:
        self.model = model
        self.network = OnnxNetwork(model.net, model.window.steps, threads)
        self.history, self.horizon, self.n_dof = model.history, model.horizon, model.n_dof

    def predict_batch(self, history: np.ndarray) -> np.ndarray:
        """Predicted positions (B, H, d) in m from raw histories (B, history, 4·d), as
        :meth:`IntentModel.predict_batch <coassist.intent.model.IntentModel.predict_batch>`."""
        model = self.model
        h = model.checked_history(history)
        return model.history_positions(self.network(model.scale_inputs(model.prepare(h)).numpy()), h)

    def predict(self, history: np.ndarray) -> np.ndarray:
        """One prediction: raw history (history, 4·d) -> (H, d) positions in m."""
        return self.predict_batch(np.asarray(history, dtype=np.float64)[None])[0]
