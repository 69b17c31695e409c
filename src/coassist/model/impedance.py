"""Cartesian impedance model of the end effector (thesis §3.1, eq. 3.1–3.5).

The robot tip behaves as a mass-spring-damper driven by the human's measured
effort and the robot's virtual assistance::

    M a(t) + D v(t) + K Δx(t) = u_h(t) + u_r(t)                    (eq. 3.1)

With the state z = [Δx; v] (shape (2n,), Δx = x − x0 in m or rad, v in m/s or
rad/s) this is the linear system (eq. 3.2–3.4)::

    ż = A z + B u,    A = [[0, I], [−M⁻¹K, −M⁻¹D]],   B = [[0], [M⁻¹]]
    y = C z,          C = I (2n×2n): the output is position and velocity

Human and robot act through the same input matrix (B_h = B_r = B). Discretised
with sampling time dt (eq. 3.5)::

    z(k+1) = A_d z(k) + B_d (u_h(k) + u_r(k))

by an exact zero-order hold (the default, docs/architecture.md, *Conventions for the math*) or the bilinear (Tustin)
transform that the thesis group's own code uses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from coassist._checks import (
    as_square_matrix,
    check_positive_definite,
    check_positive_scalar,
    check_positive_semidefinite,
)

Discretization = Literal["zoh", "tustin"]


def continuous_matrices(M: np.ndarray, D: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A (2n, 2n) and B (2n, n) of eq. 3.3–3.4 for inertia M, damping D, stiffness K (n, n)."""
    n = M.shape[0]
    M_inv_D = np.linalg.solve(M, D)
    M_inv_K = np.linalg.solve(M, K)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-M_inv_K, -M_inv_D]])
    B = np.vstack([np.zeros((n, n)), np.linalg.solve(M, np.eye(n))])
    return A, B


#: The discretisations computed in this process, by their inputs' bytes (:func:`discretize`).
_DISCRETE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
#: At most this many are kept (the oldest goes first); a run uses a handful of (M, D, dt).
DISCRETE_CACHE_SIZE = 64


def discretize(
    A: np.ndarray, B: np.ndarray, dt: float, method: Discretization = "zoh"
) -> tuple[np.ndarray, np.ndarray]:
    """Discrete (A_d, B_d) of ż = A z + B u with sampling time ``dt`` [s] (eq. 3.5).

    ``"zoh"``: A_d = e^{A dt}, B_d = ∫₀^dt e^{A s} ds B, from one matrix exponential of
    the block matrix [[A, B], [0, 0]] dt (Van Loan), exact for piecewise-constant u.
    ``"tustin"``: A_d = (I − A dt/2)⁻¹(I + A dt/2), B_d = (I − A dt/2)⁻¹ B dt, the
    state-space form scipy.signal.cont2discrete uses with method="bilinear". That form
    also maps the output (C_d = C (I − A dt/2)⁻¹, D_d ≠ 0); like the thesis group's code
    we keep y = z, an approximation that only zero-order hold avoids.

    A (2n, 2n) and B (2n, n) float arrays; returns new arrays of the same shapes (the caller's
    to change). The result is remembered per process by the inputs' exact bytes, shapes,
    ``dt`` and ``method`` (at most :data:`DISCRETE_CACHE_SIZE`): every simulated trial builds
    its plant and controller models afresh, and the matrix exponential was 1.5 % of the main
    job's worker time (issue 44, docs/performance.md). The same inputs give the same bits
    either way: the function is deterministic in one process.
    """
    if method not in ("zoh", "tustin"):
        raise ValueError(f"discretization must be 'zoh' or 'tustin', got {method!r}")
    A, B = np.asarray(A), np.asarray(B)
    key = (method, float(dt), A.dtype.str, A.shape, B.dtype.str, B.shape, A.tobytes(), B.tobytes())
    known = _DISCRETE.get(key)
    if known is None:
        known = _discretize(A, B, dt, method)
        if len(_DISCRETE) >= DISCRETE_CACHE_SIZE:
            _DISCRETE.pop(next(iter(_DISCRETE)))
        _DISCRETE[key] = known
    return known[0].copy(), known[1].copy()


