"""The intent stage's array twin: WindowIntentBatch row for row against each WindowIntent."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.interfaces import Fault, TrialContext
from coassist.runtime.intent import WindowIntent, WindowIntentBatch


class WindowSource:
    """A model-like source: the window's last x-y plus its mean x-y times the row number."""

    model_id = "window-test"

    def __init__(self, history: int, horizon: int) -> None:
        self.history, self.horizon = history, horizon

    def reset(self, context: TrialContext) -> None:
        pass

    def predict(self, window: np.ndarray) -> np.ndarray:
        steps = np.arange(1, self.horizon + 1)[:, None]
        return window[-1, :2] + steps * window[:, :2].mean(axis=0)


@pytest.mark.parametrize("history", [0, 1, 4])
def test_the_batch_pushes_the_stages_windows_and_accepts_as_they_do(history):
    """Windows bit for bit those of each stage's push (the ring's padding at tick 0, its wrap),
    and ok where the stage's accept takes the row: a short answer, a NaN in the first horizon
    rows (a NaN past them is no fallback), for rows leaving as their runs end."""
    rng = np.random.default_rng(history)
    horizon, need, n = 5, 3, 6
    source = WindowSource(history, horizon)
    stages = [WindowIntent(source, need) for _ in range(n)]
    twins = [WindowIntent(source, need) for _ in range(n)]
    batch = WindowIntentBatch(twins)
    rows = np.arange(n)
    for k in range(3 * history + 4):
        if k == history + 2:
            rows = rows[1:]  # a run left
        features = rng.normal(0.0, 1.0, (rows.size, 8))
        windows = batch.push(k, rows, features)
        assert windows.shape == (rows.size, history, 8)
        for j, i in enumerate(rows.tolist()):
            assert windows[j].tolist() == stages[i].push(k, tuple(features[j])).tolist()
        answer = (
            np.stack([source.predict(w) for w in windows])
            if history
            else rng.normal(0.0, 1.0, (rows.size, horizon + 2, 2))
        )
        answer[0, 1, 0] = np.nan  # row 0: a NaN in use (a fallback)
        if rows.size > 1:
            answer[1, horizon:, :] = np.nan  # row 1: NaNs only past the horizon (taken)
        positions, ok = batch.accept(rows, answer)
        for j, i in enumerate(rows.tolist()):
            pred, flags = stages[i].accept(answer[j])
            assert bool(ok[j]) == (flags == Fault.NONE), (k, i)
            if ok[j]:
                assert positions[j].tolist() == pred.tolist()
        assert not ok[0] and (rows.size < 2 or ok[1])
    short = np.zeros((rows.size, need - 1, 2))  # fewer rows than the controller needs: every row a fallback
    assert not batch.accept(rows, short)[1].any()
    with pytest.raises(ValueError, match="malformed"):
        batch.accept(rows, np.zeros((rows.size + 1, horizon, 2)))


def test_the_batch_takes_stages_of_one_history_and_horizon_only():
    with pytest.raises(ValueError, match="history"):
        WindowIntentBatch([WindowIntent(WindowSource(2, 5), 3), WindowIntent(WindowSource(3, 5), 3)])
    with pytest.raises(ValueError, match="horizon"):
        WindowIntentBatch([WindowIntent(WindowSource(2, 5), 3), WindowIntent(WindowSource(2, 6), 3)])
