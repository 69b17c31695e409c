"""LoopLog.prediction_or_plan by hand."""

import numpy as np

from coassist.runtime.loop import LoopLog


def _log(n, prediction=None):
    z = np.zeros((n, 2))
    return LoopLog(
        pose=z,
        velocity=z,
        wrench=z,
        reference=z,
        prediction=prediction,
        effort_h=z,
        effort_r=z,
        fault=np.zeros(n, dtype=np.int64),
        joints=None,
        joint_velocity=None,
        compute=np.zeros(n),
        ended="target",
    )


def test_the_plans_next_rows_at_every_tick_or_the_logged_prediction():
    plan = np.stack([np.arange(6.0), 10 + np.arange(6.0)], axis=1)  # row i = (i, 10 + i)
    out = _log(3).prediction_or_plan(plan, 2)
    # tick k gets rows k+1, k+2
    np.testing.assert_array_equal(out, [[[1, 11], [2, 12]], [[2, 12], [3, 13]], [[3, 13], [4, 14]]])
    logged = np.ones((3, 2, 2))
    assert _log(3, logged).prediction_or_plan(plan, 2) is logged
