"""Two-player linear-quadratic MPC games between human and robot (thesis §3.2).

Notation. Both players act on one impedance model through the same input matrix::

    Y = F z + Φ U_h + Φ U_r                                               (eq. 3.9)

Y, U_h, U_r stack y(k+1…k+Np) and u_·(k…k+Nc−1) (:mod:`coassist.control.prediction`).
Y_h and Y_r stack the human's and the robot's *reference outputs* y_ref,h, y_ref,r at
k+1…k+Np, each (Np·2n,) [m, m/s]. Effort weights are R_h, R_r (n, n) [1/N²] and
R̃_p = blkdiag(R_p, …, R_p) over the control horizon (eq. 3.21–3.22). Each player scores
the predicted output against both references (y(k+i) against the references at k+i,
docs/architecture.md's conventions)::

    J_p = Σ_i e_h(k+i)' W_p,h e_h(k+i) + e_r(k+i)' W_p,r e_r(k+i) + U_p' R̃_p U_p
    e_h = y − y_ref,h,   e_r = y − y_ref,r                       (eq. 3.15–3.16)

**Cooperative** (eq. 3.17, 3.23–3.26): both players share the state cost
Q_gt = α Q̃_h + (1 − α) Q̃_r with Q_h = blkdiag(Q_hh, Q_hr), Q_r = blkdiag(Q_rh, Q_rr),
so W_h,h = W_r,h = α Q_hh + (1 − α) Q_rh and W_h,r = W_r,r = α Q_hr + (1 − α) Q_rr.
The augmented system of eq. 3.7 stacks two copies of the same state, so its output is
[y; y] and its cost reduces exactly to the form above. Input weights stay R_h, R_r
(eq. 3.17); ``input_weighting="alpha_scaled"`` uses α R_h and (1 − α) R_r as the
thesis group's code does.

**Nash** (non-cooperative): each player keeps its own Q, W_h,· = (Q_hh, Q_hr) and
W_r,· = (Q_rh, Q_rr), no α mixing.

The equilibrium solves both players' first-order conditions (eq. 3.27–3.31). With
Ŵ = blkdiag over the horizon of a W, W̄_p = Ŵ_p,h + Ŵ_p,r (player p's whole state
weight) and P_p = Φ' W̄_p Φ::

    [P_h + R̃_h   P_h      ] [U_h]   [Φ'(Ŵ_h,h Y_h + Ŵ_h,r Y_r − W̄_h F z)]
    [P_r         P_r + R̃_r] [U_r] = [Φ'(Ŵ_r,h Y_h + Ŵ_r,r Y_r − W̄_r F z)]

In the thesis' notation (eq. 3.27–3.30) this is U_h = −K_h U_r + L_h Z with
S_h = (Φ' Q_gt Φ + R̃_gt,h)⁻¹ Φ' Q_gt (eq. 3.28, a gain, not the weight W̄_h above) and
K_h = S_h Φ_r: the coupling gain multiplies the *other* player's input (the thesis
writes S_h Φ_h, equal only because Φ_h = Φ_r). In the cooperative game the matrix is
symmetric positive definite — it is the Hessian of the shared cost plus both input
costs, whose minimiser is therefore the equilibrium — and is factored by Cholesky;
the Nash matrix is not symmetric and is LU-factored.

The system is LTI, so only the rows of the solution that the receding horizon
applies (u_h(k), u_r(k)) are kept, as gains::

    [u_h(k); u_r(k)] = G_z z + G_h vec(Y_h) + G_r vec(Y_r)

and a control tick is three matrix-vector products.

**Online α** (the thesis' future work). In the cooperative game the matrix above and
its right-hand side are both affine in α: H(α) = H(α₀) + β ΔH, T(α) = T(α₀) + β ΔT,
β = α − α₀ (with either input weighting). :meth:`CooperativeGame.prepare_alpha_changes`
solves the generalized symmetric eigenproblem ΔH V = H(α₀) V Λ once (V' H(α₀) V = I),
so that H(α)⁻¹ = V (I + βΛ)⁻¹ V' and the first-step gains are::

    G(α) = E'V (I + βΛ)⁻¹ V' (T₀ + β ΔT)
         = C₀ + β C₁ + Σ_{λ_j ≠ 0} a_j (b₀_j + β b₁_j)' / (1 + β λ_j)

Directions with λ_j = 0 fold into the constant C₀, C₁; with the thesis' weights
(Q_hh = Q_rr, Q_hr = Q_rh = 0, shared input weights) ΔH = 0 and the gains are exactly
affine in α, so a new α costs one scaled add of the (2n, 2n + 2·Np·2n) gain matrix.

With other weights the sum above costs about 2n·r·p multiply-adds per α (r up to 2N, p
the gains' columns: 4.4 M at 6 DOF, Np = 50, r = 300). Its poles β = −1/λ_j lie outside the
α range, where H(α) is positive definite, so on each of ``_AlphaFamily.PIECES`` (16) equal
stretches of [0, 1] the gains are a Chebyshev series of low degree K::

    G(α) = Σ_{k=0…K} c_k T_k(t),   t = 2(α − a)/w − 1 on the stretch [a, a + w]

fitted at the K + 1 Chebyshev points of the stretch and accepted only where it matches the
exact sum to 1e-11 (relative to the stretch's largest gain) at both ends and at the
extrema of T_{K+1}, which fall between the points; a stretch where no degree up to 16
does (a pole too close) keeps the exact sum. A new α then costs (K + 1)·2n·p
multiply-adds. Where the series would take more than ``_AlphaFamily.MAX_BYTES`` (64 MiB)
every α uses the exact sum.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike
from threadpoolctl import threadpool_limits

from coassist._checks import refuse_truth_value
from coassist.config import GameParameters, GameWeights
from coassist.control.prediction import prediction_matrices
from coassist.model.impedance import ImpedanceModel

InputWeighting = Literal["shared", "alpha_scaled"]


def _weights(weights: GameWeights | None, n_dof: int, given: dict[str, ArrayLike | None]) -> GameWeights:
    """The game's weights: ``weights``, or a :class:`GameWeights` of the six keywords (``given``), not both.

    The keywords are sugar (the README's example writes them): they build the one
    :class:`GameWeights` the game then reads, as ``GameWeights(**given, n_dof=n_dof)``.
    """
    passed = [name for name, value in given.items() if value is not None]
    if weights is not None:
        if not isinstance(weights, GameWeights):
            raise ValueError(f"weights must be a GameWeights, got {type(weights).__name__}")
        if passed:
            raise ValueError(
                f"give the weights as a GameWeights or as keywords, not both (got weights and {', '.join(passed)})"
            )
        if weights.n_dof != n_dof:
            raise ValueError(f"weights are for {weights.n_dof} DOFs, the model has {n_dof}")
        return weights
    missing = [name for name, value in given.items() if value is None]
    if missing:
        raise ValueError(f"the game needs its weights: a GameWeights, or the keywords {', '.join(missing)}")
    return GameWeights(**given, n_dof=n_dof)  # type: ignore[arg-type]


@dataclass(frozen=True)
class EquilibriumGains:
    """First-step gains of the equilibrium: [u_h(k); u_r(k)] = G_z z + G_h ref_h + G_r ref_r.

    Shapes: G_z (2n, 2n), G_h and G_r (2n, Np·m); rows 0…n−1 give u_h, n…2n−1 give u_r.
    """

    G_z: np.ndarray
    G_h: np.ndarray
    G_r: np.ndarray


class _LinearQuadraticGame:
    """Shared machinery: prediction matrices, per-weight products, the equilibrium solve."""

    def __init__(
        self, model: ImpedanceModel, weights: GameWeights, *, horizon: int, control_horizon: int | None
    ) -> None:
        n, m = model.n_dof, model.C.shape[0]
        if m != 2 * n:  # the weights are on [position; velocity] (ImpedanceModel's C = I)
            raise ValueError(f"the game needs the model's output [position; velocity] (2n = {2 * n} rows), got {m}")
        self.model = model
        self._n, self._m = n, m
        self.weights = weights
        Qs = weights.Q
        self.Q = Qs
        self.R_h, self.R_r = weights.R_h, weights.R_r
        self.F, self.Phi = prediction_matrices(model.Ad, model.Bd, model.C, horizon, control_horizon)
        self.horizon = horizon
        self.control_horizon = horizon if control_horizon is None else control_horizon
        Np, Nc = self.horizon, self.control_horizon
        # Φ' Ŵ for Ŵ = blkdiag over the horizon of each Q: the cost is linear in the
        # four Q's, so these products are all an α change needs (no rebuild of Φ'QΦ).
        phi_blocks = self.Phi.reshape(Np, m, Nc * n)
        self._PtQ = {k: np.einsum("imj,mq->jiq", phi_blocks, Q).reshape(Nc * n, Np * m) for k, Q in Qs.items()}
        self._PtQP = {k: PtQ @ self.Phi for k, PtQ in self._PtQ.items()}
        self._PtQF = {k: PtQ @ self.F for k, PtQ in self._PtQ.items()}
        self._R_h_tilde = np.kron(np.eye(Nc), self.R_h)
        self._R_r_tilde = np.kron(np.eye(Nc), self.R_r)
        self._ref_shape = (Np, m)
        self._z_shape = (model.n_state,)

    @property
    def n_dof(self) -> int:
        return self._n

    @property
    def reference_shape(self) -> tuple[int, int]:
        """Shape (Np, 2n) of ref_h and ref_r: [position; velocity] at k+1…k+Np."""
        return self._ref_shape

    # -- weights of each player, as coefficients on (Q_hh, Q_hr, Q_rh, Q_rr) -------------
    def _player_weights(
        self, alpha: float | None
    ) -> tuple[dict[str, float], dict[str, float], dict[str, float], dict[str, float]]:
        """(W_h,h, W_h,r, W_r,h, W_r,r) as linear combinations of the four Q's."""
        raise NotImplementedError

    def _input_weights(self, alpha: float | None) -> tuple[np.ndarray, np.ndarray]:
        return self._R_h_tilde, self._R_r_tilde

    @staticmethod
    def _combine(terms: dict[str, np.ndarray], coeffs: dict[str, float]) -> np.ndarray:
        out = np.zeros_like(next(iter(terms.values())))
        for name, c in coeffs.items():
            if c != 0.0:
                out += c * terms[name]
        return out

    def _assemble(self, alpha: float | None) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
        """The stacked first-order conditions: matrix H and, per player, Φ'Ŵ_·,h, Φ'Ŵ_·,r, Φ'S F."""
        w_hh, w_hr, w_rh, w_rr = self._player_weights(alpha)
        R_h, R_r = self._input_weights(alpha)
        cache: dict = {}

        def combine(terms: dict[str, np.ndarray], coeffs: dict[str, float]) -> np.ndarray:
            # In the cooperative game both players' terms are equal: build each once,
            # and let _compute_gains see that they are the same object.
            key = (id(terms), tuple(sorted(coeffs.items())))
            if key not in cache:
                cache[key] = self._combine(terms, coeffs)
            return cache[key]

        P_h = combine(self._PtQP, _add(w_hh, w_hr))
        P_r = combine(self._PtQP, _add(w_rh, w_rr))
        H = np.block([[P_h + R_h, P_h], [P_r, P_r + R_r]])
        ref_h_terms = [combine(self._PtQ, w_hh), combine(self._PtQ, w_rh)]
        ref_r_terms = [combine(self._PtQ, w_hr), combine(self._PtQ, w_rr)]
        state_terms = [combine(self._PtQF, _add(w_hh, w_hr)), combine(self._PtQF, _add(w_rh, w_rr))]
        return H, ref_h_terms, ref_r_terms, state_terms

    def _factor(self, H: np.ndarray):
        raise NotImplementedError

    def _solve_factored(self, factor, rhs: np.ndarray, transposed: bool = False) -> np.ndarray:
        raise NotImplementedError

    def _compute_gains(self, alpha: float | None = None) -> None:
        H, ref_h_terms, ref_r_terms, state_terms = self._assemble(alpha)
        factor = self._factor(H)
        n, N = self._n, self._n * self.control_horizon
        # Only u_h(k) and u_r(k) are applied: the rows E' H⁻¹ suffice, found from H' X = E.
        E = np.zeros((2 * N, 2 * n))
        E[:n, :n] = np.eye(n)
        E[N : N + n, n:] = np.eye(n)
        X = self._solve_factored(factor, E, transposed=True).T  # (2n, 2N) = E' H⁻¹
        X_h, X_r = X[:, :N], X[:, N:]
        X_sum = None

        def apply(terms: list[np.ndarray]) -> np.ndarray:
            nonlocal X_sum
            if terms[0] is terms[1]:
                if X_sum is None:
                    X_sum = X_h + X_r
                return X_sum @ terms[0]
            return X_h @ terms[0] + X_r @ terms[1]

        gains = EquilibriumGains(G_z=-apply(state_terms), G_h=apply(ref_h_terms), G_r=apply(ref_r_terms))
        for g in (gains.G_z, gains.G_h, gains.G_r):
            g.setflags(write=False)
        # One attribute assignment: a concurrent tick sees the old gains or the new, never a mix.
        self._state = (gains, factor, ref_h_terms, ref_r_terms, state_terms, alpha)

    @property
    def gains(self) -> EquilibriumGains:
        return self._state[0]

    def _check_refs(self, ref_h: np.ndarray, ref_r: np.ndarray) -> None:
        if ref_h.shape != self._ref_shape:
            raise ValueError(f"ref_h must have shape {self._ref_shape} (horizon, 2n), got {ref_h.shape}")
        if ref_r.shape != self._ref_shape:
            raise ValueError(f"ref_r must have shape {self._ref_shape} (horizon, 2n), got {ref_r.shape}")

    def solve(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """First-step equilibrium efforts (u_h(k), u_r(k)), each (n,) [N or N·m].

        Parameters
        ----------
        z : (2n,) state [Δx; v].
        ref_h, ref_r : (Np, 2n) the human's and the robot's reference outputs
            [position; velocity] at k+1…k+Np, DOF order as in M.
        """
        z = np.asarray(z, dtype=float)
        ref_h = np.asarray(ref_h, dtype=float)
        ref_r = np.asarray(ref_r, dtype=float)
        self._check_refs(ref_h, ref_r)
        if z.shape != self._z_shape:
            raise ValueError(f"z must have shape {self._z_shape} (2n,), got {z.shape}")
        g = self._state[0]
        dot = np.dot  # measured faster than the @ operator for these small products
        u = dot(g.G_z, z)
        u += dot(g.G_h, ref_h.reshape(-1))
        u += dot(g.G_r, ref_r.reshape(-1))
        return u[: self._n], u[self._n :]

    def solve_batch(self, z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`solve` for B states at once (trials in lockstep sharing these gains):
        z (B, 2n), ref_h and ref_r (B, Np, 2n) float64 → (u_h (B, n), u_r (B, n)) [N or N·m].

        Row b equals ``solve(z[b], ref_h[b], ref_r[b])`` bit for bit: each row takes the same
        three matrix-vector products in the same order. numpy's stacked ``matmul`` of a
        matrix with (B, k, 1) vectors makes one BLAS gemv call per row, the call ``np.dot``
        makes for one row, in a C loop (7× faster than a Python loop of ``np.dot`` at B = 30;
        tests/control/test_game.py checks the rows bit for bit). One matrix-matrix product
        over the batch would round differently (BLAS's gemm and gemv kernels sum in other
        orders), and the lockstep runner must reproduce the per-trial one exactly.
        """
        z = np.asarray(z, dtype=float)
        ref_h = np.asarray(ref_h, dtype=float)
        ref_r = np.asarray(ref_r, dtype=float)
        B = z.shape[0]
        if (
            z.shape != (B, *self._z_shape)
            or ref_h.shape != (B, *self._ref_shape)
            or ref_r.shape != (B, *self._ref_shape)
        ):
            raise ValueError(
                f"z, ref_h, ref_r must have shapes (B, {self._z_shape[0]}) and (B, {self._ref_shape[0]}, "
                f"{self._ref_shape[1]}), got {z.shape}, {ref_h.shape}, {ref_r.shape}"
            )
        g = self._state[0]
        G_z, G_h, G_r = g.G_z, g.G_h, g.G_r
        # contiguous rows: each row's gemv reads its vector as np.dot reads a contiguous row
        zc = np.ascontiguousarray(z)[:, :, None]
        rh = np.ascontiguousarray(ref_h).reshape(B, -1, 1)
        rr = np.ascontiguousarray(ref_r).reshape(B, -1, 1)
        u = np.matmul(G_z, zc)
        u += np.matmul(G_h, rh)
        u += np.matmul(G_r, rr)
        u = u[:, :, 0]
        return u[:, : self._n], u[:, self._n :]

    def solve_horizon(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The whole equilibrium input sequences U_h, U_r, each (Nc, n) (for analysis, not the tick)."""
        z = np.asarray(z, dtype=float)
        ref_h = np.asarray(ref_h, dtype=float)
        ref_r = np.asarray(ref_r, dtype=float)
        self._check_refs(ref_h, ref_r)
        if z.shape != self._z_shape:
            raise ValueError(f"z must have shape {self._z_shape} (2n,), got {z.shape}")
        _, factor, ref_h_terms, ref_r_terms, state_terms, alpha = self._state
        if factor is None:  # gains set by the online-α path: factor this α's matrix now (analysis only)
            H, ref_h_terms, ref_r_terms, state_terms = self._assemble(alpha)
            factor = self._factor(H)
        rh, rr = ref_h.reshape(-1), ref_r.reshape(-1)
        rhs = np.concatenate([ref_h_terms[p] @ rh + ref_r_terms[p] @ rr - state_terms[p] @ z for p in (0, 1)])
        U = self._solve_factored(factor, rhs)
        N = self._n * self.control_horizon
        return U[:N].reshape(-1, self._n), U[N:].reshape(-1, self._n)


def solve_with_gains(
    gains: list[EquilibriumGains], z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`~_LinearQuadraticGame.solve` for B rows, row b with its own gains ``gains[b]``
    (trials in lockstep whose α differs: :func:`coassist.control.arbitration.arbitrated_effort_batch`):
    z (B, 2n), ref_h and ref_r (B, Np, 2n) float64 → (u_h (B, n), u_r (B, n)).

    Row b is a game's ``solve(z[b], ref_h[b], ref_r[b])`` with those gains bit for bit on any
    BLAS: it makes the same three ``np.dot`` calls on the same arrays, in the same order.
    (Stacking the gains for one batched ``matmul`` measured 118 against 227 µs for 18 rows
    of the application preset, but a copied matrix reaches BLAS with another leading
    dimension and alignment, and bit-equality would then rest on the BLAS build.)
    """
    B = z.shape[0]
    if len(gains) != B:
        raise ValueError(f"one gain set per row: {len(gains)} for {B} rows")
    n = z.shape[1] // 2
    if B == 0:
        return np.zeros((0, n)), np.zeros((0, n))
    rh, rr = ref_h.reshape(B, -1), ref_r.reshape(B, -1)
    u = np.empty((B, 2 * n))
    dot = np.dot
    for b, (g, zb, rhb, rrb) in enumerate(zip(gains, z, rh, rr)):  # the rows as views, as z[b] gives them
        ub = dot(g.G_z, zb)
        ub += dot(g.G_h, rhb)
        ub += dot(g.G_r, rrb)
        u[b] = ub
    return u[:, :n], u[:, n:]


def _check_model(model: object) -> None:
    if not isinstance(model, ImpedanceModel):
        raise ValueError(f"model must be an ImpedanceModel, got {type(model).__name__}")


def _add(a: dict[str, float], b: dict[str, float]) -> dict[str, float]:
    out = dict(a)
    for k, v in b.items():
        out[k] = out.get(k, 0.0) + v
    return out


class CooperativeGame(_LinearQuadraticGame):
    """Cooperative game-theoretic MPC: human and robot share the α-weighted cost (eq. 3.17–3.31).

    Parameters
    ----------
    model : the impedance model both players act on.
    weights : both players' cost weights (:class:`GameWeights`); or give them as the
        keywords ``Q_hh``, ``Q_hr``, ``Q_rh``, ``Q_rr``, ``R_h``, ``R_r`` (each as
        :class:`GameWeights` reads it), not both.
    alpha : share of the human's cost in the common objective, 0 ≤ α ≤ 1 (0 < α < 1
        with ``input_weighting="alpha_scaled"``). α → 1 follows the human's reference.
    horizon : prediction horizon Np [samples].
    control_horizon : Nc ≤ Np [samples]; the input is held after Nc. None: Nc = Np.
    input_weighting : "shared" (eq. 3.17: R_h, R_r) or "alpha_scaled" (α R_h, (1 − α) R_r).
    Q_hh, Q_hr, Q_rh, Q_rr, R_h, R_r : the weights as keywords (see ``weights``).
    """

    def __init__(
        self,
        model: ImpedanceModel,
        weights: GameWeights | None = None,
        *,
        alpha: float,
        horizon: int,
        control_horizon: int | None = None,
        input_weighting: InputWeighting = "shared",
        Q_hh: ArrayLike | None = None,
        Q_hr: ArrayLike | None = None,
        Q_rh: ArrayLike | None = None,
        Q_rr: ArrayLike | None = None,
        R_h: ArrayLike | None = None,
        R_r: ArrayLike | None = None,
    ) -> None:
        if input_weighting not in ("shared", "alpha_scaled"):
            raise ValueError(f"input_weighting must be 'shared' or 'alpha_scaled', got {input_weighting!r}")
        _check_model(model)
        weights = _weights(weights, model.n_dof, dict(Q_hh=Q_hh, Q_hr=Q_hr, Q_rh=Q_rh, Q_rr=Q_rr, R_h=R_h, R_r=R_r))
        super().__init__(model, weights, horizon=horizon, control_horizon=control_horizon)
        self.input_weighting = input_weighting
        self._alpha_family: _AlphaFamily | None = None
        # α₀ → its _AlphaFamily, shared with the copies of this game (:meth:`copy`): the
        # family is a pure function of the game's matrices and α₀, which copies share.
        self._families: dict[float, _AlphaFamily] = {}
        self._compute_gains(self._check_alpha(alpha))

    def copy(self) -> CooperativeGame:
        """A game equal to this one with its own α: the weights, factor and gains are shared
        (never written in place; :meth:`set_alpha` swaps its own state), and so are the
        α-families prepared by either (:meth:`prepare_alpha_changes`). Costs microseconds
        where building the game costs a factorisation and preparing α changes an
        eigendecomposition."""
        twin = copy.copy(self)
        twin._alpha_family = None
        return twin

    def _check_alpha(self, alpha: float) -> float:
        refuse_truth_value(alpha, "alpha")  # (float(True) is 1)
        try:
            a = float(alpha)
        except (TypeError, ValueError):
            raise ValueError(f"alpha must be a number, got {alpha!r}") from None
        if self.input_weighting == "alpha_scaled":
            if not 0.0 < a < 1.0:
                raise ValueError(f"alpha must be in (0, 1) with input_weighting='alpha_scaled', got {alpha!r}")
        elif not 0.0 <= a <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {alpha!r}")
        return a

    @property
    def alpha(self) -> float:
        return self._state[5]

    def set_alpha(self, alpha: float) -> None:
        """Change α at run time; the new gains are swapped in at once.

        The new gains are the equilibrium for the new α (module docstring, "Online α";
        equal to a fresh computation to about 1e-11 relative, the match each stretch's
        series is held to), so the next effort is the new optimum: it changes by no more
        than the optimum itself does. After :meth:`prepare_alpha_changes` (done by the
        first call if not before) a change costs microseconds (benchmarks/bench_game.py).
        """
        a = self._check_alpha(alpha)
        family = self._alpha_family
        if family is None:
            self.prepare_alpha_changes()
            family = self._alpha_family
        G = family.gains(a)
        # α travels with its gains in one tuple: a failure leaves both as they were.
        self._state = (_split_gains(G, self._n, self._ref_shape), None, None, None, None, a)

    def prepare_alpha_changes(self) -> None:
        """Precompute the gains as a function of α (module docstring, "Online α").

        One generalized symmetric eigendecomposition of the (2N, 2N) equilibrium matrix,
        N = n·Nc, at the current α, and where the gains are not affine in α a Chebyshev
        series per stretch of [0, 1] (0.2–0.9 s measured at 6 DOF, Nc = 50, one core; a few
        seconds if every stretch needed degree 16): do it before the loop starts so that no
        tick pays for it.
        """
        family = self._families.get(self.alpha)
        if family is None:
            with threadpool_limits(1, user_api="blas"):  # as in cooperative_game: same rounding in every process
                family = self._families[self.alpha] = _AlphaFamily(self, self.alpha)
        self._alpha_family = family

    def _player_weights(self, alpha):
        a = alpha
        w_h = {"Q_hh": a, "Q_rh": 1.0 - a}  # weight on e_h, shared by both players
        w_r = {"Q_hr": a, "Q_rr": 1.0 - a}  # weight on e_r
        return w_h, w_r, w_h, w_r

    def _input_weights(self, alpha):
        if self.input_weighting == "alpha_scaled":
            return alpha * self._R_h_tilde, (1.0 - alpha) * self._R_r_tilde
        return self._R_h_tilde, self._R_r_tilde

    def _factor(self, H):
        try:
            return scipy.linalg.cho_factor(H, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            raise ValueError("the cooperative game's Hessian is not positive definite; check R_h and R_r") from None

    def _solve_factored(self, factor, rhs, transposed=False):
        return scipy.linalg.cho_solve(factor, rhs, check_finite=False)  # H is symmetric


def _split_gains(G: np.ndarray, n: int, ref_shape: tuple[int, int]) -> EquilibriumGains:
    """EquilibriumGains viewing the columns [G_z | G_h | G_r] of one (2n, 2n + 2·Np·2n) matrix."""
    G.setflags(write=False)
    p = ref_shape[0] * ref_shape[1]
    return EquilibriumGains(G_z=G[:, : 2 * n], G_h=G[:, 2 * n : 2 * n + p], G_r=G[:, 2 * n + p :])


class _AlphaFamily:
    """The cooperative game's first-step gains as a function of α (module docstring, "Online α").

    Built at α₀ (where H(α₀) is known to be positive definite). Stores, for β = α − α₀:
    C₀, C₁ (2n, p) from the directions with λ_j = 0, and A (2n, r), B₀, B₁ (r, p), λ (r,)
    for the r others; p = 2n + 2·Np·2n columns [G_z | G_h | G_r]. With r > 0, ``pieces``
    holds per stretch [a, a + 1/PIECES] of α its start a and Chebyshev coefficients
    (K + 1, 2n·p), or None where the exact sum is kept.
    """

    #: |λ_j| below this folds into C₀ + β C₁: with |β| ≤ 1 the neglected factor
    #: 1/(1 + βλ_j) − 1 is below 1e-12.
    ZERO_EIGENVALUE = 1e-12

    def __init__(self, game: CooperativeGame, alpha0: float) -> None:
        n, N = game._n, game._n * game.control_horizon
        H0, T0 = self._system(game, alpha0)
        H1, T1 = self._system(game, alpha0 + 1.0)
        dH, dT = H1 - H0, T1 - T0  # exact slopes: both are affine in α
        dH = 0.5 * (dH + dH.T)
        if not dH.any():
            lam, V = np.zeros(2 * N), None
        else:
            try:
                lam, V = scipy.linalg.eigh(dH, H0, check_finite=False)
            except np.linalg.LinAlgError:
                raise ValueError("the cooperative game's Hessian is not positive definite; check R_h and R_r") from None
        rows = np.r_[0:n, N : N + n]  # u_h(k) and u_r(k) in the stacked solution
        if V is None:
            # ΔH = 0: G(α) = E' H₀⁻¹ (T₀ + β ΔT), two solves with the Cholesky factor.
            factor = scipy.linalg.cho_factor(H0, lower=True, check_finite=False)
            E = np.zeros((2 * N, 2 * n))
            E[rows, np.arange(2 * n)] = 1.0
            X = scipy.linalg.cho_solve(factor, E, check_finite=False).T  # E' H₀⁻¹
            self.C0, self.C1 = X @ T0, X @ dT
            self.A = np.zeros((2 * n, 0))
            self.B0 = self.B1 = np.zeros((0, T0.shape[1]))
            self.lam = np.zeros(0)
        else:
            A = V[rows]  # E'V
            B0, B1 = V.T @ T0, V.T @ dT
            zero = np.abs(lam) <= self.ZERO_EIGENVALUE
            self.C0, self.C1 = A[:, zero] @ B0[zero], A[:, zero] @ B1[zero]
            keep = ~zero
            self.A = np.ascontiguousarray(A[:, keep])
            self.B0, self.B1 = np.ascontiguousarray(B0[keep]), np.ascontiguousarray(B1[keep])
            self.lam = lam[keep]
        self.alpha0 = float(alpha0)
        self.pieces: list[tuple[float, np.ndarray] | None] = []
        if self.rank and self.PIECES * (self.DEGREES[-1] + 1) * self.C0.size * 8 <= self.MAX_BYTES:
            self.pieces = [self._fit_piece(i / self.PIECES, 1.0 / self.PIECES) for i in range(self.PIECES)]

    #: Stretches of [0, 1] with their own Chebyshev series, the degrees tried on each (the
    #: first that matches is kept), the match required (relative), and the memory allowed.
    PIECES = 16
    DEGREES = (4, 6, 10, 16)
    MATCH = 1e-11
    MAX_BYTES = 64 * 2**20

    def _fit_piece(self, a: float, w: float) -> tuple[float, np.ndarray] | None:
        """(a, coefficients (K + 1, 2n·p)) of the stretch [a, a + w], or None to keep the exact sum there."""
        for K in self.DEGREES:
            j = np.arange(K + 1)
            nodes = np.cos(np.pi * (j + 0.5) / (K + 1))  # Chebyshev points of the first kind, in (−1, 1)
            checks = np.concatenate([[-1.0, 1.0], np.cos(np.pi * (j[1:]) / (K + 1))])  # ends, and between the points
            try:
                values = np.stack([self._exact(a + 0.5 * w * (t + 1.0)).ravel() for t in nodes])
                wanted = np.stack([self._exact(a + 0.5 * w * (t + 1.0)).ravel() for t in checks])
            except ValueError:  # H(α) not positive definite somewhere on the stretch
                return None
            # Discrete orthogonality at these points: c_k = (2 − δ_k0)/(K + 1) Σ_j f(t_j) T_k(t_j).
            coef = (2.0 / (K + 1)) * (np.polynomial.chebyshev.chebvander(nodes, K).T @ values)
            coef[0] *= 0.5
            got = np.polynomial.chebyshev.chebvander(checks, K) @ coef
            if np.abs(got - wanted).max() <= self.MATCH * np.abs(wanted).max():
                return a, np.ascontiguousarray(coef)
        return None

    @staticmethod
    def _system(game: CooperativeGame, alpha: float) -> tuple[np.ndarray, np.ndarray]:
        """H(α) (2N, 2N) and the stacked right-hand sides T(α) (2N, p) = [−Φ'W̄F | Φ'Ŵ_·,h | Φ'Ŵ_·,r] per player."""
        H, ref_h_terms, ref_r_terms, state_terms = game._assemble(alpha)
        T = np.vstack([np.hstack([-state_terms[p], ref_h_terms[p], ref_r_terms[p]]) for p in (0, 1)])
        return H, T

    @property
    def rank(self) -> int:
        """r: the directions in which the gains are not affine in α."""
        return self.lam.shape[0]

    def gains(self, alpha: float) -> np.ndarray:
        """G(α) (2n, p), a new array (published gains are never written to again).

        From the stretch's Chebyshev series where it has one, else the exact sum. Raises
        ValueError where H(α) is not positive definite (1 + βλ_j ≤ 0 for some j).
        """
        alpha = float(alpha)
        if self.pieces and 0.0 <= alpha <= 1.0:
            piece = self.pieces[min(int(alpha * self.PIECES), self.PIECES - 1)]
            if piece is not None:
                a, coef = piece
                t = 2.0 * self.PIECES * (alpha - a) - 1.0
                T = [1.0, t]  # T_k(t) by the three-term recurrence: K multiply-adds of floats
                for _ in range(coef.shape[0] - 2):
                    T.append(2.0 * t * T[-1] - T[-2])
                return np.dot(T, coef).reshape(self.C0.shape)
        return self._exact(alpha)

    def _exact(self, alpha: float) -> np.ndarray:
        """G(α) from the eigen-sum (the module docstring's formula)."""
        beta = float(alpha) - self.alpha0
        G = np.multiply(self.C1, beta)
        np.add(G, self.C0, out=G)
        if self.lam.shape[0]:
            denominator = 1.0 + beta * self.lam
            if not denominator.min() > 1e-12:
                raise ValueError(f"the cooperative game's Hessian is not positive definite at alpha = {alpha!r}")
            G += (self.A / denominator) @ (self.B0 + beta * self.B1)
        return G


class NashGame(_LinearQuadraticGame):
    """Non-cooperative Nash equilibrium: each player minimises its own cost (eq. 3.15–3.16).

    Q_h = blkdiag(Q_hh, Q_hr) for the human and Q_r = blkdiag(Q_rh, Q_rr) for the robot,
    no α mixing. Same parameters and call as :class:`CooperativeGame` minus ``alpha``
    and ``input_weighting``.
    """

    def __init__(
        self,
        model: ImpedanceModel,
        weights: GameWeights | None = None,
        *,
        horizon: int,
        control_horizon: int | None = None,
        Q_hh: ArrayLike | None = None,
        Q_hr: ArrayLike | None = None,
        Q_rh: ArrayLike | None = None,
        Q_rr: ArrayLike | None = None,
        R_h: ArrayLike | None = None,
        R_r: ArrayLike | None = None,
    ) -> None:
        _check_model(model)
        weights = _weights(weights, model.n_dof, dict(Q_hh=Q_hh, Q_hr=Q_hr, Q_rh=Q_rh, Q_rr=Q_rr, R_h=R_h, R_r=R_r))
        super().__init__(model, weights, horizon=horizon, control_horizon=control_horizon)
        self._compute_gains()

    def _player_weights(self, alpha):
        return {"Q_hh": 1.0}, {"Q_hr": 1.0}, {"Q_rh": 1.0}, {"Q_rr": 1.0}

    def _factor(self, H):
        lu = scipy.linalg.lu_factor(H, check_finite=False)
        diag = np.abs(np.diag(lu[0]))
        if diag.min() <= 1e-13 * diag.max():
            raise ValueError(
                "the Nash game has no unique equilibrium for these weights (singular first-order conditions)"
            )
        return lu

    def _solve_factored(self, factor, rhs, transposed=False):
        return scipy.linalg.lu_solve(factor, rhs, trans=1 if transposed else 0, check_finite=False)


def extrapolation_feedback(game: _LinearQuadraticGame) -> tuple[np.ndarray, np.ndarray]:
    """The state feedback a pose-extrapolating prediction closes through the robot's gains.

    A predictor of the tool's future *pose* (what :mod:`coassist.intent` learns) is, to
    first order, the constant-velocity extrapolation of the robot's own state::

        ref_h[i] = [Δx + (i+1)·dt·v;  v]        i = 0 … Np−1 (rows k+1 … k+Np)

    With it the robot's effort is a state feedback (plus terms in ref_r)::

        u_r(k) = −K Δx − D v + G_r vec(ref_r),   [−K, −D] = G_z,r + G_h,r L

    (G_·,r the u_r rows of the gains, L the (Np·2n, 2n) extrapolation map). D < 0 is
    negative damping: the robot pushes along the motion, which is the assistance, and the
    plant's damping D_plant + D is what is left to damp the coupled human-robot loop.

    Returns K, D (n, n) [N/m, N·s/m].
    """
    n = game.n_dof
    Np, m = game.reference_shape
    dt = float(game.model.dt)
    L = np.zeros((Np, m, 2 * n))
    for i in range(Np):
        L[i, :n, :n] = np.eye(n)
        L[i, :n, n:] = (i + 1) * dt * np.eye(n)
        L[i, n:, n:] = np.eye(n)
    g = game.gains
    feedback = g.G_z[n:] + g.G_h[n:] @ L.reshape(Np * m, 2 * n)
    return -feedback[:, :n], -feedback[:, n:]


#: (model, parameters) → a game built from them, of which :func:`cooperative_game` hands out
#: copies: a memo of a pure construction, bounded (a process meets a handful of presets).
_GAME_MEMO: dict[tuple, CooperativeGame] = {}
_GAME_MEMO_SIZE = 16


def cooperative_game(model: ImpedanceModel, params: GameParameters) -> CooperativeGame:
    """The :class:`CooperativeGame` of a validated :class:`~coassist.config.GameParameters`.

    Each call returns a game of its own (its α changes alone), a :meth:`~CooperativeGame.copy`
    of one built once per (model, parameters) in this process: a simulation worker that
    runs many trials with the same preset factorises, and prepares online α, once.
    """
    key = (
        params,
        float(model.dt),
        model.discretization,  # zoh and tustin of one M, D, K, dt are two games
        *(np.asarray(a, float).tobytes() for a in (model.M, model.D, model.K)),
        np.shape(model.M),
    )
    template = _GAME_MEMO.get(key)
    if template is None:
        # One BLAS thread: the gains then round the same in every process whatever its BLAS
        # threads (a simulation worker, the main process, a test), and building them does not
        # stall at the barriers of threads competing for cores with other work (measured
        # 1-2 s against ~15 ms for an arbitrated controller on a loaded 2-core machine).
        with threadpool_limits(1, user_api="blas"):
            template = CooperativeGame(
                model,
                params.weights,
                alpha=params.alpha,
                horizon=params.horizon,
                control_horizon=params.control_horizon,
                input_weighting=params.input_weighting,  # type: ignore[arg-type]
            )
        if len(_GAME_MEMO) >= _GAME_MEMO_SIZE:
            _GAME_MEMO.pop(next(iter(_GAME_MEMO)))
        _GAME_MEMO[key] = template
    return template.copy()
