"""The game's closed form against independent references.

The reference is built the thesis' way, from the augmented system of eq. 3.7
(two copies of the state, output [y; y], stacked errors E_gt of eq. 3.18 with the
docs/architecture.md's indexing), with prediction matrices obtained by simulating impulse
responses — no code shared with the library beyond the impedance model.
"""

import numpy as np
import osqp
import pytest
import scipy.linalg
import scipy.sparse

from coassist.control import CooperativeGame, NashGame
from coassist.control.game import _AlphaFamily, extrapolation_feedback
from coassist.model import ImpedanceModel


def random_psd(rng, m, rank=None):
    a = rng.normal(size=(m, rank or m))
    return a @ a.T / m


def random_instance(rng, n, Np, Nc):
    model = ImpedanceModel(rng.uniform(2, 10, n), rng.uniform(20, 100, n), rng.uniform(0, 50, n), 0.008)
    m = 2 * n
    Q = {k: random_psd(rng, m) * rng.uniform(50, 500) for k in ("Q_hh", "Q_hr", "Q_rh", "Q_rr")}
    R_h = random_psd(rng, n) * 1e-3 + 1e-3 * np.eye(n)
    R_r = random_psd(rng, n) * 1e-3 + 1e-3 * np.eye(n)
    z = rng.normal(size=m) * 0.1
    ref_h = rng.normal(size=(Np, m)) * 0.1
    ref_r = rng.normal(size=(Np, m)) * 0.1
    return model, Q, R_h, R_r, z, ref_h, ref_r


def augmented_prediction(model, Np, Nc):
    """F_gt, Φ_gt of eq. 3.7–3.12 for z_gt = [z; z], by simulating the augmented system."""
    n = model.n_dof
    A_gt = scipy.linalg.block_diag(model.Ad, model.Ad)
    B_gt = np.vstack([model.Bd, model.Bd])
    C_gt = scipy.linalg.block_diag(model.C, model.C)

    def simulate(z0, U):
        z, out = z0, []
        for i in range(Np):
            z = A_gt @ z + B_gt @ U[min(i, Nc - 1)]
            out.append(C_gt @ z)
        return np.concatenate(out)

    F = np.column_stack([simulate(e, np.zeros((Nc, n))) for e in np.eye(4 * n)])
    Phi = np.column_stack([simulate(np.zeros(4 * n), e.reshape(Nc, n)) for e in np.eye(n * Nc)])
    return F, Phi


def stacked_refs(ref_h, ref_r):
    """[y_ref,h(k+1); y_ref,r(k+1); …] as in eq. 3.18 / 3.31."""
    return np.concatenate([np.concatenate([h, r]) for h, r in zip(ref_h, ref_r)])


def joint_minimiser(model, Q, R_h, R_r, alpha, Np, Nc, z, ref_h, ref_r):
    """argmin over (U_h, U_r) of E_gt' Q_gt E_gt + U_h' R̃_h U_h + U_r' R̃_r U_r (dense KKT solve)."""
    F, Phi = augmented_prediction(model, Np, Nc)
    Q_h = scipy.linalg.block_diag(Q["Q_hh"], Q["Q_hr"])
    Q_r = scipy.linalg.block_diag(Q["Q_rh"], Q["Q_rr"])
    Q_gt = np.kron(np.eye(Np), alpha * Q_h + (1 - alpha) * Q_r)  # eq. 3.17, 3.19–3.20
    G = np.hstack([Phi, Phi])  # both players through B_h = B_r
    target = stacked_refs(ref_h, ref_r) - F @ np.concatenate([z, z])
    R = scipy.linalg.block_diag(np.kron(np.eye(Nc), R_h), np.kron(np.eye(Nc), R_r))
    H = G.T @ Q_gt @ G + R
    U = np.linalg.solve(H, G.T @ Q_gt @ target)
    return U, H, G.T @ Q_gt @ target


CASES = [(1, 1, 1), (1, 8, 8), (2, 5, 2), (2, 20, 20), (3, 10, 4), (3, 15, 15), (6, 6, 3), (6, 12, 12)]


@pytest.mark.parametrize("n, Np, Nc", CASES)
def test_cooperative_equilibrium_is_the_joint_minimiser(n, Np, Nc):
    rng = np.random.default_rng(1000 * n + 10 * Np + Nc)
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, n, Np, Nc)
    alpha = rng.uniform(0.05, 0.95)
    game = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=alpha, horizon=Np, control_horizon=Nc)
    U_ref, _, _ = joint_minimiser(model, Q, R_h, R_r, alpha, Np, Nc, z, ref_h, ref_r)
    U_h, U_r = game.solve_horizon(z, ref_h, ref_r)
    U = np.concatenate([U_h.reshape(-1), U_r.reshape(-1)])
    assert np.linalg.norm(U - U_ref) <= 1e-8 * np.linalg.norm(U_ref)
    u_h, u_r = game.solve(z, ref_h, ref_r)
    first = np.concatenate([U_ref[:n], U_ref[n * Nc : n * Nc + n]])
    assert np.linalg.norm(np.concatenate([u_h, u_r]) - first) <= 1e-8 * np.linalg.norm(first)


