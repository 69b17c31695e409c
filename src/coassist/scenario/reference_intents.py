"""The two intent sources every predictor sits between: the plan the robot knows, and the truth.

- :class:`NominalIntent` (``"nominal"``): ŷ_ref,h = y_ref,r, no prediction at all (the
  thesis' assumption with no model loaded, eq. 4.7, dataset D0);
- :class:`OracleIntent` (``"oracle"``): ŷ_ref,h = the simulated operator's true intent, the
  best any predictor could do (simulation only: it reads ``TrialContext.true_intent``).

Both are registered in :data:`coassist.scenario.intent_registry.INTENT_SOURCES`.
"""

from __future__ import annotations

import numpy as np

from coassist._checks import check_int
from coassist.interfaces import TrialContext

__all__ = ["NominalIntent", "OracleIntent"]


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
    #: It reads the simulated operator's intent: the episode hands TrialContext.true_intent to it alone.
    reads_true_intent = True

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


def _rows(grid: np.ndarray, k: int, horizon: int) -> np.ndarray:
    """Rows k+1 … k+horizon of a (n, d) grid, holding the last row past the end."""
    n = grid.shape[0]
    if k + 1 + horizon <= n:
        return grid[k + 1 : k + 1 + horizon]
    idx = np.minimum(np.arange(k + 1, k + 1 + horizon), n - 1)
    return grid[idx]
