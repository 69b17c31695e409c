"""The intent predictor inside the control loop, with a deadline.

Every tick (8 ms at 125 Hz) the loop calls :meth:`RealtimePredictor.tick` with the new
sample of the 4·d features and the planner's nominal reference for the next H ticks.
The tick never waits for the network:

- ``threaded=True`` (the default): the newest history window is handed to a worker
  thread (a one-slot mailbox: a window the worker has not started is replaced by a
  newer one), and the tick uses the newest finished prediction;
- ``threaded=False``: the prediction is computed inside the tick (deterministic; for
  simulation and tests, where the loop's clock is not the wall clock).

A prediction made at tick j for ticks j+1 … j+H is *shifted* when used at tick
k = j + a: rows a … H−1, then the last row held. With 0 < a ≤ ``max_age`` the tick is
flagged :attr:`Fault.PREDICTION_STALE`; with no prediction yet, one older than
``max_age`` ticks, or one with non-finite values, the nominal reference is used
(ŷ_ref,h = y_ref,r, eq. 4.7) and the tick is flagged :attr:`Fault.PREDICTION_FALLBACK`.

Backends: ``"torch"`` (eager) or ``"onnx"`` (ONNX Runtime; needs the ``onnx`` and
``onnxruntime`` packages). ``benchmarks/bench_intent.py`` measures both.
"""

from __future__ import annotations

import io
import threading
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from coassist.interfaces import FEATURES, Fault
from coassist.intent.model import IntentModel

__all__ = ["BACKENDS", "ModelIntent", "PredictionTick", "RealtimeConfig", "RealtimePredictor", "load_intent_source", "make_runner"]

BACKENDS = ("torch", "onnx")


@dataclass(frozen=True)
class RealtimeConfig:
    """max_age : ticks a prediction may be shifted before the fallback (≥ 0, < horizon);
        None: min(10, horizon − 1), i.e. 80 ms at 125 Hz.
    threaded : run the network in a worker thread.  backend : "torch" or "onnx".
    threads : intra-op threads of the backend (1: one core, the latency target)."""

    max_age: int | None = None
    threaded: bool = True
    backend: str = "torch"
    threads: int = 1

    def __post_init__(self) -> None:
        if self.max_age is not None and (isinstance(self.max_age, bool) or not isinstance(self.max_age, int) or self.max_age < 0):
            raise ValueError(f"realtime.max_age must be an integer >= 0, got {self.max_age!r}")
        if self.backend not in BACKENDS:
            raise ValueError(f"realtime.backend must be one of {BACKENDS}, got {self.backend!r}")
        if isinstance(self.threads, bool) or not isinstance(self.threads, int) or self.threads < 1:
            raise ValueError(f"realtime.threads must be an integer >= 1, got {self.threads!r}")
        if not isinstance(self.threaded, bool):
            raise ValueError(f"realtime.threaded must be a bool, got {self.threaded!r}")


class PredictionTick(NamedTuple):
    """What one tick gives the controller.

    positions : (H, d) predicted desired positions for ticks k+1 … k+H, in m.
    fault : Fault.NONE, PREDICTION_STALE or PREDICTION_FALLBACK.
    age : ticks between the prediction's input window and now (−1 on fallback).
    """

    positions: np.ndarray
    fault: Fault
    age: int


def make_runner(model: IntentModel, backend: str = "torch", threads: int = 1) -> Callable[[np.ndarray], np.ndarray]:
    """A function raw history (history, 4·d) -> (H, d) positions, on the chosen backend."""
    if backend == "torch":
        torch.set_num_threads(threads)
        return model.predict
    if backend != "onnx":
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    try:
        import onnxruntime as ort
    except ImportError:
        raise ImportError("backend 'onnx' needs onnxruntime (pip install onnxruntime==1.31.1)") from None
    steps, nf = model.window.steps, 4 * model.n_dof
    buf = io.BytesIO()
    net = model.net.eval()
    try:
        # The tracer's warnings concern shapes we fix (batch 1, ``steps`` rows): not the user's to act on.
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            torch.onnx.export(net, (torch.zeros(1, steps, nf),), buf, input_names=["x"], output_names=["y"],
                              dynamo=False)  # fmt: skip
    except Exception as exc:  # the exporter reports a missing 'onnx' package this way
        raise ImportError(f"ONNX export failed (is the 'onnx' package installed?): {exc}") from None
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    session = ort.InferenceSession(buf.getvalue(), opts, providers=["CPUExecutionProvider"])
    d = model.n_dof

    def run(history: np.ndarray) -> np.ndarray:
        h = np.asarray(history, dtype=np.float64)[None]
        x = model.input_scaler.transform(model.prepare(h)).astype(np.float32)
        out = session.run(None, {"x": x})[0]
        return model.outputs_to_positions(out, h[:, -1, :d], h[:, -1, d : 2 * d])[0]

    return run