@pytest.mark.parametrize("n, Np, Nc", [(2, 10, 10), (6, 8, 4)])
def test_cooperative_equilibrium_agrees_with_osqp(n, Np, Nc):
    rng = np.random.default_rng(7 + n)
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, n, Np, Nc)
    game = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=0.8, horizon=Np, control_horizon=Nc)
    _, H, g = joint_minimiser(model, Q, R_h, R_r, 0.8, Np, Nc, z, ref_h, ref_r)
    N = H.shape[0]
    solver = osqp.OSQP()
    # No constraints binding: loose bounds, tight tolerances, polishing.
    solver.setup(
        P=scipy.sparse.csc_matrix(np.triu(H)),
        q=-g,
        A=scipy.sparse.identity(N, format="csc"),
        l=np.full(N, -1e9),
        u=np.full(N, 1e9),
        eps_abs=1e-12,
        eps_rel=1e-12,
        max_iter=200000,
        polishing=True,
        verbose=False,
    )
    result = solver.solve(raise_error=True)
    assert result.info.status == "solved", result.info.status
    U_h, U_r = game.solve_horizon(z, ref_h, ref_r)
    U = np.concatenate([U_h.reshape(-1), U_r.reshape(-1)])
    assert np.linalg.norm(U - result.x) <= 1e-6 * np.linalg.norm(result.x)


def test_thesis_closed_form_eq_3_27_with_other_players_coupling_gain():
    """U* = [[I, K_h], [K_r, I]]⁻¹ [L_h Z; L_r Z] with K_h = S_h Φ_r, K_r = S_r Φ_h (eq. 3.27–3.31)."""
    rng = np.random.default_rng(3)
    n, Np, Nc, alpha = 2, 10, 10, 0.7
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, n, Np, Nc)
    F, Phi = augmented_prediction(model, Np, Nc)
    Q_h = scipy.linalg.block_diag(Q["Q_hh"], Q["Q_hr"])
    Q_r = scipy.linalg.block_diag(Q["Q_rh"], Q["Q_rr"])
    Q_gt = np.kron(np.eye(Np), alpha * Q_h + (1 - alpha) * Q_r)
    R_ht, R_rt = np.kron(np.eye(Nc), R_h), np.kron(np.eye(Nc), R_r)
    S_h = np.linalg.solve(Phi.T @ Q_gt @ Phi + R_ht, Phi.T @ Q_gt)
    S_r = np.linalg.solve(Phi.T @ Q_gt @ Phi + R_rt, Phi.T @ Q_gt)
    K_h, K_r = S_h @ Phi, S_r @ Phi  # Φ_h = Φ_r here
    L_h = np.hstack([-S_h @ F, S_h])
    L_r = np.hstack([-S_r @ F, S_r])
    Z = np.concatenate([z, z, stacked_refs(ref_h, ref_r)])
    lhs = np.block([[np.eye(n * Nc), K_h], [K_r, np.eye(n * Nc)]])
    U_star = np.linalg.solve(lhs, np.concatenate([L_h @ Z, L_r @ Z]))
    game = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=alpha, horizon=Np)
    U_h, U_r = game.solve_horizon(z, ref_h, ref_r)
    np.testing.assert_allclose(np.concatenate([U_h.reshape(-1), U_r.reshape(-1)]), U_star, rtol=1e-8, atol=1e-10)


def test_alpha_scaled_input_weighting_is_the_minimiser_with_scaled_R():
    rng = np.random.default_rng(11)
    n, Np, Nc, alpha = 2, 8, 8, 0.3
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, n, Np, Nc)
    game = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=alpha, horizon=Np, input_weighting="alpha_scaled")
    U_ref, _, _ = joint_minimiser(model, Q, alpha * R_h, (1 - alpha) * R_r, alpha, Np, Nc, z, ref_h, ref_r)
    U_h, U_r = game.solve_horizon(z, ref_h, ref_r)
    np.testing.assert_allclose(np.concatenate([U_h.reshape(-1), U_r.reshape(-1)]), U_ref, rtol=1e-8, atol=1e-10)


def player_cost(model, Q_own_h, Q_own_r, R_own, Np, Nc, z, ref_h, ref_r, U_h, U_r, player):
    """J_p of eq. 3.15/3.16 by simulating the model step by step."""
    cost, zk = 0.0, z.copy()
    for i in range(Np):
        j = min(i, Nc - 1)
        zk = model.Ad @ zk + model.Bd @ (U_h[j] + U_r[j])
        e_h, e_r = zk - ref_h[i], zk - ref_r[i]
        cost += e_h @ Q_own_h @ e_h + e_r @ Q_own_r @ e_r
    U = U_h if player == "h" else U_r
    return cost + sum(u @ R_own @ u for u in U)


