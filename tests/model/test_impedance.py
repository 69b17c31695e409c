"""The impedance model against scipy.signal.cont2discrete and the closed-form mass-damper."""

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from coassist.model import ImpedanceModel, continuous_matrices, discretize
from coassist.model.impedance import DISCRETE_CACHE_SIZE


def random_impedance(rng, n):
    a = rng.normal(size=(n, n))
    M = a @ a.T + n * np.eye(n)
    b = rng.normal(size=(n, n))
    D = b @ b.T * 10
    c = rng.normal(size=(n, n))
    K = c @ c.T * 50
    return M, D, K


def test_continuous_matrices_equal_eq_3_3_and_3_4_for_one_dof():
    A, B = continuous_matrices(np.array([[2.0]]), np.array([[6.0]]), np.array([[8.0]]))
    np.testing.assert_array_equal(A, [[0.0, 1.0], [-4.0, -3.0]])
    np.testing.assert_array_equal(B, [[0.0], [0.5]])


@pytest.mark.parametrize("n", [1, 2, 3, 6])
@pytest.mark.parametrize("method, scipy_method", [("zoh", "zoh"), ("tustin", "bilinear")])
def test_discretisation_matches_scipy_cont2discrete(n, method, scipy_method):
    rng = np.random.default_rng(n)
    M, D, K = random_impedance(rng, n)
    model = ImpedanceModel(M, D, K, 0.008, discretization=method)
    Ad, Bd, *_ = scipy.signal.cont2discrete(
        (model.A, model.B, np.eye(2 * n), np.zeros((2 * n, n))), 0.008, method=scipy_method
    )
    np.testing.assert_allclose(model.Ad, Ad, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(model.Bd, Bd, rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(model.C, np.eye(2 * n))


def test_zero_order_hold_is_exact_for_a_mass_damper_under_constant_force():
    # M v' + D v = u  →  v(t) = u/D + (v0 − u/D) e^{−t D/M},  x(t) = x0 + u t/D + (v0 − u/D)(M/D)(1 − e^{−t D/M})
    m, d, u, dt = 10.0, 100.0, 7.0, 0.008
    model = ImpedanceModel(m, d, 0.0, dt)
    z = np.array([0.3, -0.2])
    for _ in range(25):
        z = model.step(z, np.array([u]))
    t = 25 * dt
    decay = np.exp(-t * d / m)
    v = u / d + (-0.2 - u / d) * decay
    x = 0.3 + u * t / d + (-0.2 - u / d) * (m / d) * (1 - decay)
    # 25 steps, each exact to a few ulp of the state (expm's backward error is ~ε·‖A·dt‖): the
    # error stays below ~25·10·ε of |z| ≈ 0.3, i.e. ≲ 2e-12 relative to v ≈ 0.03.
    np.testing.assert_allclose(z, [x, v], rtol=1e-11)


def test_diagonal_shorthand_and_dof_count():
    model = ImpedanceModel([10, 10], [100, 100], 0, 0.008)
    assert model.n_dof == 2 and model.n_state == 4
    np.testing.assert_array_equal(model.M, np.diag([10.0, 10.0]))
    np.testing.assert_array_equal(model.K, np.zeros((2, 2)))


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(M=[[1, 2], [0, 1]], D=[1, 1], K=[0, 0], dt=0.01), "M must be symmetric"),
        (dict(M=[1, -1], D=[1, 1], K=[0, 0], dt=0.01), "M must be positive definite"),
        (dict(M=[1, 1], D=[1, -1], K=[0, 0], dt=0.01), "D must be positive semidefinite"),
        (dict(M=[1, 1], D=[1, 1], K=[[0, 1], [1, 0]], dt=0.01), "K must be positive semidefinite"),
        (dict(M=[1, 1], D=[1, 1, 1], K=[0, 0], dt=0.01), "D must be 2x2"),
        (dict(M=[1, 1], D=[1, 1], K=[0, 0], dt=0.0), "dt must be a finite number > 0"),
        (dict(M=[1, np.nan], D=[1, 1], K=[0, 0], dt=0.01), "M has non-finite"),
        (dict(M=np.ones(7), D=np.ones(7), K=np.zeros(7), dt=0.01), "1 to 6 Cartesian DOFs"),
        (dict(M=[1, 1], D=[1, 1], K=[0, 0], dt=0.01, discretization="euler"), "discretization"),
    ],
)
def test_validation_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ImpedanceModel(**kwargs)


def test_model_is_immutable():
    model = ImpedanceModel(1, 1, 0, 0.01)
    with pytest.raises(ValueError):
        model.Ad[0, 0] = 2.0


@pytest.mark.parametrize("method", ["zoh", "tustin"])
def test_discretize_gives_the_same_bits_when_it_remembers_and_new_arrays_each_time(method):
    # The formulas of eq. 3.5 written out here (Van Loan's block exponential; Tustin's solves): the
    # same floating-point operations, so the same bits, whether discretize computes or remembers.
    rng = np.random.default_rng(7)
    M, D, K = random_impedance(rng, 2)
    A, B = continuous_matrices(M, D, K)
    dt = 0.008
    if method == "zoh":
        block = np.zeros((6, 6))
        block[:4, :4] = A * dt
        block[:4, 4:] = B * dt
        e = scipy.linalg.expm(block)
        want = (e[:4, :4], e[:4, 4:])
    else:
        lhs = np.eye(4) - A * (dt / 2.0)
        want = (np.linalg.solve(lhs, np.eye(4) + A * (dt / 2.0)), np.linalg.solve(lhs, B * dt))
    first = discretize(A, B, dt, method)
    first[0][:] = np.nan  # the caller's own arrays: changing them changes nothing remembered
    first[1][:] = np.nan
    for got in (discretize(A, B, dt, method), discretize(A.copy(), B.copy(), dt, method)):
        np.testing.assert_array_equal(got[0], want[0], strict=True)
        np.testing.assert_array_equal(got[1], want[1], strict=True)
    # another dt or another matrix is another discretisation, not the one remembered
    other = discretize(A, B, dt / 2, method)[0]
    assert not np.array_equal(other, want[0])
    A2 = A.copy()
    A2[2, 2] *= 2.0
    assert not np.array_equal(discretize(A2, B, dt, method)[0], want[0])


def test_discretize_answers_right_past_the_number_it_remembers():
    A, B = continuous_matrices(np.array([[2.0]]), np.array([[6.0]]), np.array([[0.0]]))
    dts = [0.001 * (k + 1) for k in range(DISCRETE_CACHE_SIZE + 5)]
    for dt in dts:
        Ad, Bd = discretize(A, B, dt)
        # the 1-DOF mass-damper's closed form: v decays by exp(-dt D/M)
        np.testing.assert_allclose(Ad[1, 1], np.exp(-dt * 3.0), rtol=1e-13)
    # the first dt was let go (the oldest of more than DISCRETE_CACHE_SIZE): computed again, right
    np.testing.assert_allclose(discretize(A, B, dts[0])[0][1, 1], np.exp(-dts[0] * 3.0), rtol=1e-13)


def test_discretize_names_a_bad_method_before_remembering_anything():
    A, B = continuous_matrices(np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]]))
    with pytest.raises(ValueError, match="discretization must be 'zoh' or 'tustin'"):
        discretize(A, B, 0.01, "euler")  # type: ignore[arg-type]
