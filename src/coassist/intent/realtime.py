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
``max_age`` ticks, or one that failed the checks below, the nominal reference is used
(ŷ_ref,h = y_ref,r, eq. 4.7) and the tick is flagged :attr:`Fault.PREDICTION_FALLBACK`.
Whatever happens, :meth:`~RealtimePredictor.tick` returns (H, d) positions.

Checks (each counted in :meth:`~RealtimePredictor.health`):

- a prediction that raises, is non-finite or has the wrong shape is an *error*;
- a finite one that is implausible (farther than ``plausibility.max_distance`` from
  the tool, or faster than ``plausibility.max_speed``; see
  :func:`coassist.interfaces.prediction_plausible`) is *implausible*; both are dropped;
- a malformed or non-finite *sample* (wrong shape, strings, booleans, NaN) is replaced
  by the last good one for up to ``max_hold`` ticks in a row (24 ms at 125 Hz: an
  isolated dropout costs no prediction) and the tick is flagged
  :attr:`Fault.INVALID_INPUT`; a longer gap empties the history, so predictions resume
  one history (1 s for the default model) after the sensor recovers — the window the
  network needs is then entirely real again.

Backends (``benchmarks/bench_intent.py`` and ``benchmarks/bench_tick.py`` measure them):

- ``"torch"``: eager PyTorch in the worker thread. Its Python-level work holds the GIL,
  which the control thread then waits for (a tick's p99 grows by the network's time).
  It uses torch's thread count as the application set it (``torch.set_num_threads``) when the
  predictor was built; the worker thread applies it to itself, as a new thread's OpenMP team
  does not follow the setting of the thread that made it (measured: a thesis-size network's call
  8–12 ms on the main thread, a median of 29–43 ms and single calls of 3 s in a thread that did not
  apply it; 75 % of a 125 Hz run's ticks fell back).
- ``"onnx"``: ONNX Runtime with ``threads`` intra-op threads; ``session.run`` releases the
  GIL, so the control thread runs while the network does.
- ``"process"``: the model in a worker process of its own (``threads`` torch threads
  there); the worker thread only sends the window and waits on a pipe, which releases
  the GIL. Costs a second interpreter (≈ 1–3 s to start) and a copy of the model.
"""

from __future__ import annotations

import math
import multiprocessing
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from coassist._checks import as_real_array, check_int, check_optional_int
from coassist.intent.model import IntentModel
from coassist.interfaces import FEATURES, NETWORK_BACKENDS, Fault, PlausibilityLimits, prediction_plausible

__all__ = [
    "BACKENDS",
    "ModelIntent",
    "PredictionTick",
    "PredictorHealth",
    "ProcessRunner",
    "RealtimeConfig",
    "RealtimePredictor",
    "load_model_intent",
    "make_runner",
]

BACKENDS = ("torch", "onnx", "process")


@dataclass(frozen=True)
class RealtimeConfig:
    """max_age : ticks a prediction may be shifted before the fallback (≥ 0, < horizon);
        None: min(10, horizon − 1), i.e. 80 ms at 125 Hz.
    threaded : run the network off the control thread (worker thread; with
        ``backend="process"`` the thread waits on a worker process).
    backend : "torch", "onnx" or "process" (module docstring).
    threads : intra-op threads of the onnx and process backends (1: one core).
    max_hold : ticks in a row a bad sample is replaced by the last good one (≥ 0).
    plausibility : limits a prediction must meet to be used.
    """

    max_age: int | None = None
    threaded: bool = True
    backend: str = "torch"
    threads: int = 1
    max_hold: int = 3
    plausibility: PlausibilityLimits = field(default_factory=PlausibilityLimits)

    def __post_init__(self) -> None:
        object.__setattr__(self, "max_age", check_optional_int(self.max_age, "realtime.max_age", 0))
        if self.backend not in BACKENDS:
            raise ValueError(f"realtime.backend must be one of {BACKENDS}, got {self.backend!r}")
        object.__setattr__(self, "threads", check_int(self.threads, "realtime.threads", 1))
        if not isinstance(self.threaded, bool):
            raise ValueError(f"realtime.threaded must be a bool, got {self.threaded!r}")
        object.__setattr__(self, "max_hold", check_int(self.max_hold, "realtime.max_hold", 0))
        if not isinstance(self.plausibility, PlausibilityLimits):
            raise ValueError(f"realtime.plausibility must be a PlausibilityLimits, got {self.plausibility!r}")


class PredictionTick(NamedTuple):
    """What one tick gives the controller.

    positions : (H, d) predicted desired positions for ticks k+1 … k+H, in m (always
        this shape; on fallback the nominal reference, NaN where that was unusable).
    fault : Fault.NONE, PREDICTION_STALE or PREDICTION_FALLBACK, plus INVALID_INPUT
        when this tick's sample or nominal was malformed or non-finite.
    age : ticks between the prediction's input window and now (−1 on fallback).
    """

    positions: np.ndarray
    fault: Fault
    age: int


class PredictorHealth(NamedTuple):
    """A snapshot of the predictor's state (:meth:`RealtimePredictor.health`).

    alive : the worker thread (and worker process) is running, or the predictor is inline.
    busy : the network is running now.  busy_s : for how long [s] (0 when idle): a hung
        network shows here long before its result is missed.
    predictions : predictions accepted.  errors : raised, non-finite or misshapen.
    implausible : finite but rejected by the plausibility limits.
    held_samples : bad samples replaced by the last good one.  last_run_s : the network's
        last run time [s] (NaN before the first).
    """

    alive: bool
    busy: bool
    busy_s: float
    predictions: int
    errors: int
    implausible: int
    held_samples: int
    last_run_s: float


def _as_sample(x: Any, n: int) -> np.ndarray | None:
    """A finite float (n,) row (a copy: the caller may reuse its buffer), or None for anything
    else (strings, booleans, objects, NaN; :func:`coassist._checks.as_real_array`)."""
    a = as_real_array(x)
    if a is None or a.shape != (n,) or not np.isfinite(a).all():
        return None
    return a.copy()


# ---------------------------------------------------------------------- backends
class ProcessRunner:
    """The model in a worker process: ``runner(window (history, 4·d)) -> (H, d)``.

    The model travels as a model folder (safetensors + JSON, written to a private
    temporary folder), never pickled; windows and predictions travel as raw float64
    bytes over a pipe. A call blocks on the pipe (GIL released) until the answer comes.

    ``liveness_interval`` [s]: :meth:`alive` asks the OS at most this often and answers
    from the last check in between. The control loop asks every tick, and ``is_alive``
    right after the loop's sleep costs 10–40 µs on a VM, against 2 µs back to back
    (``benchmarks/bench_tick.py``); a death is still seen
    within 50 ms, inside the 0.2 s the loop allows before it flags the predictor
    stalled, and a call into a dead process fails at once.
    """

    def __init__(
        self, model: IntentModel, threads: int = 1, start_timeout: float = 120.0, liveness_interval: float = 0.05
    ) -> None:
        from coassist.intent.model import save_model

        self._tmp = tempfile.TemporaryDirectory(prefix="coassist-predictor-")
        folder = save_model(model, Path(self._tmp.name) / "model")
        self.shape = (model.horizon, model.n_dof)
        self.liveness_interval = float(liveness_interval)
        self._alive, self._alive_checked = True, -math.inf
        self.window_shape = (model.history, 4 * model.n_dof)
        ctx = multiprocessing.get_context("spawn")  # no fork of a process holding threads and torch state
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve_model, args=(str(folder), threads, child), name="intent-predictor", daemon=True
        )
        self._proc.start()
        child.close()
        # Poll with the process in view: a child that dies while importing never closes the pipe's
        # other end (the parent's resource sharer still holds it), so EOF alone would not tell.
        deadline, ready = time.monotonic() + start_timeout, False
        while time.monotonic() < deadline:
            if self._conn.poll(0.05):
                try:
                    ready = self._conn.recv_bytes() == b"ready"
                except (EOFError, OSError):
                    ready = False
                break
            if not self._proc.is_alive():
                break
        if ready:  # the worker has loaded its copy: nothing left behind should this process be killed
            self._tmp.cleanup()
        if not ready:
            self._proc.join(1.0)  # a child that closed its pipe and exited: reaped, so its exit code is known
            code = self._proc.exitcode
            waited = time.monotonic() - (deadline - start_timeout)
            self.close()
            why = f"it exited with code {code}" if code is not None else f"it did not answer within {waited:.0f} s"
            raise RuntimeError(f"the predictor's worker process did not start: {why} (its error is printed above)")

    def __call__(self, window: np.ndarray) -> np.ndarray:
        w = np.ascontiguousarray(window, dtype=np.float64)
        if w.shape != self.window_shape:
            raise ValueError(f"window must have shape {self.window_shape}, got {w.shape}")
        self._conn.send_bytes(w.tobytes())
        while not self._conn.poll(0.1):  # wait (GIL released) and notice a process that died meanwhile
            if not self._proc.is_alive():
                raise EOFError("the predictor's worker process died")
        out = self._conn.recv_bytes()  # EOFError when the process died: the caller counts an error
        if not out:
            raise RuntimeError("the worker process's prediction raised")
        return np.frombuffer(out, dtype=np.float64).reshape(self.shape).copy()

    def alive(self) -> bool:
        """Whether the worker process runs (asked of the OS at most every ``liveness_interval``)."""
        now = time.monotonic()
        if self._alive and now - self._alive_checked >= self.liveness_interval:
            self._alive, self._alive_checked = self._proc.is_alive(), now
        return self._alive

    def close(self) -> None:
        try:
            self._conn.close()
        except OSError:
            pass
        self._proc.join(timeout=2.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(timeout=2.0)
        self._tmp.cleanup()


def _serve_model(folder: str, threads: int, conn: Any) -> None:
    """The worker process: load the model, answer windows until the pipe closes."""
    from coassist.intent.model import load_model

    torch.set_num_threads(threads)  # this process's own setting: it runs nothing else
    model = load_model(folder)
    shape = (model.history, 4 * model.n_dof)
    conn.send_bytes(b"ready")
    while True:
        try:
            data = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            window = np.frombuffer(data, dtype=np.float64).reshape(shape)
            out = np.ascontiguousarray(model.predict(window), dtype=np.float64).tobytes()
        except Exception:  # a failing prediction is the parent's to count, not a dead worker
            out = b""
        try:
            conn.send_bytes(out)
        except (EOFError, OSError):
            return


def make_runner(model: IntentModel, backend: str = "torch", threads: int = 1) -> Callable[[np.ndarray], np.ndarray]:
    """A function raw history (history, 4·d) -> (H, d) positions, on the chosen backend.

    ``"torch"`` returns ``model.predict`` (torch's process-wide threads apply);
    ``"process"`` a :class:`ProcessRunner` (call ``close()`` when done).
    """
    if backend == "torch":
        return model.predict
    if backend == "process":
        return ProcessRunner(model, threads)
    if backend != "onnx":
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    from coassist.intent.onnx_network import OnnxIntentModel

    return OnnxIntentModel(model, threads).predict


class RealtimePredictor:
    """Per-tick intent prediction that never blocks on the network (see the module docstring).

    Use as a context manager, or call :meth:`close`, to stop the worker thread (and process).
    """

    def __init__(
        self,
        model: IntentModel,
        config: RealtimeConfig | None = None,
        *,
        runner: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.model = model
        self.config = config or RealtimeConfig()
        self.max_age = min(10, model.horizon - 1) if self.config.max_age is None else self.config.max_age
        if self.max_age >= model.horizon:
            raise ValueError(f"realtime.max_age must be < the model's horizon ({model.horizon}), got {self.max_age}")
        self._run = runner or make_runner(model, self.config.backend, self.config.threads)
        self.horizon, self.n_dof, self.n_features = model.horizon, model.n_dof, 4 * model.n_dof
        self.history = model.history
        self.dt = model.dt
        # A ring twice the history long: every window is one contiguous slice (no roll per tick).
        self._ring = np.zeros((2 * model.history, self.n_features))
        self._lock = threading.Condition()
        # (generation, k, window) / (generation, k, positions): a worker result from before a
        # reset() carries an old generation and is dropped, never served to the new trial.
        self._pending: tuple[int, int, np.ndarray] | None = None
        self._latest: tuple[int, int, np.ndarray] | None = None
        self._generation = 0
        self._stop = False
        self._busy_since: float | None = None  # the worker is running the network since (monotonic s)
        self._worker: threading.Thread | None = None
        self.errors = 0  # predictions that raised, were non-finite or misshapen
        self.implausible = 0  # finite predictions rejected by the plausibility limits
        self.predictions = 0
        self.held_samples = 0
        self._last_run = float("nan")
        self.reset()
        # the thread count the worker thread applies to itself (torch backend, module docstring)
        self._torch_threads = torch.get_num_threads() if self.config.backend == "torch" and runner is None else None
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
            self._held = 0
            self._last_good: np.ndarray | None = None
            self._pending = None
            self._latest = None

    def _fallback(self, nominal: Any, fault: Fault) -> PredictionTick:
        H, d = self.horizon, self.n_dof
        try:
            a = np.asarray(nominal)
            ok = a.ndim == 2 and a.shape[0] >= 1 and a.shape[1] == d and a.dtype.kind in "iuf"
        except Exception:
            ok = False
        if not ok:
            return PredictionTick(np.full((H, d), np.nan), fault | Fault.PREDICTION_FALLBACK | Fault.INVALID_INPUT, -1)
        a = a.astype(np.float64)
        pos = a[:H].copy() if len(a) >= H else np.concatenate([a, np.repeat(a[-1:], H - len(a), axis=0)])
        # A non-finite nominal goes out flagged: the controller's guard turns it into zero effort.
        bad = Fault.NONE if np.isfinite(pos).all() else Fault.INVALID_INPUT
        return PredictionTick(pos, fault | Fault.PREDICTION_FALLBACK | bad, -1)

    def tick(self, sample: Any, nominal: Any) -> PredictionTick:
        """Push this tick's features (4·d,) and get the prediction for k+1 … k+H.

        ``nominal`` is the planner's reference for ticks k+1 … k+H, (H, d) in m: the
        fallback. Never waits for the network, never raises on bad input (module docstring).
        """
        self._k += 1
        row = _as_sample(sample, self.n_features)
        flags = Fault.NONE
        if row is None:
            flags = Fault.INVALID_INPUT
            self.held_samples += 1
            self._held += 1
            if self._last_good is not None and self._held <= self.config.max_hold:
                row = self._last_good
            else:
                self._filled = 0  # too long a gap: the window must be real again before predicting
        else:
            self._held = 0
            self._last_good = row
        if row is not None:
            L = self.history
            i = self._k % L
            self._ring[i] = row
            self._ring[i + L] = row
            self._filled = min(self._filled + 1, L)
            if self._filled == L:
                window = self._ring[i + 1 : i + 1 + L].copy()
                if self.config.threaded:
                    with self._lock:
                        self._pending = (self._generation, self._k, window)
                        self._lock.notify()
                else:
                    self._store(self._generation, self._k, window)
        latest = self._latest  # one attribute read: the worker replaces the tuple whole, never edits it
        age = -1 if latest is None else self._k - latest[1]
        if not 0 <= age <= self.max_age:
            return self._fallback(nominal, flags)
        pos = latest[2]
        if age:
            pos = np.concatenate([pos[age:], np.repeat(pos[-1:], age, axis=0)])
        else:
            pos = pos.copy()  # the caller may write into it; the stored one is shifted later
        return PredictionTick(pos, flags | (Fault.PREDICTION_STALE if age else Fault.NONE), age)

    def health(self) -> PredictorHealth:
        """Whether the worker lives, what it is doing and what it has rejected (thread-safe)."""
        with self._lock:
            since = self._busy_since
            counts = (self.predictions, self.errors, self.implausible, self.held_samples, self._last_run)
        busy_s = 0.0 if since is None else time.monotonic() - since
        return PredictorHealth(self.worker_alive, since is not None, busy_s, *counts)

    @property
    def worker_alive(self) -> bool:
        """False once the worker thread or the worker process has died (inline: always True)."""
        if self._worker is not None and not self._worker.is_alive() and not self._stop:
            return False
        alive = getattr(self._run, "alive", None)
        return bool(alive()) if callable(alive) else True

    # ------------------------------------------------------------------ worker side
    def _store(self, generation: int, k: int, window: np.ndarray) -> None:
        t0 = time.perf_counter()
        plausible = True
        try:
            # a copy: a runner that writes into one buffer of its own would change the stored prediction
            pos = np.array(self._run(window), dtype=np.float64)
            ok = pos.shape == (self.horizon, self.n_dof) and bool(np.all(np.isfinite(pos)))
            if ok:
                plausible = prediction_plausible(pos, window[-1, : self.n_dof], self.dt, self.config.plausibility)
        except Exception:  # a failing network must not take the loop down: fall back
            ok = False
        with self._lock:
            self._last_run = time.perf_counter() - t0
            if not ok:
                self.errors += 1
            elif not plausible:
                self.implausible += 1
            elif generation == self._generation and (self._latest is None or k > self._latest[1]):
                self._latest = (generation, k, pos)
                self.predictions += 1

    def _work(self) -> None:
        if self._torch_threads is not None:
            torch.set_num_threads(self._torch_threads)  # this thread's OpenMP team (module docstring)
        while True:
            with self._lock:
                while self._pending is None and not self._stop:
                    self._lock.wait()
                if self._stop:
                    return
                generation, k, window = self._pending
                self._pending = None
                self._busy_since = time.monotonic()
            self._store(generation, k, window)
            with self._lock:
                self._busy_since = None

    def wait_idle(self, timeout: float = 1.0) -> None:
        """Testing aid: wait until the worker has no window pending and none in progress."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                if self._pending is None and self._busy_since is None:
                    return
            time.sleep(0.0005)

    def close(self) -> None:
        with self._lock:
            self._stop = True
            self._lock.notify()
        close_runner = getattr(self._run, "close", None)
        if callable(close_runner):
            close_runner()  # unblocks a worker thread waiting on a process
        if self._worker is not None:
            self._worker.join(timeout=2.0)

    def __enter__(self) -> RealtimePredictor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ModelIntent:
    """A trained model as the simulator's intent source (``coassist.interfaces.IntentSource``).

    The world calls :meth:`predict` once per tick with the last ``history`` feature rows
    and handles a raising or non-finite prediction itself (nominal fallback, flagged);
    the prediction is computed inside the tick, so a simulated trial is deterministic.
    On the real robot use :class:`RealtimePredictor`, which never waits for the network.

    ``model_id`` is ``<folder name>@<first 12 hex digits of the weights' SHA-256>``: the
    id recorded in every trial collected with this model in the loop (thesis D_{k+1}).
    ``backend``: what evaluates the network, "torch" or "onnx"
    (:mod:`coassist.intent.onnx_network`); ``network`` names it with its version, for the
    trial's record.
    """

    def __init__(self, model: IntentModel, model_id: str, backend: str = "torch") -> None:
        if backend not in ("torch", "onnx"):
            raise ValueError(f"backend must be 'torch' or 'onnx', got {backend!r}")
        self.model = model
        self.history, self.horizon, self.model_id = model.history, model.horizon, model_id
        if backend == "onnx":
            from coassist.intent.onnx_network import OnnxIntentModel

            onnx = OnnxIntentModel(model)
            self._batcher: Any = onnx
            self.network = onnx.network.runtime
        else:
            self._batcher = model
            self.network = f"torch {torch.__version__}"

    def reset(self, context: Any = None) -> None:
        """Refuse a trial whose sampling period differs from the model's."""
        if context is not None:
            self.model.check_compatible(None, context.dt, what="the simulated loop")

    def predict(self, history: np.ndarray) -> np.ndarray:
        return self._batcher.predict(history)

    @property
    def batcher(self) -> Any:
        """``predict_batch(histories (B, history, 8))``, the model's on the chosen backend: serves
        many trials' ticks in one network call (coassist.runtime.batched_loops); row b is
        ``predict(histories[b])`` up to the float32 rounding of batched kernels. Stateless,
        so trials may share it."""
        return self._batcher


def load_model_intent(path: str, backend: str = "auto") -> ModelIntent:
    """A model folder as an intent source for the simulated loop (see :class:`ModelIntent`).

    ``backend``: what evaluates the network, one of
    :data:`~coassist.interfaces.NETWORK_BACKENDS`: "torch", "onnx" (ONNX Runtime,
    1.6–1.9× faster at the loop's batch sizes, :mod:`coassist.intent.onnx_network`) or
    "auto": ONNX Runtime where the ``onnx`` extra is installed, else torch. The two agree
    to float32 rounding; each simulated trial records which one ran
    (``Trial.meta.extra["network"]``).

    Leaves torch's thread count alone: the simulator's worker processes set one thread
    each (one process per core); a single-process caller chooses its own.
    """
    from coassist.intent.model import load_model, unfinished

    if backend not in NETWORK_BACKENDS:
        raise ValueError(f"network backend must be one of {NETWORK_BACKENDS}, got {backend!r}")
    if backend == "auto":
        from coassist.intent.onnx_network import onnx_runtime_available

        backend = "onnx" if onnx_runtime_available() else "torch"
    model = load_model(path, features=FEATURES)
    if why := unfinished(model):  # a checkpoint in the loop: a model its training has not finished (review)
        raise ValueError(f"{path}: {why}")
    digest = str(model.weights_sha256)[:12]  # the weights that were loaded and verified
    return ModelIntent(model, f"{Path(path).name}@{digest}", backend)