@pytest.mark.parametrize("n, Np, Nc", [(1, 6, 6), (2, 10, 4), (3, 8, 8)])
def test_nash_efforts_are_mutual_best_responses(n, Np, Nc):
    rng = np.random.default_rng(100 + n)
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, n, Np, Nc)
    game = NashGame(model, **Q, R_h=R_h, R_r=R_r, horizon=Np, control_horizon=Nc)
    U_h, U_r = game.solve_horizon(z, ref_h, ref_r)

    def J_h(Uh):
        return player_cost(model, Q["Q_hh"], Q["Q_hr"], R_h, Np, Nc, z, ref_h, ref_r, Uh, U_r, "h")

    def J_r(Ur):
        return player_cost(model, Q["Q_rh"], Q["Q_rr"], R_r, Np, Nc, z, ref_h, ref_r, U_h, Ur, "r")

    base_h, base_r = J_h(U_h), J_r(U_r)
    for _ in range(20):
        d = rng.normal(size=U_h.shape) * rng.choice([1e-3, 1e-1, 1.0])
        assert J_h(U_h + d) >= base_h - 1e-9 * abs(base_h)
        assert J_r(U_r + d) >= base_r - 1e-9 * abs(base_r)
    # and it is not the cooperative solution: the players' costs differ here
    coop = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=0.5, horizon=Np, control_horizon=Nc)
    assert not np.allclose(coop.solve_horizon(z, ref_h, ref_r)[1], U_r)
    u_h, u_r = game.solve(z, ref_h, ref_r)
    np.testing.assert_allclose(u_h, U_h[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(u_r, U_r[0], rtol=1e-9, atol=1e-12)


def thesis_game(alpha, horizon=50, R_r=5e-4):
    model = ImpedanceModel([10, 10], [100, 100], 0, 0.008)
    Q = np.diag([1, 1, 1e-4, 1e-4])
    return CooperativeGame(
        model, Q_hh=Q, Q_hr=0, Q_rh=0, Q_rr=Q, R_h=[5e-4, 5e-4], R_r=[R_r, R_r], alpha=alpha, horizon=horizon
    )


def test_set_alpha_gives_exactly_the_new_optimum_and_efforts_are_continuous_in_alpha():
    rng = np.random.default_rng(5)
    z, ref_h, ref_r = rng.normal(size=4), rng.normal(size=(50, 4)), rng.normal(size=(50, 4))
    game = thesis_game(0.8)
    game.set_alpha(0.3)
    assert game.alpha == 0.3
    fresh = thesis_game(0.3)
    # set_alpha's gains match a fresh computation to _AlphaFamily.MATCH relative to the largest
    # gain (game.py: "Online α"), not to rounding: through U = G·x that allows
    # |ΔU| ≤ MATCH·max|G|·‖x‖₁; 10× for the products' own rounding. A wrong α is off by O(|U|).
    G = np.hstack([fresh.gains.G_z, fresh.gains.G_h, fresh.gains.G_r])
    x = np.concatenate([z, ref_h.ravel(), ref_r.ravel()])
    tol = 10 * _AlphaFamily.MATCH * np.abs(G).max() * np.abs(x).sum()
    for a, b in zip(game.solve(z, ref_h, ref_r), fresh.solve(z, ref_h, ref_r)):
        np.testing.assert_allclose(a, b, rtol=0, atol=tol)
        assert tol < 1e-6 * np.abs(b).max()  # still a sharp check
    # a small change of α moves the effort by a proportionally small amount (no jump)
    u0 = np.concatenate(game.solve(z, ref_h, ref_r))
    steps = []
    for delta in (1e-2, 1e-3, 1e-4):
        game.set_alpha(0.3 + delta)
        steps.append(np.linalg.norm(np.concatenate(game.solve(z, ref_h, ref_r)) - u0))
    assert steps[1] < 0.2 * steps[0] and steps[2] < 0.2 * steps[1]


def test_failed_alpha_change_keeps_the_old_gains(monkeypatch):
    game = thesis_game(0.8)
    before = game.gains.G_z.copy()
    with pytest.raises(ValueError, match="alpha must be in"):
        game.set_alpha(1.5)
    game.prepare_alpha_changes()

    def failing_gains(alpha):
        raise ValueError("gains failed")

    monkeypatch.setattr(game._alpha_family, "gains", failing_gains)  # fail after the new α was accepted
    with pytest.raises(ValueError, match="gains failed"):
        game.set_alpha(0.3)
    assert game.alpha == 0.8
    np.testing.assert_array_equal(game.gains.G_z, before)


def fresh_and_online(build, alphas):
    """Max over α of max|G_online − G_fresh| / max|G_fresh|, and the online family's rank."""
    game = build(0.5)
    game.prepare_alpha_changes()
    worst = 0.0
    for a in alphas:
        game.set_alpha(a)
        fresh = build(a)  # a new game: assembled, factored and solved from scratch at α
        # relative to the largest gain of this α (one block can be exactly zero, e.g. G_r at α = 1 with Q_hr = 0)
        online = np.hstack([game.gains.G_z, game.gains.G_h, game.gains.G_r])
        ref = np.hstack([fresh.gains.G_z, fresh.gains.G_h, fresh.gains.G_r])
        worst = max(worst, np.abs(online - ref).max() / np.abs(ref).max())
    return worst, game._alpha_family.rank


@pytest.mark.parametrize(
    "n, Np, Nc, weights, input_weighting",
    [
        (2, 50, 50, "thesis", "shared"),
        (2, 12, 12, "random", "shared"),
        (3, 10, 4, "random", "shared"),
        (2, 12, 6, "random", "alpha_scaled"),
        (2, 20, 20, "thesis", "alpha_scaled"),
    ],
)
def test_online_alpha_gains_equal_a_fresh_computation(n, Np, Nc, weights, input_weighting):
    rng = np.random.default_rng(50 + n + Np)
    model, Q, R_h, R_r, *_ = random_instance(rng, n, Np, Nc)
    if weights == "thesis":  # Q_hh = Q_rr, Q_hr = Q_rh = 0: ΔH = 0 with shared input weights
        q = np.diag([1.0] * n + [1e-4] * n)
        Q = dict(Q_hh=q, Q_hr=np.zeros_like(q), Q_rh=np.zeros_like(q), Q_rr=q)

    def build(alpha):
        return CooperativeGame(
            model, **Q, R_h=R_h, R_r=R_r, alpha=alpha, horizon=Np, control_horizon=Nc, input_weighting=input_weighting
        )

    lo = 0.02 if input_weighting == "alpha_scaled" else 0.0
    worst, rank = fresh_and_online(build, np.linspace(lo, 1.0 - lo, 13))
    assert worst <= 1e-9
    # both paths of the family are exercised: affine (rank 0) and rational (rank > 0) in α
    if weights == "thesis" and input_weighting == "shared":
        assert rank == 0
    else:
        assert rank > 0


def _random_weights_game(alpha=0.8, n=2, Np=12, Nc=12):
    rng = np.random.default_rng(77)
    model, Q, R_h, R_r, *_ = random_instance(rng, n, Np, Nc)
    return CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=alpha, horizon=Np, control_horizon=Nc)


def test_online_alpha_chebyshev_stretches_match_the_exact_sum_and_a_fresh_computation():
    """With rank > 0 every stretch of [0, 1] gets a series, and α anywhere (nodes, ends, between) matches."""
    game = _random_weights_game()
    game.prepare_alpha_changes()
    family = game._alpha_family
    assert family.rank > 0
    assert len(family.pieces) == family.PIECES and all(p is not None for p in family.pieces)
    import coassist.control.game as game_module

    assert f"``_AlphaFamily.PIECES`` ({family.PIECES})" in game_module.__doc__  # the docstring's count is the code's
    alphas = np.concatenate([np.random.default_rng(3).uniform(0.0, 1.0, 40), np.linspace(0.0, 1.0, 9)])
    for a in alphas:
        exact = family._exact(a)
        assert np.abs(family.gains(a) - exact).max() <= 1e-10 * np.abs(exact).max()
    for a in (0.0, 0.3, 0.77, 1.0):
        game.set_alpha(a)
        fresh = _random_weights_game(alpha=a)
        online = np.hstack([game.gains.G_z, game.gains.G_h, game.gains.G_r])
        ref = np.hstack([fresh.gains.G_z, fresh.gains.G_h, fresh.gains.G_r])
        assert np.abs(online - ref).max() <= 1e-9 * np.abs(ref).max()


def test_online_alpha_stretch_without_a_matching_series_keeps_the_exact_sum(monkeypatch):
    from coassist.control import game as game_module

    monkeypatch.setattr(game_module._AlphaFamily, "MATCH", 0.0)  # no series can match: every stretch exact
    game = _random_weights_game()
    game.prepare_alpha_changes()
    family = game._alpha_family
    assert family.pieces == [None] * family.PIECES
    np.testing.assert_array_equal(family.gains(0.41), family._exact(0.41))


def test_online_alpha_series_over_the_memory_allowance_is_not_built(monkeypatch):
    from coassist.control import game as game_module

    game = _random_weights_game()
    family_bytes = (
        game_module._AlphaFamily.PIECES
        * (game_module._AlphaFamily.DEGREES[-1] + 1)
        * 8
        * (2 * game.n_dof * (2 * game.n_dof + 2 * game.reference_shape[0] * game.reference_shape[1]))
    )
    monkeypatch.setattr(game_module._AlphaFamily, "MAX_BYTES", family_bytes - 1)
    game.prepare_alpha_changes()
    family = game._alpha_family
    assert family.rank > 0 and family.pieces == []
    np.testing.assert_array_equal(family.gains(0.41), family._exact(0.41))
    monkeypatch.setattr(game_module._AlphaFamily, "MAX_BYTES", family_bytes)  # exactly at the allowance: built
    game._families.clear()  # the game keeps the family it prepared at this α; build it again
    game.prepare_alpha_changes()
    assert len(game._alpha_family.pieces) == game_module._AlphaFamily.PIECES


def test_online_alpha_series_is_chebyshev_of_the_documented_degree():
    """The stretch's coefficients reproduce numpy's Chebyshev interpolant at the same points."""
    game = _random_weights_game()
    game.prepare_alpha_changes()
    family = game._alpha_family
    a, coef = family.pieces[3]
    K = coef.shape[0] - 1
    assert K in family.DEGREES
    nodes = np.cos(np.pi * (np.arange(K + 1) + 0.5) / (K + 1))
    values = np.stack([family._exact(a + 0.5 * (t + 1.0) / family.PIECES).ravel() for t in nodes])
    reference = np.polynomial.chebyshev.chebfit(nodes, values, K)
    np.testing.assert_allclose(coef, reference, rtol=1e-9, atol=1e-12 * np.abs(values).max())


def test_horizon_solution_after_an_online_alpha_change_is_the_joint_minimiser():
    rng = np.random.default_rng(8)
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, 2, 8, 4)
    game = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=0.9, horizon=8, control_horizon=4)
    game.set_alpha(0.35)
    U_ref, _, _ = joint_minimiser(model, Q, R_h, R_r, 0.35, 8, 4, z, ref_h, ref_r)
    U_h, U_r = game.solve_horizon(z, ref_h, ref_r)
    np.testing.assert_allclose(np.concatenate([U_h.reshape(-1), U_r.reshape(-1)]), U_ref, rtol=1e-8, atol=1e-10)
    u_h, u_r = game.solve(z, ref_h, ref_r)
    np.testing.assert_allclose(
        np.concatenate([u_h, u_r]), np.concatenate([U_ref[:2], U_ref[8:10]]), rtol=1e-8, atol=1e-10
    )


