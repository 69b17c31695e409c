"""Where the controller's estimate of the operator's intent ŷ_ref,h comes from.

The world asks an :class:`IntentSource` once per tick for the operator's desired
positions over the next ``horizon`` ticks, from the last ``history`` samples of what
the robot measures. This is the interface the LSTM predictor (thesis §4.1, Fig. 4.1)
implements; the world builds the controller's human reference from it::

    ref_h[i] = [p̂(k+1+i) − x0,  (p̂(k+1+i) − p̂(k+i)) / dt]      i = 0 … H−1

(positions shifted into the controller's Δx frame; velocities by finite differences
along the prediction, the first row using the second row's difference).

History features, one row per tick, oldest first, thesis order (eq. 4.3–4.6, x-y)::

    FEATURES = (x, y, ẋ, ẏ, f_x, f_y, x_ref, y_ref)     [m, m, m/s, m/s, N, N, m, m]

x, y: measured tip position; ẋ, ẏ: its velocity; f: the force-sensor reading in use at
that tick (Trial.wrench); x_ref, y_ref: the planner's nominal reference (Trial.reference).
Row j of the window at tick k is exactly row k − history + 1 + j of the logged Trial,
so windows cut from logged trials are what the source sees online. Before ``history``
ticks have passed, the window is padded at the front with copies of tick 0's row (the
robot is at rest at the start).

Fallback: if ``predict`` raises, or returns anything other than a finite array of shape
(≥ controller horizon, 2), the world uses the nominal reference for that tick and sets
``Fault.PREDICTION_FALLBACK`` in Trial.fault.

Model-backed sources travel to worker processes as a path (see :func:`load_intent_source`),
never as an object: the intent package provides ``coassist.intent.load_model_intent(path)
-> IntentSource``.
"""

from __future__ import annotations

import numpy as np

from coassist._checks import check_int
from coassist.interfaces import NETWORK_BACKENDS, IntentSource, TrialContext


class NominalIntent:
    """ŷ_ref,h = y_ref,r: the thesis' assumption with no model loaded (eq. 4.7, dataset D0).

    The world recognises it and passes the planner's reference rows (positions and
    analytic velocities) as ref_h, so ref_h is exactly ref_r.
    """

    history = 0
    model_id = None

    def __init__(self, horizon: int = 50) -> None:
        self.horizon = check_int(horizon, "NominalIntent.horizon", 1)
        self._ref: np.ndarray | None = None
        self._k = 0

    def reset(self, context: TrialContext) -> None:
        self._ref = context.reference
        self._k = 0

    def predict(self, history: np.ndarray) -> np.ndarray:
        if self._ref is None:
            raise RuntimeError("NominalIntent.predict called before reset")
        k, self._k = self._k, self._k + 1
        return _rows(self._ref[:, :2], k, self.horizon)


class OracleIntent:
    """ŷ_ref,h = the operator's true intent: the best any predictor could do (simulation only)."""

    history = 0
    model_id = "oracle"

    def __init__(self, horizon: int = 50) -> None:
        self.horizon = check_int(horizon, "OracleIntent.horizon", 1)
        self._intent: np.ndarray | None = None
        self._k = 0

    def reset(self, context: TrialContext) -> None:
        if context.true_intent is None:
            raise ValueError("OracleIntent needs TrialContext.true_intent (simulated trials only)")
        self._intent = context.true_intent
        self._k = 0

    def predict(self, history: np.ndarray) -> np.ndarray:
        if self._intent is None:
            raise RuntimeError("OracleIntent.predict called before reset")
        k, self._k = self._k, self._k + 1
        return _rows(self._intent, k, self.horizon)


class ConstantVelocityIntent:
    """ŷ_ref,h(k+i) = x(k) + i·dt·ẋ(k): the tool's constant-velocity extrapolation, the
    simplest learned-free predictor (and to first order what a forecast of the tool
    becomes under assistance, docs/assistance.md). Reads the last feature row only."""

    history = 1
    model_id = "constant-velocity"

    def __init__(self, horizon: int = 50) -> None:
        self.horizon = check_int(horizon, "ConstantVelocityIntent.horizon", 1)
        self._steps: np.ndarray | None = None

    def reset(self, context: TrialContext) -> None:
        self._steps = float(context.dt) * np.arange(1, self.horizon + 1)[:, None]

    def predict(self, history: np.ndarray) -> np.ndarray:
        if self._steps is None:
            raise RuntimeError("ConstantVelocityIntent.predict called before reset")
        row = history[-1]
        return row[0:2] + self._steps * row[2:4]


