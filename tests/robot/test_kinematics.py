"""Tests of coassist.robot.kinematics against independent references.

References: a hand-written standard-DH UR5 chain with UR's published parameters,
central finite differences of the forward kinematics, numpy's pinv and scipy's
Rotation.
"""

from __future__ import annotations

import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")
try:
    metadata.distribution("example-robot-data")
except metadata.PackageNotFoundError:
    pytest.skip("the UR5 model needs example-robot-data: pip install 'coassist[robot]'", allow_module_level=True)

from scipy.spatial.transform import Rotation  # noqa: E402

from coassist.robot import kinematics as kinematics_module  # noqa: E402
from coassist.robot.kinematics import (  # noqa: E402
    IKConvergenceError,
    UR5Kinematics,
    damped_pseudo_inverse,
    joint_velocity,
    manipulability,
    orientation_error,
    rotation_matrix,
    rotation_vector,
    solve_ik,
    ur5_urdf_path,
)

# UR5 standard DH parameters (Universal Robots, "DH parameters for calculations of kinematics").
DH_D = np.array([0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823])
DH_A = np.array([0.0, -0.425, -0.39225, 0.0, 0.0, 0.0])
DH_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])

# Constant rotation of URDF tool0 in the DH frame 6, found by comparing the two chains
# (R_dh6ᵀ R_tool0 at random joint vectors): the identity. With the module's base frame
# (URDF base_link rotated by pi about z) tool0 *is* the DH flange frame.
R_DH6_TOOL0 = np.eye(3)

HOME = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
WELL_CONDITIONED = np.array([0.1, -1.2, 1.5, -1.9, -1.5, 0.3])