def test_online_gains_are_read_only():
    game = thesis_game(0.8, horizon=5)
    game.set_alpha(0.4)
    with pytest.raises(ValueError):
        game.gains.G_h[0, 0] = 1.0


@pytest.mark.parametrize("alpha", [0.0, 1.0])
def test_extreme_alphas_are_the_joint_minimiser(alpha):
    rng = np.random.default_rng(int(alpha) + 40)
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, 2, 6, 3)
    game = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=alpha, horizon=6, control_horizon=3)
    U_ref, _, _ = joint_minimiser(model, Q, R_h, R_r, alpha, 6, 3, z, ref_h, ref_r)
    U_h, U_r = game.solve_horizon(z, ref_h, ref_r)
    np.testing.assert_allclose(np.concatenate([U_h.reshape(-1), U_r.reshape(-1)]), U_ref, rtol=1e-8, atol=1e-10)


def test_solve_is_linear_in_its_inputs():
    rng = np.random.default_rng(2)
    game = thesis_game(0.8, horizon=20)
    a = (rng.normal(size=4), rng.normal(size=(20, 4)), rng.normal(size=(20, 4)))
    b = (rng.normal(size=4), rng.normal(size=(20, 4)), rng.normal(size=(20, 4)))
    ua, ub = game.solve(*a), game.solve(*b)
    uab = game.solve(*(x + 2 * y for x, y in zip(a, b)))
    np.testing.assert_allclose(uab[1], ua[1] + 2 * ub[1], rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(alpha=-0.1), "alpha must be in"),
        (dict(R_r=[0, 1e-4]), "R_r must be positive definite"),
        (dict(Q_hh=np.eye(3)), "Q_hh must be 4x4"),
        (dict(Q_rh=-np.eye(4)), "Q_rh must be positive semidefinite"),
        (dict(control_horizon=60), "control_horizon must be <= horizon"),
        (dict(input_weighting="alpha_scaled", alpha=1.0), r"alpha must be in \(0, 1\)"),
        (dict(input_weighting="other"), "input_weighting"),
    ],
)
def test_validation_names_the_field(change, message):
    model = ImpedanceModel([10, 10], [100, 100], 0, 0.008)
    Q = np.diag([1, 1, 1e-4, 1e-4])
    kwargs = dict(Q_hh=Q, Q_hr=0, Q_rh=0, Q_rr=Q, R_h=[5e-4, 5e-4], R_r=[5e-4, 5e-4], alpha=0.8, horizon=50)
    kwargs.update(change)
    with pytest.raises(ValueError, match=message):
        CooperativeGame(model, **kwargs)


