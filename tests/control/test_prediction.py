"""F and Φ (eq. 3.9–3.12, docs/architecture.md's indexing) against step-by-step simulation."""

import numpy as np
import pytest

from coassist.control import prediction_matrices
from coassist.model import ImpedanceModel


@pytest.mark.parametrize("n, Np, Nc", [(1, 1, 1), (1, 7, 3), (2, 10, 10), (3, 12, 1), (6, 9, 4)])
def test_prediction_matches_simulation_with_held_input(n, Np, Nc):
    rng = np.random.default_rng(10 * n + Np)
    model = ImpedanceModel(rng.uniform(1, 10, n), rng.uniform(5, 50, n), rng.uniform(0, 100, n), 0.01)
    C = rng.normal(size=(3, 2 * n))  # any output matrix
    F, Phi = prediction_matrices(model.Ad, model.Bd, C, Np, Nc)
    assert F.shape == (3 * Np, 2 * n) and Phi.shape == (3 * Np, n * Nc)
    z0 = rng.normal(size=2 * n)
    U = rng.normal(size=(Nc, n))
    z = z0.copy()
    Y = []
    for i in range(Np):
        u = U[min(i, Nc - 1)]  # u(k+i), held at u(k+Nc−1) after the control horizon
        z = model.Ad @ z + model.Bd @ u
        Y.append(C @ z)  # y(k+i+1)
    np.testing.assert_allclose(F @ z0 + Phi @ U.reshape(-1), np.concatenate(Y), rtol=1e-12, atol=1e-13)


def test_control_horizon_longer_than_prediction_is_refused():
    model = ImpedanceModel(1, 1, 0, 0.01)
    with pytest.raises(ValueError, match="control_horizon must be <= horizon"):
        prediction_matrices(model.Ad, model.Bd, model.C, 3, 4)
    with pytest.raises(ValueError, match="horizon must be >= 1"):
        prediction_matrices(model.Ad, model.Bd, model.C, 0)