def is_path_hypotheses(spec: str) -> bool:
    """Whether ``spec`` is a folder holding a calibrated ``paths`` source (not a trained model)."""
    from pathlib import Path

    from coassist.scenario.path_hypotheses import CALIBRATION_FILE

    return spec not in ("", "nominal", "oracle", "constant-velocity") and (Path(spec) / CALIBRATION_FILE).is_file()


def _rows(grid: np.ndarray, k: int, horizon: int) -> np.ndarray:
    """Rows k+1 … k+horizon of a (n, d) grid, holding the last row past the end."""
    n = grid.shape[0]
    if k + 1 + horizon <= n:
        return grid[k + 1 : k + 1 + horizon]
    idx = np.minimum(np.arange(k + 1, k + 1 + horizon), n - 1)
    return grid[idx]


def load_intent_source(spec: str, horizon: int = 50, network: str = "auto") -> IntentSource:
    """An intent source from its name or model path.

    ``"nominal"`` → :class:`NominalIntent`; ``"oracle"`` → :class:`OracleIntent`;
    ``"constant-velocity"`` → :class:`ConstantVelocityIntent`; ``"present"`` and ``"paths"``
    → :class:`~coassist.scenario.path_hypotheses.PathHypothesesIntent` (a folder holding its
    calibration, ``path-hypotheses.json``, → the calibrated one); any
    other string is a model path handed to ``coassist.intent.load_model_intent``
    (imported lazily, so the simulator works without the learning stack), its network
    evaluated by ``network`` (:data:`~coassist.interfaces.NETWORK_BACKENDS`).
    """
    if not isinstance(spec, str) or not spec:
        raise ValueError(f"intent must be 'nominal', 'oracle' or a model path, got {spec!r}")
    if network not in NETWORK_BACKENDS:
        raise ValueError(f"network must be one of {NETWORK_BACKENDS}, got {network!r}")
    if spec == "nominal":
        return NominalIntent(horizon)
    if spec == "oracle":
        return OracleIntent(horizon)
    if spec == "constant-velocity":
        return ConstantVelocityIntent(horizon)
    if spec in ("present", "paths") or is_path_hypotheses(spec):
        from coassist.scenario.path_hypotheses import PathHypothesesIntent, read_calibration

        if spec == "present":
            return PathHypothesesIntent(horizon, use_obstacles=False)
        return PathHypothesesIntent(horizon) if spec == "paths" else read_calibration(spec, horizon)
    try:
        from coassist.intent import load_model_intent
    except ImportError as exc:
        raise ValueError(
            f"intent {spec!r} is a model path, but coassist.intent.load_model_intent is not available ({exc})"
        ) from None
    try:
        return load_model_intent(spec, backend=network)
    except (OSError, ValueError) as exc:  # missing folder, bad sidecar, features or dt that do not match
        raise ValueError(f"intent {spec!r} could not be loaded as a model: {exc}") from None


def shared_intent_source(spec: str, horizon: int, cache: dict[tuple[str, int, str], IntentSource] | None,
                         network: str = "auto") -> IntentSource:  # fmt: skip
    """:func:`load_intent_source` through ``cache`` ((spec, horizon, network) → source), for runs in
    lockstep: a source with a ``batcher`` (a loaded model: stateless) is loaded once and
    shared, so one network call per tick serves every run; the others keep per-run state
    and are loaded per call. ``cache`` None: always loaded."""
    key = (spec, horizon, network)
    shared = None if cache is None else cache.get(key)
    if shared is not None:
        return shared
    source = load_intent_source(spec, horizon=horizon, network=network)
    if cache is not None and getattr(source, "batcher", None) is not None:
        cache[key] = source
    return source