def test_reference_and_state_shapes_are_checked():
    game = thesis_game(0.8, horizon=5)
    with pytest.raises(ValueError, match=r"ref_h must have shape \(5, 4\)"):
        game.solve(np.zeros(4), np.zeros((4, 5)), np.zeros((5, 4)))
    with pytest.raises(ValueError, match=r"z must have shape \(4,\)"):
        game.solve(0.5, np.zeros((5, 4)), np.zeros((5, 4)))
    with pytest.raises(ValueError, match=r"z must have shape \(4,\)"):
        game.solve_horizon(np.zeros((4, 1)), np.zeros((5, 4)), np.zeros((5, 4)))


@pytest.mark.parametrize("kind", ["cooperative", "nash"])
@pytest.mark.parametrize(("horizon", "control_horizon", "B"), [(10, 4, 9), (50, 10, 33)])
def test_solve_batch_is_solve_row_for_row_bit_for_bit(kind, horizon, control_horizon, B):
    """Trials in lockstep share one game: each row must get exactly what solve() gives it alone
    (the lockstep runner reproduces the per-trial loop bit for bit), also from a non-contiguous
    batch; at a toy size and at the presets' (Np = 50, a worker's group of 33)."""
    rng = np.random.default_rng(7)
    model, Q, R_h, R_r, _, _, _ = random_instance(rng, 2, horizon, control_horizon)
    if kind == "cooperative":
        game = CooperativeGame(
            model, **Q, R_h=R_h, R_r=R_r, alpha=0.7, horizon=horizon, control_horizon=control_horizon
        )
    else:
        game = NashGame(model, **Q, R_h=R_h, R_r=R_r, horizon=horizon, control_horizon=control_horizon)
    z = rng.normal(size=(B, 4)) * 0.1
    ref_h, ref_r = rng.normal(size=(2, B, horizon, 4)) * 0.1  # slices of one array: ref_r[b] is not ref_h's neighbour
    u_h, u_r = game.solve_batch(z, ref_h, ref_r)
    strided = game.solve_batch(z[::-1], ref_h[::-1, :, ::1], ref_r[::-1])  # rows in reverse: negative strides
    np.testing.assert_array_equal(strided[0], u_h[::-1])
    np.testing.assert_array_equal(strided[1], u_r[::-1])
    assert u_h.shape == u_r.shape == (B, 2)
    for b in range(B):
        e_h, e_r = game.solve(z[b], ref_h[b], ref_r[b])
        np.testing.assert_array_equal(u_h[b], e_h)
        np.testing.assert_array_equal(u_r[b], e_r)
    with pytest.raises(ValueError, match=rf"z, ref_h, ref_r must have shapes \(B, 4\) and \(B, {horizon}, 4\)"):
        game.solve_batch(z, ref_h[:, :5], ref_r)


