"""Prediction matrices of the MPC (thesis eq. 3.8–3.12, indexing of docs/architecture.md's conventions).

Over a prediction horizon Np and control horizon Nc ≤ Np::

    Y(k) = F z(k) + Φ U(k)                                            (eq. 3.9)
    Y = [y(k+1); …; y(k+Np)]                         shape (m·Np,)    (eq. 3.10)
    U = [u(k); …; u(k+Nc−1)]                         shape (n·Nc,)
    F = [C A; C A²; …; C A^Np]                       shape (m·Np, nx) (eq. 3.11)
    Φ[i, j] = C A^(i−j) B   for j < Nc−1, j ≤ i     (block row i = 0…Np−1: y(k+i+1))
    Φ[i, Nc−1] = Σ_{l=Nc−1}^{i} C A^(i−l) B          (input held at u(k+Nc−1) after Nc)

Unlike eq. 3.12 the last input block accumulates the held input, and y(k+i) is
compared with the reference at k+i (eq. 3.13 and 3.18 shift these by one).
"""

from __future__ import annotations

import numpy as np

from coassist._checks import check_int_at_least


def prediction_matrices(
    A: np.ndarray, B: np.ndarray, C: np.ndarray, horizon: int, control_horizon: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """F (m·Np, nx) and Φ (m·Np, nu·Nc) for the discrete system (A, B, C).

    Parameters
    ----------
    A : (nx, nx) discrete state matrix A_d.
    B : (nx, nu) discrete input matrix B_d.
    C : (m, nx) output matrix.
    horizon : Np ≥ 1 samples.
    control_horizon : Nc, 1 ≤ Nc ≤ Np; None means Nc = Np.
    """
    Np = check_int_at_least(horizon, "horizon", 1)
    Nc = Np if control_horizon is None else check_int_at_least(control_horizon, "control_horizon", 1)
    if Nc > Np:
        raise ValueError(f"control_horizon must be <= horizon ({Np}), got {Nc}")
    nx, nu = B.shape
    m = C.shape[0]
    # Markov parameters CA^p B for p = 0…Np−1, and CA^p for p = 1…Np.
    markov = np.empty((Np, m, nu))
    F = np.empty((Np * m, nx))
    power = np.eye(nx)
    for p in range(Np):
        markov[p] = C @ power @ B
        power = A @ power
        F[p * m : (p + 1) * m] = C @ power
    Phi = np.zeros((Np * m, Nc * nu))
    for i in range(Np):
        rows = slice(i * m, (i + 1) * m)
        for j in range(min(i + 1, Nc - 1)):
            Phi[rows, j * nu : (j + 1) * nu] = markov[i - j]
        if i >= Nc - 1:
            # Held input: u(k+l) = u(k+Nc−1) for l ≥ Nc−1 contributes Σ CA^(i−l)B.
            Phi[rows, (Nc - 1) * nu :] = markov[: i - Nc + 2].sum(axis=0)
    return F, Phi