class RealtimePredictor:
    """Per-tick intent prediction that never blocks on the network (see the module docstring).

    Use as a context manager, or call :meth:`close`, to stop the worker thread.
    """

    def __init__(self, model: IntentModel, config: RealtimeConfig | None = None, *,
                 runner: Callable[[np.ndarray], np.ndarray] | None = None) -> None:  # fmt: skip
        self.model = model
        self.config = config or RealtimeConfig()
        self.max_age = min(10, model.horizon - 1) if self.config.max_age is None else self.config.max_age
        if self.max_age >= model.horizon:
            raise ValueError(f"realtime.max_age must be < the model's horizon ({model.horizon}), got {self.max_age}")
        self._run = runner or make_runner(model, self.config.backend, self.config.threads)
        self.horizon, self.n_dof, self.n_features = model.horizon, model.n_dof, 4 * model.n_dof
        self._buf = np.zeros((model.history, self.n_features))
        self._lock = threading.Condition()
        # (generation, k, window) / (generation, k, positions): a worker result from before a
        # reset() carries an old generation and is dropped, never served to the new trial.
        self._pending: tuple[int, int, np.ndarray] | None = None
        self._latest: tuple[int, int, np.ndarray] | None = None
        self._generation = 0
        self._stop = False
        self._busy = False  # the worker is running the network
        self._worker: threading.Thread | None = None
        self.errors = 0  # predictions that raised or were non-finite
        self.reset()
        if self.config.threaded:
            self._worker = threading.Thread(target=self._work, name="intent-predictor", daemon=True)
            self._worker.start()

    # ------------------------------------------------------------------ loop side
    def reset(self, context: Any = None) -> None:
        """Start a new trial: empty history, no prediction."""
        with self._lock:
            self._generation += 1
            self._k = -1
            self._filled = 0
            self._pending = None
            self._latest = None

    def tick(self, sample: np.ndarray, nominal: np.ndarray) -> PredictionTick:
        """Push this tick's features (4·d,) and get the prediction for k+1 … k+H.

        ``nominal`` is the planner's reference for ticks k+1 … k+H, (H, d) in m: the
        fallback. Never waits for the network.
        """
        self._k += 1
        self._buf = np.roll(self._buf, -1, axis=0)
        self._buf[-1] = sample
        self._filled = min(self._filled + 1, len(self._buf))
        if self._filled == len(self._buf) and np.all(np.isfinite(self._buf)):
            window = self._buf.copy()
            if self.config.threaded:
                with self._lock:
                    self._pending = (self._generation, self._k, window)
                    self._lock.notify()
            else:
                self._store(self._generation, self._k, window)
        with self._lock:
            latest = self._latest
        age = -1 if latest is None else self._k - latest[1]
        if not 0 <= age <= self.max_age:
            # A non-finite nominal goes out flagged: the controller's guard turns it into zero effort.
            return PredictionTick(np.array(nominal, dtype=np.float64, copy=True), Fault.PREDICTION_FALLBACK, -1)
        pos = latest[2]
        if age:
            pos = np.concatenate([pos[age:], np.repeat(pos[-1:], age, axis=0)])
        else:
            pos = pos.copy()  # the caller may write into it; the stored one is shifted later
        return PredictionTick(pos, Fault.PREDICTION_STALE if age else Fault.NONE, age)

    # ------------------------------------------------------------------ worker side
    def _store(self, generation: int, k: int, window: np.ndarray) -> None:
        try:
            pos = np.asarray(self._run(window), dtype=np.float64)
            ok = pos.shape == (self.horizon, self.n_dof) and bool(np.all(np.isfinite(pos)))
        except Exception:  # a failing network must not take the loop down: fall back
            ok = False
        with self._lock:
            if not ok:
                self.errors += 1
            elif generation == self._generation and (self._latest is None or k > self._latest[1]):
                self._latest = (generation, k, pos)

    def _work(self) -> None:
        torch.set_num_threads(self.config.threads)
        while True:
            with self._lock:
                while self._pending is None and not self._stop:
                    self._lock.wait()
                if self._stop:
                    return
                generation, k, window = self._pending
                self._pending = None
                self._busy = True
            self._store(generation, k, window)
            with self._lock:
                self._busy = False

    def wait_idle(self, timeout: float = 1.0) -> None:
        """Testing aid: wait until the worker has no window pending and none in progress."""
        import time

        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                if self._pending is None and not self._busy:
                    return
            time.sleep(0.0005)

    def close(self) -> None:
        with self._lock:
            self._stop = True
            self._lock.notify()
        if self._worker is not None:
            self._worker.join(timeout=2.0)

    def __enter__(self) -> RealtimePredictor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ModelIntent:
    """A trained model as the simulator's intent source (``coassist.sim.IntentSource``).

    The world calls :meth:`predict` once per tick with the last ``history`` feature rows
    and handles a raising or non-finite prediction itself (nominal fallback, flagged);
    the prediction is computed inside the tick, so a simulated trial is deterministic.
    On the real robot use :class:`RealtimePredictor`, which never waits for the network.

    ``model_id`` is ``<folder name>@<first 12 hex digits of the weights' SHA-256>``: the
    id recorded in every trial collected with this model in the loop (thesis D_{k+1}).
    """

    def __init__(self, model: IntentModel, model_id: str) -> None:
        self.model = model
        self.history, self.horizon, self.model_id = model.history, model.horizon, model_id

    def reset(self, context: Any = None) -> None:
        """Refuse a trial whose sampling period differs from the model's."""
        if context is not None:
            self.model.check_compatible(None, context.dt, what="the simulated loop")

    def predict(self, history: np.ndarray) -> np.ndarray:
        return self.model.predict(history)


def load_intent_source(path: str, threads: int = 1) -> ModelIntent:
    """A model folder as an intent source for the simulated loop (see :class:`ModelIntent`).

    Sets torch's intra-op threads to ``threads``: the simulator runs one process per
    core, and more threads per process would oversubscribe them.
    """
    from coassist.intent.model import load_model, read_sidecar

    model = load_model(path, features=FEATURES)
    torch.set_num_threads(threads)
    digest = str(read_sidecar(path).get("weights_sha256", ""))[:12]
    return ModelIntent(model, f"{Path(path).name}@{digest}")