def test_extrapolation_feedback_is_the_effort_of_a_constant_velocity_reference():
    """[−K, −D] against solve() with ref_h built row by row from the state (rows k+1 … k+Np)."""
    rng = np.random.default_rng(21)
    model, Q, R_h, R_r, *_ = random_instance(rng, 2, 12, 12)
    game = CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=0.7, horizon=12)
    K, D = extrapolation_feedback(game)
    dt = 0.008
    for _ in range(3):
        x, v = rng.normal(size=2), rng.normal(size=2)
        ref_h = np.array([np.r_[x + (i + 1) * dt * v, v] for i in range(12)])
        _, u_r = game.solve(np.r_[x, v], ref_h, np.zeros((12, 4)))
        np.testing.assert_allclose(u_r, -K @ x - D @ v, rtol=1e-10, atol=1e-12)


def test_application_presets_damping_left_by_a_pose_extrapolating_prediction():
    """At the presets' α = 0.9 the "-dm" application preset removes 2/3 of the plant's damping; the damped one
    leaves more than 2/3 (config.APPLICATION_DAMPED_SCALE)."""
    from coassist.control.presets import get_preset, make_controller

    left = {}
    for name in ("thesis-application-dm", "thesis-application-damped"):
        preset = get_preset(name)
        _, D = extrapolation_feedback(make_controller("cooperative", preset).game)
        left[name] = preset.impedance.D[0] + D[0, 0]
    assert left["thesis-application-dm"] == pytest.approx(32.5, abs=0.1)
    assert left["thesis-application-damped"] == pytest.approx(68.7, abs=0.1)
    assert left["thesis-application-damped"] >= 2 / 3 * get_preset("thesis-application-damped").impedance.D[0]


def test_games_of_one_preset_share_the_work_not_the_alpha():
    """cooperative_game builds once per (model, parameters): the copies it hands out have the
    gains of a game built alone, bit for bit, and each its own α."""
    from dataclasses import replace

    from threadpoolctl import threadpool_limits

    from coassist.config import THESIS_WEIGHTS, GameParameters
    from coassist.control import game as game_module
    from coassist.control.game import CooperativeGame, cooperative_game

    model = ImpedanceModel(np.diag([8.0, 8.0]), np.diag([30.0, 30.0]), np.zeros((2, 2)), 0.008)
    params = GameParameters(replace(THESIS_WEIGHTS, Q_hr=(0.2, 0.2, 0.0, 0.0)), horizon=12, control_horizon=6)
    twin = GameParameters(replace(THESIS_WEIGHTS, Q_hr=np.diag([0.2, 0.2, 0.0, 0.0])), horizon=12, control_horizon=6)
    game_module._GAME_MEMO.clear()
    a, b = cooperative_game(model, params), cooperative_game(model, twin)  # equal parameters: one build
    # built as cooperative_game builds, on one BLAS thread: bit for bit on any BLAS build
    with threadpool_limits(1, user_api="blas"):
        alone = CooperativeGame(
            model,
            Q_hh=np.diag([1.0, 1.0, 1e-4, 1e-4]),
            Q_hr=np.diag([0.2, 0.2, 0.0, 0.0]),
            Q_rh=0.0,
            Q_rr=np.diag([1.0, 1.0, 1e-4, 1e-4]),
            R_h=[5e-4, 5e-4],
            R_r=[5e-4, 5e-4],
            alpha=0.8,
            horizon=12,
            control_horizon=6,
        )
    assert params.weights is not twin.weights and params.alpha == 0.8
    assert a is not b and len(game_module._GAME_MEMO) == 1
    for g in (a, b):
        for name in ("G_z", "G_h", "G_r"):
            np.testing.assert_array_equal(getattr(g.gains, name), getattr(alone.gains, name))
    a.set_alpha(0.3)  # prepares the family once; b's α stays
    assert b.alpha == params.alpha and a.alpha == 0.3
    b.prepare_alpha_changes()
    assert b._alpha_family is a._alpha_family  # shared, not rebuilt
    b.set_alpha(0.3)
    alone.set_alpha(0.3)
    np.testing.assert_array_equal(b.gains.G_h, alone.gains.G_h)
    # another model: another game
    other = ImpedanceModel(np.diag([9.0, 9.0]), np.diag([30.0, 30.0]), np.zeros((2, 2)), 0.008)
    assert not np.array_equal(cooperative_game(other, params).gains.G_z, a.gains.G_z)