def dh_forward(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standard-DH forward kinematics of the UR5: flange position and rotation in the base frame."""
    T = np.eye(4)
    for theta, d, a, alpha in zip(q, DH_D, DH_A, DH_ALPHA):
        ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
        T = T @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return T[:3, 3], T[:3, :3] @ R_DH6_TOOL0


def fd_jacobian(kin: UR5Kinematics, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences: linear part from positions, angular part from log(R+ R-ᵀ)/(2h)."""
    J = np.zeros((6, 6))
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        p_plus, R_plus = kin.forward(q + dq)
        p_minus, R_minus = kin.forward(q - dq)
        J[:3, i] = (p_plus - p_minus) / (2 * h)
        J[3:, i] = rotation_vector(R_plus @ R_minus.T) / (2 * h)
    return J


@pytest.fixture(scope="module")
def kin() -> UR5Kinematics:
    return UR5Kinematics()


@pytest.fixture(scope="module")
def kin_offset() -> UR5Kinematics:
    return UR5Kinematics(tcp_offset=(0.01, -0.02, 0.15, 0.1, -0.2, 0.3))


def random_q(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(-np.pi, np.pi, size=(n, 6))


# ----------------------------------------------------------------------------
# Forward kinematics
# ----------------------------------------------------------------------------


def test_forward_matches_standard_dh(kin):
    rng = np.random.default_rng(20240611)
    for q in random_q(rng, 25):
        p, R = kin.forward(q)
        p_dh, R_dh = dh_forward(q)
        np.testing.assert_allclose(p, p_dh, rtol=0, atol=1e-6)
        np.testing.assert_allclose(R, R_dh, rtol=0, atol=1e-6)


def test_zero_configuration_in_base_frame(kin):
    p, R = kin.forward(np.zeros(6))
    # (a2 + a3, -(d4 + d6), d1 - d5): the URDF's (0.817, 0.191, -0.005) rotated by pi about z.
    np.testing.assert_allclose(p, [-0.81725, -0.19145, 0.089159 - 0.09465], atol=1e-9)
    np.testing.assert_allclose(R, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-9)


def test_pose_is_position_and_rotation_vector(kin):
    p, R = kin.forward(WELL_CONDITIONED)
    pose = kin.pose(WELL_CONDITIONED)
    np.testing.assert_allclose(pose[:3], p, atol=1e-15)
    np.testing.assert_allclose(rotation_matrix(pose[3:]), R, atol=1e-12)


def test_forward_and_jacobian_matches_separate_calls(kin):
    q_other = np.array([1.0, -0.5, 0.7, 0.2, 1.1, -2.0])
    kin.forward(q_other)  # leave the pinocchio data at another configuration
    p, R, J = kin.forward_and_jacobian(WELL_CONDITIONED)
    kin.forward(q_other)
    p2, R2 = kin.forward(WELL_CONDITIONED)
    np.testing.assert_array_equal(p, p2)
    np.testing.assert_array_equal(R, R2)
    np.testing.assert_allclose(J, kin.jacobian(WELL_CONDITIONED), rtol=0, atol=1e-15)
    assert p.shape == (3,) and R.shape == (3, 3) and J.shape == (6, 6)


def test_returned_arrays_are_not_views_of_the_model_state(kin):
    p, R, J = kin.forward_and_jacobian(WELL_CONDITIONED)
    saved = p.copy(), R.copy(), J.copy()
    kin.forward_and_jacobian(HOME)
    np.testing.assert_array_equal(p, saved[0])
    np.testing.assert_array_equal(R, saved[1])
    np.testing.assert_array_equal(J, saved[2])


# ----------------------------------------------------------------------------
# Jacobian
# ----------------------------------------------------------------------------


def test_jacobian_matches_finite_differences(kin):
    rng = np.random.default_rng(7)
    for q in random_q(rng, 10):
        np.testing.assert_allclose(kin.jacobian(q), fd_jacobian(kin, q), rtol=0, atol=1e-6)


def test_jacobian_of_dh_chain(kin):
    # Linear rows also against differences of the independent DH chain.
    rng = np.random.default_rng(8)
    h = 1e-6
    for q in random_q(rng, 5):
        J = kin.jacobian(q)
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h
            dp = (dh_forward(q + dq)[0] - dh_forward(q - dq)[0]) / (2 * h)
            np.testing.assert_allclose(J[:3, i], dp, rtol=0, atol=1e-6)


# ----------------------------------------------------------------------------
# TCP offset
# ----------------------------------------------------------------------------


def test_tcp_offset_composes_with_tool0(kin, kin_offset):
    t = np.asarray(kin_offset.tcp_offset[:3])
    R_off = rotation_matrix(kin_offset.tcp_offset[3:])
    rng = np.random.default_rng(3)
    for q in random_q(rng, 10):
        p0, R0 = kin.forward(q)
        p, R = kin_offset.forward(q)
        np.testing.assert_allclose(p, p0 + R0 @ t, rtol=0, atol=1e-12)
        np.testing.assert_allclose(R, R0 @ R_off, rtol=0, atol=1e-12)


def test_tcp_offset_jacobian_matches_finite_differences(kin, kin_offset):
    rng = np.random.default_rng(4)
    for q in random_q(rng, 5):
        J = kin_offset.jacobian(q)
        np.testing.assert_allclose(J, fd_jacobian(kin_offset, q), rtol=0, atol=1e-6)
        # Rigid-body transport: v_tcp = v_tool0 + ω × (p_tcp - p_tool0), ω unchanged.
        J0 = kin.jacobian(q)
        r = kin_offset.forward(q)[0] - kin.forward(q)[0]
        np.testing.assert_allclose(J[:3], J0[:3] - np.cross(r, J0[3:].T).T, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J[3:], J0[3:], rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "bad",
    [
        (0, 0, 0),
        (0, 0, 0, 0, 0, 0, 0),
        (0, 0, np.nan, 0, 0, 0),
        (0, 0, 0, np.inf, 0, 0),
        "abcdef",
        ((0, 0, 0), (0, 0, 0)),
    ],
)
def test_tcp_offset_is_validated(bad):
    with pytest.raises(ValueError, match="tcp_offset"):
        UR5Kinematics(tcp_offset=bad)


def test_q_is_validated(kin):
    with pytest.raises(ValueError, match="q must have shape"):
        kin.forward(np.zeros(5))
    with pytest.raises(ValueError, match="q has non-finite"):
        kin.jacobian([0, 0, np.nan, 0, 0, 0])


def test_limits(kin):
    assert kin.n_joints == 6
    np.testing.assert_array_equal(kin.joint_velocity_limit, np.full(6, np.pi))
    assert kin.joint_position_limit.shape == (6, 2)
    np.testing.assert_array_equal(kin.joint_position_limit[:, 0], -2 * np.pi)
    np.testing.assert_array_equal(kin.joint_position_limit[:, 1], 2 * np.pi)


# ----------------------------------------------------------------------------
# Damped pseudo-inverse and the joint-velocity map
# ----------------------------------------------------------------------------


def test_dls_equals_pinv_when_well_conditioned(kin):
    rng = np.random.default_rng(11)
    checked = 0
    for q in random_q(rng, 40):
        J = kin.jacobian(q)
        if np.linalg.svd(J, compute_uv=False)[-1] < 0.06:
            continue
        J_pinv, lam = damped_pseudo_inverse(J)
        assert lam == 0.0
        np.testing.assert_allclose(J_pinv, np.linalg.pinv(J), rtol=0, atol=1e-10)
        twist = rng.normal(size=6)
        np.testing.assert_allclose(joint_velocity(J, twist), np.linalg.pinv(J) @ twist, rtol=0, atol=1e-10)
        checked += 1
    assert checked >= 10


def test_dls_non_square():
    rng = np.random.default_rng(12)
    for shape in [(3, 6), (6, 3)]:
        J = rng.normal(size=shape)
        J_pinv, lam = damped_pseudo_inverse(J, sigma_threshold=1e-3)
        assert lam == 0.0 and J_pinv.shape == shape[::-1]
        np.testing.assert_allclose(J_pinv, np.linalg.pinv(J), rtol=0, atol=1e-10)
    J = rng.normal(size=(3, 6))
    J[2] = J[1]  # rank 2
    J_pinv, lam = damped_pseudo_inverse(J)
    assert lam == pytest.approx(0.05, abs=1e-9)
    np.testing.assert_allclose(J_pinv, J.T @ np.linalg.inv(J @ J.T + lam**2 * np.eye(3)), rtol=0, atol=1e-10)


def test_dls_bounded_at_wrist_singularity(kin):
    # q5 = 0 aligns the axes of joints 4 and 6: a rank drop of the Jacobian.
    q = WELL_CONDITIONED.copy()
    q[4] = 0.0
    assert np.linalg.svd(kin.jacobian(q), compute_uv=False)[-1] < 1e-12
    q[4] = 1e-6
    J = kin.jacobian(q)
    U, s, Vt = np.linalg.svd(J)
    worst = U[:, -1]  # unit twist along the lost direction
    assert np.linalg.norm(np.linalg.pinv(J) @ worst) > 1e4  # undamped inverse blows up

    J_pinv, lam = damped_pseudo_inverse(J)  # defaults: sigma_threshold = max_damping = 0.05
    assert lam == pytest.approx(0.05, rel=1e-6)
    np.testing.assert_allclose(J_pinv, J.T @ np.linalg.inv(J @ J.T + lam**2 * np.eye(6)), rtol=0, atol=1e-9)
    bound = 1.0 / (2.0 * lam)
    assert np.linalg.norm(J_pinv, 2) <= bound * (1 + 1e-12)
    rng = np.random.default_rng(13)
    twists = [worst] + list(rng.normal(size=(50, 6)))
    for twist in twists:
        twist = twist / np.linalg.norm(twist)
        qdot = joint_velocity(J, twist)
        assert np.linalg.norm(qdot) <= bound * (1 + 1e-12)
        assert np.linalg.norm(qdot) <= 10.0 + 1e-9  # 1/(2 * 0.05) rad/s per (m/s or rad/s)


def _synthetic_jacobian(sigma_min: float) -> np.ndarray:
    rng = np.random.default_rng(14)
    U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    return U @ np.diag([2.0, 1.5, 1.0, 0.6, 0.3, sigma_min]) @ V.T


def test_damping_is_continuous_in_sigma_min():
    thr, lam_max = 0.05, 0.05
    # The SVD gives σ_min to within d_sigma = p(n)·ε·‖J‖₂ (backward stability; p(n) = n²
    # covers forming J = U Σ Vᵀ as well): 36 · 2.2e-16 · 2 ≈ 1.6e-14, whatever the BLAS.
    # λ(σ) = λ_max·sqrt(1 − (σ/thr)²) is only Hölder-½ continuous at the threshold, so an
    # error d_sigma in σ moves λ by at most lam_tol = λ_max·sqrt(2·d_sigma/thr) ≈ 4e-8
    # (|√a − √b| ≤ √|a − b|), the test's tolerance everywhere. A wrong law is off by ≳ 1e-3.
    d_sigma = 36 * np.finfo(float).eps * 2.0
    lam_tol = lam_max * np.sqrt(2 * d_sigma / thr)
    assert damped_pseudo_inverse(_synthetic_jacobian(thr))[1] <= lam_tol  # at the threshold: (nearly) undamped
    assert damped_pseudo_inverse(_synthetic_jacobian(0.0))[1] == pytest.approx(lam_max, abs=lam_tol)
    sigmas = np.linspace(0.0, 0.08, 81)
    lams = np.array([damped_pseudo_inverse(_synthetic_jacobian(s))[1] for s in sigmas])
    expected = np.where(sigmas >= thr, 0.0, lam_max * np.sqrt(np.clip(1 - (sigmas / thr) ** 2, 0, None)))
    np.testing.assert_allclose(lams, expected, rtol=0, atol=lam_tol)
    # Decreasing below the threshold (neighbours on this grid differ by ≥ 1e-5 ≫ 2·lam_tol),
    # exactly zero beyond it (σ ≥ thr + 1e-3, far outside d_sigma).
    below_thr = sigmas < thr - 1e-6
    assert np.all(np.diff(lams[below_thr]) < -2 * lam_tol)
    assert np.all(lams[sigmas > thr + 1e-6] == 0.0)
    # The inverse itself is continuous across the threshold. At thr ∓ gap, gap = 1e-9 ≫ d_sigma:
    # above is exactly undamped; below, λ = λ_max·sqrt(2·gap/thr)·(1 + O(gap/thr)) = 1e-5, known
    # to a relative d_sigma/gap ≈ 2e-5 (σ's error against the gap that sets λ).
    gap = 1e-9
    below, lam_below = damped_pseudo_inverse(_synthetic_jacobian(thr - gap))
    above, lam_above = damped_pseudo_inverse(_synthetic_jacobian(thr + gap))
    assert lam_above == 0.0
    assert lam_below == pytest.approx(lam_max * np.sqrt(1 - ((thr - gap) / thr) ** 2), rel=d_sigma / gap)
    # ‖J⁺(below) − J⁺(above)‖ ≈ λ²/σ³ + 2·gap/σ² ≈ 8e-7 + 8e-7 (the σ_min direction only).
    assert np.linalg.norm(below - above, 2) < 5e-6


@pytest.mark.parametrize("name", ["sigma_threshold", "max_damping"])
@pytest.mark.parametrize("value", [0.0, -1.0, np.nan, np.inf, "x"])
def test_dls_options_are_validated(name, value):
    with pytest.raises(ValueError, match=name):
        damped_pseudo_inverse(np.eye(6), **{name: value})
    with pytest.raises(ValueError, match=name):
        joint_velocity(np.eye(6), np.ones(6), **{name: value})


def test_joint_velocity_validates_shapes():
    with pytest.raises(ValueError, match="twist"):
        joint_velocity(np.eye(6), np.ones(5))
    with pytest.raises(ValueError, match="J"):
        joint_velocity(np.ones(6), np.ones(6))


def test_manipulability(kin):
    J = kin.jacobian(WELL_CONDITIONED)
    assert manipulability(J) == pytest.approx(np.sqrt(np.linalg.det(J @ J.T)), rel=1e-10)
    q = WELL_CONDITIONED.copy()
    q[4] = 0.0
    assert manipulability(kin.jacobian(q)) < 1e-10
    assert manipulability(np.ones((6, 3))) == 0.0


# ----------------------------------------------------------------------------
# Rotations
# ----------------------------------------------------------------------------

SPECIAL_ANGLES = [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.5, np.pi / 2, 3.0, np.pi - 1e-3, np.pi - 1e-6, np.pi - 1e-9, np.pi]


@pytest.mark.parametrize("angle", SPECIAL_ANGLES)
def test_rotation_round_trip(angle):
    rng = np.random.default_rng(15)
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        rv = angle * axis
        R = rotation_matrix(rv)
        np.testing.assert_allclose(R, Rotation.from_rotvec(rv).as_matrix(), rtol=0, atol=1e-14)
        np.testing.assert_allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-14)
        back = rotation_vector(R)
        np.testing.assert_allclose(rotation_matrix(back), R, rtol=0, atol=1e-14)
        assert np.linalg.norm(back) <= np.pi + 1e-15
        if angle < np.pi - 1e-7:
            np.testing.assert_allclose(back, rv, rtol=0, atol=1e-9 if angle > 3 else 1e-14)
        else:  # at pi, rv and -rv are the same rotation
            assert min(np.linalg.norm(back - rv), np.linalg.norm(back + rv)) < 1e-7


def test_rotation_vector_against_scipy():
    rng = np.random.default_rng(16)
    for R in Rotation.random(200, random_state=rng).as_matrix():
        np.testing.assert_allclose(rotation_vector(R), Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-12)


def test_orientation_error_of_known_rotation():
    R_actual = Rotation.from_rotvec([0.3, -1.0, 0.5]).as_matrix()
    small = np.array([0.002, -0.01, 0.005])
    # Desired = actual turned by `small` about base axes: the error is `small`.
    np.testing.assert_allclose(orientation_error(rotation_matrix(small) @ R_actual, R_actual), small, atol=1e-14)
    # Desired = actual turned about its own z axis: the error is that axis in the base frame.
    R_desired = R_actual @ rotation_matrix([0.0, 0.0, 0.01])
    np.testing.assert_allclose(orientation_error(R_desired, R_actual), 0.01 * R_actual[:, 2], atol=1e-14)
    np.testing.assert_allclose(orientation_error(R_actual, R_actual), np.zeros(3), atol=1e-15)


def test_rotation_inputs_validated():
    with pytest.raises(ValueError, match="rv"):
        rotation_matrix([1.0, 2.0])
    with pytest.raises(ValueError, match="R"):
        rotation_vector(np.eye(4))
    with pytest.raises(ValueError, match="R_desired"):
        orientation_error(np.full((3, 3), np.nan), np.eye(3))


def test_rotation_helpers_work_without_pinocchio():
    # Only the UR5Kinematics constructor imports pinocchio.
    source = Path(kinematics_module.__file__).read_text()
    head = source.split("def _import_pinocchio")[0]
    assert "import pinocchio" not in head


# ----------------------------------------------------------------------------
# Inverse kinematics
# ----------------------------------------------------------------------------


def test_solve_ik_recovers_random_pose(kin_offset):
    rng = np.random.default_rng(17)
    for q_true in random_q(rng, 5):
        p, R = kin_offset.forward(q_true)
        q0 = q_true + rng.uniform(-0.2, 0.2, size=6)
        q = solve_ik(kin_offset, p, R, q0)
        p_sol, R_sol = kin_offset.forward(q)
        np.testing.assert_allclose(p_sol, p, rtol=0, atol=1e-6)
        assert np.linalg.norm(orientation_error(R, R_sol)) < 1e-6


def test_solve_ik_task_start_and_end(kin):
    # Tool pointing down (tool z = -base z) over the task's start and end points.
    R_down = np.diag([1.0, -1.0, -1.0])
    for xy in [(-0.10, -0.615), (0.40, -0.615)]:
        target = np.array([*xy, 0.20])
        q = solve_ik(kin, target, R_down, HOME)
        p, R = kin.forward(q)
        np.testing.assert_allclose(p, target, atol=1e-6)
        np.testing.assert_allclose(R, R_down, atol=1e-6)


def test_solve_ik_position_only(kin):
    target = np.array([0.1, -0.5, 0.3])
    q = solve_ik(kin, target, None, HOME)
    np.testing.assert_allclose(kin.forward(q)[0], target, atol=1e-6)


def test_solve_ik_unreachable_raises(kin):
    with pytest.raises(IKConvergenceError, match="did not converge"):
        solve_ik(kin, np.array([2.0, 0.0, 0.0]), None, HOME, max_iterations=50)


# ----------------------------------------------------------------------------
# Model file and optional dependency
# ----------------------------------------------------------------------------


def test_urdf_is_the_installed_one(kin):
    path = ur5_urdf_path()
    assert path.is_file() and path.name == "ur5_robot.urdf"
    root = Path(metadata.distribution("example-robot-data").locate_file("")).resolve()
    assert path.resolve().is_relative_to(root)
    assert any(p.endswith("site-packages") for p in map(str, path.resolve().parents))
    assert kin.urdf_path == path


def test_missing_example_robot_data_names_the_extra(monkeypatch):
    def missing(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(kinematics_module.metadata, "distribution", missing)
    with pytest.raises(ImportError, match=r"coassist\[robot\]"):
        ur5_urdf_path()


def test_missing_pinocchio_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pinocchio", None)
    with pytest.raises(ImportError, match=r"coassist\[robot\]"):
        UR5Kinematics()
