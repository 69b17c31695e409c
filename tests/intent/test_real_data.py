"""Checks on the recorded UR5 trials (skipped when ../shared/data is absent)."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.data import default_real_data
from coassist.intent import WindowConfig, WindowSet, load_trials, split_trials

USER_A = default_real_data() / "user-a"

pytestmark = [
    pytest.mark.real_data,
    pytest.mark.skipif(not USER_A.is_dir(), reason=f"real recordings not found at {USER_A}"),
]


def test_user_a_split_and_windows():
    trials = load_trials([USER_A])
    ids = [lt.id for lt in trials]
    assert len(ids) == 15 and ids[0] == "ur5-thesis/user-a/trial_1"
    train, test = split_trials(ids, 0.2, seed=0)
    assert len(train) == 12 and len(test) == 3 and not set(train) & set(test)
    ws = WindowSet([trials[i].trial for i in test], WindowConfig(history=125, decimation=5, horizon=50), 0.008)
    x = ws.raw_inputs(np.arange(3))
    assert x.shape == (3, 25, 8) and np.isfinite(x).all()