def _discretize(A: np.ndarray, B: np.ndarray, dt: float, method: Discretization) -> tuple[np.ndarray, np.ndarray]:
    """:func:`discretize` computed."""
    nx, nu = B.shape
    if method == "zoh":
        block = np.zeros((nx + nu, nx + nu))
        block[:nx, :nx] = A * dt
        block[:nx, nx:] = B * dt
        expm = scipy.linalg.expm(block)
        return expm[:nx, :nx], expm[:nx, nx:]
    if method == "tustin":
        eye = np.eye(nx)
        lhs = eye - A * (dt / 2.0)
        return np.linalg.solve(lhs, eye + A * (dt / 2.0)), np.linalg.solve(lhs, B * dt)
    raise ValueError(f"discretization must be 'zoh' or 'tustin', got {method!r}")


@dataclass(frozen=True, eq=False)  # arrays make field-wise == ambiguous: identity semantics
class ImpedanceModel:
    """The end effector's Cartesian impedance for 1 to 6 DOFs (eq. 3.1–3.5).

    Parameters
    ----------
    M : (n, n) inertia [kg, or kg·m² for rotations]; symmetric positive definite.
        A scalar or a length-n vector means a diagonal. The size n of M decides the
        number of DOFs (1 ≤ n ≤ 6).
    D : (n, n) damping [N·s/m]; symmetric positive semidefinite. Higher damping makes
        the tip feel more viscous: force per unit of velocity.
    K : (n, n) stiffness [N/m]; symmetric positive semidefinite. The spring pulling Δx
        back to zero; K = 0 (the thesis' choice) is free manual guidance.
    dt : sampling time [s], > 0 (0.008 s on a UR CB3, 0.002 s on an e-Series).
    discretization : "zoh" (exact, default) or "tustin".

    Attributes
    ----------
    A, B : continuous matrices, (2n, 2n) and (2n, n).
    Ad, Bd : discrete matrices, same shapes.
    C : (2n, 2n) identity: the output y = [position; velocity].
    """

    M: ArrayLike
    D: ArrayLike
    K: ArrayLike
    dt: float
    discretization: Discretization = "zoh"
    A: np.ndarray = field(init=False, repr=False, compare=False)
    B: np.ndarray = field(init=False, repr=False, compare=False)
    Ad: np.ndarray = field(init=False, repr=False, compare=False)
    Bd: np.ndarray = field(init=False, repr=False, compare=False)
    C: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        M = as_square_matrix(self.M, "M")
        n = M.shape[0]
        if not 1 <= n <= 6:
            raise ValueError(f"M must describe 1 to 6 Cartesian DOFs, got {n}x{n}")
        D = as_square_matrix(self.D, "D", n)
        K = as_square_matrix(self.K, "K", n)
        check_positive_definite(M, "M")
        check_positive_semidefinite(D, "D")
        check_positive_semidefinite(K, "K")
        dt = check_positive_scalar(self.dt, "dt")
        if self.discretization not in ("zoh", "tustin"):
            raise ValueError(f"discretization must be 'zoh' or 'tustin', got {self.discretization!r}")
        A, B = continuous_matrices(M, D, K)
        Ad, Bd = discretize(A, B, dt, self.discretization)
        for name, value in (
            ("M", M),
            ("D", D),
            ("K", K),
            ("dt", dt),
            ("A", A),
            ("B", B),
            ("Ad", Ad),
            ("Bd", Bd),
            ("C", np.eye(2 * n)),
        ):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_dof(self) -> int:
        """Number of Cartesian DOFs n."""
        return self.M.shape[0]

    @property
    def n_state(self) -> int:
        """State size 2n (position and velocity)."""
        return 2 * self.n_dof

    def with_stiffness(self, K: ArrayLike) -> ImpedanceModel:
        """The same model with another stiffness (e.g. K = 0 for manual guidance)."""
        return ImpedanceModel(self.M, self.D, K, self.dt, self.discretization)

    def step(self, z: np.ndarray, u: np.ndarray) -> np.ndarray:
        """One discrete step z(k+1) = A_d z(k) + B_d u(k); z (2n,), u (n,) total effort [N]."""
        return self.Ad @ z + self.Bd @ u