def test_solve_with_gains_is_each_games_solve_bit_for_bit():
    """Rows with their own gains (games at different α) against each game's own solve."""
    from coassist.control.game import solve_with_gains

    model = ImpedanceModel([10, 10], [100, 100], 0, 0.008)
    Q = 100 * np.diag([1, 1, 1e-4, 1e-4])
    base = CooperativeGame(
        model, Q_hh=Q, Q_hr=0, Q_rh=0, Q_rr=Q, R_h=[5e-4, 5e-4], R_r=[1e-4, 1e-4], alpha=0.5, horizon=20
    )
    games = [base.copy() for _ in range(5)]
    for g, a in zip(games, (0.3, 0.45, 0.6, 0.75, 0.9)):
        g.set_alpha(a)
    rng = np.random.default_rng(3)
    z, ref_h, ref_r = rng.normal(size=(5, 4)), rng.normal(size=(5, 20, 4)), rng.normal(size=(5, 20, 4))
    u_h, u_r = solve_with_gains([g.gains for g in games], z, ref_h, ref_r)
    for b, g in enumerate(games):
        eh, er = g.solve(z[b], ref_h[b], ref_r[b])
        np.testing.assert_array_equal(u_h[b], eh)
        np.testing.assert_array_equal(u_r[b], er)
    assert np.abs(u_r[0] - u_r[-1]).max() > 1e-3  # the α differ enough to matter
    with pytest.raises(ValueError, match="one gain set per row"):
        solve_with_gains([games[0].gains], z, ref_h, ref_r)
    e_h, e_r = solve_with_gains([], z[:0], ref_h[:0], ref_r[:0])
    assert e_h.shape == e_r.shape == (0, 2)


def test_game_weights_object_is_the_keywords_bit_for_bit():
    """One GameWeights, validated once, builds the same game as the six keywords (cooperative
    and Nash); weights given as diagonals are those diagonal matrices."""
    from coassist.control import GameWeights

    rng = np.random.default_rng(11)
    model, Q, R_h, R_r, *_ = random_instance(rng, 2, 10, 5)
    weights = GameWeights(**Q, R_h=R_h, R_r=R_r)
    assert weights.n_dof == 2 and weights.Q_hh.shape == (4, 4) and weights.R_r.shape == (2, 2)
    for by_object, by_keywords in (
        (
            CooperativeGame(model, weights, alpha=0.7, horizon=10, control_horizon=5),
            CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=0.7, horizon=10, control_horizon=5),
        ),
        (
            NashGame(model, weights, horizon=10, control_horizon=5),
            NashGame(model, **Q, R_h=R_h, R_r=R_r, horizon=10, control_horizon=5),
        ),
    ):
        for name in ("G_z", "G_h", "G_r"):
            np.testing.assert_array_equal(getattr(by_object.gains, name), getattr(by_keywords.gains, name))
    diagonals = GameWeights((1, 1, 1e-4, 1e-4), (0.2, 0.2, 0.0, 0.0), 0, (1, 1, 1e-4, 1e-4), 5e-4, (1e-4, 2e-4))
    np.testing.assert_array_equal(diagonals.Q_hr, np.diag([0.2, 0.2, 0.0, 0.0]))
    np.testing.assert_array_equal(diagonals.R_r, np.diag([1e-4, 2e-4]))
    np.testing.assert_array_equal(diagonals.R_h, np.diag([5e-4, 5e-4]))
    # a scalar is that multiple of the identity; the size comes from the first non-scalar weight
    scalar = GameWeights(1.0, 0, 0, 1.0, [5e-4, 5e-4], 5e-4)
    np.testing.assert_array_equal(scalar.Q_hh, np.eye(4))
    np.testing.assert_array_equal(scalar.R_r, 5e-4 * np.eye(2))


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_every_way_to_hand_the_weights_gives_the_same_solution(seed):
    """The three ways a game meets its weights: the GameWeights object, the six keywords
    (the README's sugar, which builds that object) and a preset's GameParameters through
    cooperative_game, on random full (not diagonal) weights: the same gains and the same
    efforts, bit for bit (all built on one BLAS thread, as cooperative_game builds)."""
    from threadpoolctl import threadpool_limits

    from coassist.config import GameParameters
    from coassist.control import GameWeights, cooperative_game

    rng = np.random.default_rng(seed)
    n = 1 + seed % 3
    model, Q, R_h, R_r, z, ref_h, ref_r = random_instance(rng, n, 9, 4)
    alpha = float(rng.uniform(0.1, 0.9))
    weights = GameWeights(**Q, R_h=R_h, R_r=R_r)
    with threadpool_limits(1, user_api="blas"):
        games = [
            CooperativeGame(model, weights, alpha=alpha, horizon=9, control_horizon=4),
            CooperativeGame(model, **Q, R_h=R_h, R_r=R_r, alpha=alpha, horizon=9, control_horizon=4),
        ]
    games.append(cooperative_game(model, GameParameters(weights, alpha=alpha, horizon=9, control_horizon=4)))
    u_h, u_r = games[0].solve(z, ref_h, ref_r)
    assert np.abs(u_r).max() > 1e-6  # a solution that could differ
    for game in games[1:]:
        for name in ("G_z", "G_h", "G_r"):
            np.testing.assert_array_equal(getattr(game.gains, name), getattr(games[0].gains, name))
        e_h, e_r = game.solve(z, ref_h, ref_r)
        np.testing.assert_array_equal(e_h, u_h)
        np.testing.assert_array_equal(e_r, u_r)


