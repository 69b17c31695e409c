"""The constant-velocity intent source (``"constant-velocity"``): the tool's own motion, extrapolated.

ŷ_ref,h(k+i) = x(k) + i·dt·ẋ(k), i = 1 … horizon: the simplest learned-free predictor, and
to first order what a forecast of the tool becomes under assistance (docs/assistance.md).

This module is the worked example of docs/architecture.md's recipe *Add an intent source*:
one file holding a class that implements :class:`~coassist.interfaces.IntentSource` (built
from the horizon), and one line in :data:`coassist.scenario.intent_registry.INTENT_SOURCES`.
"""

from __future__ import annotations

import numpy as np

from coassist._checks import check_int
from coassist.interfaces import TrialContext

__all__ = ["ConstantVelocityIntent"]


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