def test_game_weights_are_frozen_and_read_only():
    import dataclasses

    from coassist.control import GameWeights

    w = GameWeights(np.eye(4), 0, 0, np.eye(4), [5e-4, 5e-4], [5e-4, 5e-4])
    with pytest.raises(dataclasses.FrozenInstanceError):
        w.R_h = np.eye(2)  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        w.Q_hh[0, 0] = 2.0


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda W, m: W(1.0, 0, 0, 1.0, 5e-4, 5e-4), "GameWeights.n_dof is needed when every weight is a scalar"),
        (lambda W, m: W(1.0, 0, 0, 1.0, 5e-4, 5e-4, n_dof=0), "GameWeights.n_dof must be an int >= 1"),
        (lambda W, m: W(np.eye(3), 0, 0, 1.0, [1, 1], [1, 1]), "Q_hh must be 4x4"),
        (lambda W, m: W(np.eye(4), -np.eye(4), 0, 1.0, [1, 1], [1, 1]), "Q_hr must be positive semidefinite"),
        (lambda W, m: W(np.eye(4), 0, 0, 1.0, [1, 1], [0, 1]), "R_r must be positive definite"),
        (
            lambda W, m: CooperativeGame(m, W(1.0, 0, 0, 1.0, 1.0, 1.0, n_dof=3), alpha=0.5, horizon=5),
            "weights are for 3 DOFs, the model has 2",
        ),
        (
            lambda W, m: CooperativeGame(m, W(1.0, 0, 0, 1.0, 1.0, 1.0, n_dof=2), Q_hh=1.0, alpha=0.5, horizon=5),
            "not both \\(got weights and Q_hh\\)",
        ),
        (lambda W, m: NashGame(m, Q_hh=1.0, Q_rr=1.0, R_h=1.0, R_r=1.0, horizon=5), "the keywords Q_hr, Q_rh"),
        (lambda W, m: NashGame(m, {"Q_hh": 1.0}, horizon=5), "weights must be a GameWeights, got dict"),
    ],
)
def test_game_weights_validation_names_the_weight(build, message):
    from coassist.control import GameWeights

    model = ImpedanceModel([10, 10], [100, 100], 0, 0.008)
    with pytest.raises(ValueError, match=message):
        build(GameWeights, model)


def test_the_game_of_each_discretisation_is_its_own():
    # cooperative_game memoises a build per model: zoh and tustin of one M, D, K, dt are two games (the second asked
    # was handed the first's gains and model)
    from coassist.config import THESIS_WEIGHTS, GameParameters
    from coassist.control.game import cooperative_game

    params = GameParameters(weights=THESIS_WEIGHTS, alpha=0.8, horizon=50)
    dt = 0.2  # long enough for the two discretisations' gains to differ clearly
    models = {d: ImpedanceModel(np.diag([10.0, 10.0]), np.diag([100.0, 100.0]), 0, dt, d) for d in ("tustin", "zoh")}
    memo = {d: cooperative_game(m, params) for d, m in models.items()}
    for d, m in models.items():
        fresh = CooperativeGame(m, THESIS_WEIGHTS, alpha=0.8, horizon=50)
        assert memo[d].model.discretization == d
        # the same solve twice: equal to cond(H) ~ 1e6 times the rounding (BLAS threads may round apart)
        np.testing.assert_allclose(memo[d].gains.G_z, fresh.gains.G_z, rtol=1e-8, atol=0.0)
    gap = np.abs(memo["zoh"].gains.G_z - memo["tustin"].gains.G_z).max() / np.abs(memo["zoh"].gains.G_z).max()
    assert gap > 1e-4


@pytest.mark.parametrize("alpha", [True, np.bool_(False)])
def test_alpha_that_is_no_number_is_refused(alpha):
    from coassist.config import THESIS_WEIGHTS, GameParameters

    model = ImpedanceModel(np.diag([10.0, 10.0]), np.diag([100.0, 100.0]), 0, 0.008)
    with pytest.raises(ValueError, match="alpha must be a number"):
        CooperativeGame(model, THESIS_WEIGHTS, alpha=alpha, horizon=5)
    with pytest.raises(ValueError, match="game.alpha must be a number"):
        GameParameters(weights=THESIS_WEIGHTS, alpha=alpha)
