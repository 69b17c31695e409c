"""The arm registry: the Panda model against Franka's published DH table, its Jacobian against
finite differences, and the null-space posture of eq. 3.6 on 7 joints."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pinocchio", reason="the arm kinematics need the robot extra: pip install 'coassist[robot]'")

from coassist.robot.arms import ARMS, NullSpacePosture, arm_kinematics, check_model_matches, get_arm  # noqa: E402
from coassist.robot.kinematics import UR5Kinematics  # noqa: E402

# Franka's DH table (modified / Craig convention), frames 1..7 and the flange F: (a, d, alpha).
_PANDA_DH = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -np.pi / 2),
    (0.0, 0.316, np.pi / 2),
    (0.0825, 0.0, np.pi / 2),
    (-0.0825, 0.384, -np.pi / 2),
    (0.0, 0.0, np.pi / 2),
    (0.088, 0.0, np.pi / 2),
]
_FLANGE_D = 0.107


def _craig(a, d, alpha, theta):
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array([[ct, -st, 0, a], [st * ca, ct * ca, -sa, -d * sa], [st * sa, ct * sa, ca, d * ca], [0, 0, 0, 1]])


def _panda_flange(q):
    T = np.eye(4)
    for (a, d, alpha), th in zip(_PANDA_DH, q, strict=True):
        T = T @ _craig(a, d, alpha, th)
    return T @ _craig(0.0, _FLANGE_D, 0.0, 0.0)


@pytest.fixture(scope="module")
def panda():
    return arm_kinematics("panda")


def test_panda_forward_kinematics_is_franka_dh_table(panda):
    rng = np.random.default_rng(0)
    lim = panda.joint_position_limit
    for q in [np.array(get_arm("panda").home), *rng.uniform(lim[:, 0], lim[:, 1], (20, 7))]:
        p, R = panda.forward(q)
        T = _panda_flange(q)
        np.testing.assert_allclose(p, T[:3, 3], atol=1e-9)  # two exact products of 8 transforms
        np.testing.assert_allclose(R, T[:3, :3], atol=1e-9)


def test_panda_limits_come_from_the_model(panda):
    # the URDF's limits (Franka's datasheet): joint 4 never straight, joint 6 mostly positive
    np.testing.assert_allclose(panda.joint_position_limit[3], (-3.0718, -0.0698))
    np.testing.assert_allclose(panda.joint_position_limit[5], (-0.0175, 3.7525))
    assert panda.n_joints == 7 and panda.jacobian(np.array(ARMS["panda"].home)).shape == (6, 7)


def test_panda_jacobian_is_the_derivative_of_the_pose(panda):
    # central differences, h = 1e-6: truncation O(h²) ~ 1e-12, rounding ~ 1e-16/h ~ 1e-10
    q = np.array(get_arm("panda").home) + 0.1
    J = panda.jacobian(q)
    h = 1e-6
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = h
        (p1, R1), (p0, R0) = panda.forward(q + dq), panda.forward(q - dq)
        np.testing.assert_allclose((p1 - p0) / (2 * h), J[:3, i], atol=1e-8)
        W = (R1 - R0) / (2 * h) @ panda.forward(q)[1].T  # skew(ω)
        np.testing.assert_allclose([W[2, 1], W[0, 2], W[1, 0]], J[3:, i], atol=1e-8)


def test_ur5_entry_reproduces_ur5_kinematics():
    # the registry's UR5 is the class the UR worlds use, bit for bit
    q = np.array(ARMS["ur5"].home)
    a, b = arm_kinematics("ur5", (0, 0, 0.06, 0, 0, 0)), UR5Kinematics((0, 0, 0.06, 0, 0, 0))
    assert np.array_equal(a.jacobian(q), b.jacobian(q)) and np.array_equal(a.pose(q), b.pose(q))


def test_null_space_posture_tracks_the_twist_and_pulls_the_posture(panda):
    home = np.array(get_arm("panda").home)
    res = NullSpacePosture(panda, home, gain=2.0)
    q = home + np.array([0.1, -0.05, 0.2, 0.05, -0.1, 0.05, 0.1])
    _, _, J = panda.forward_and_jacobian(q)
    twist = np.array([0.05, -0.02, 0.01, 0.0, 0.1, 0.0])
    qd = res.redundant_joint_velocity(q, J, twist)
    np.testing.assert_allclose(J @ qd, twist, atol=1e-10)  # well conditioned: no damping, exact
    # no task motion: the tool stays put and the arm moves toward the posture
    qd0 = res.redundant_joint_velocity(q, J, np.zeros(6))
    np.testing.assert_allclose(J @ qd0, 0.0, atol=1e-10)
    assert qd0 @ (home - q) > 0.0
    # the null-space term is the projection of k (q0 - q): (I - J⁺J) is symmetric idempotent
    N = np.eye(7) - np.linalg.pinv(J) @ J
    np.testing.assert_allclose(qd0, N @ (2.0 * (home - q)), atol=1e-10)


def test_joint_range_scales_the_command_uniformly(panda):
    home = np.array(get_arm("panda").home)
    res = NullSpacePosture(panda, home, limit_margin=0.05, limit_horizon=0.1)
    q = home.copy()
    q[3] = -0.0698 - 0.06  # 1 cm of room (above the 5 cm margin) below joint 4's upper limit
    qd = np.array([0.0, 0.0, 0.0, 0.5, 0.0, 0.2, 0.0])
    out = res.limit_to_joint_range(q, qd)
    np.testing.assert_allclose(out, qd * (0.01 / (0.5 * 0.1)))  # s = room / (|q̇| τ) = 0.2
    np.testing.assert_allclose(res.limit_to_joint_range(q, -qd), -qd)  # away from the limit: untouched
    q[3] = -0.0698 - 0.01  # inside the margin: no motion toward the limit at all
    np.testing.assert_allclose(res.limit_to_joint_range(q, qd), 0.0)


def test_model_check_names_the_mismatch(panda):
    q = np.array(get_arm("panda").home)
    pose = panda.pose(q)
    check_model_matches(panda, q, pose)
    with pytest.raises(ValueError, match="does not match the robot.*mm"):
        check_model_matches(panda, q, pose + np.array([0.01, 0, 0, 0, 0, 0]))


def test_unknown_arm_names_the_known_ones():
    with pytest.raises(ValueError, match="unknown robot 'kuka'.*panda.*ur5"):
        get_arm("kuka")


def test_the_posture_never_moves_the_tool_near_a_singularity(panda):
    # Stretched out along −y (where the fault table's push ends): σ_min(J) < 0.05, so the
    # task inverse is damped (λ > 0) and I − J⁺J is no projector; the posture term must use
    # the exact one. Without a task twist the tool must not move: J q̇ = 0 to rounding.
    from coassist.spatial import damped_pseudo_inverse

    q = np.array([1.56, -1.18, -1.78, -0.47, -1.21, 1.31, -1.1])
    _, _, J = panda.forward_and_jacobian(q)
    J_pinv, lam = damped_pseudo_inverse(J, sigma_threshold=0.05, max_damping=0.05)
    assert lam > 0.0
    home = np.array(get_arm("panda").home)
    pull = home - q
    assert np.linalg.norm(J @ (pull - J_pinv @ J @ pull)) > 1e-3  # the damped "projector" leaks
    qd0 = NullSpacePosture(panda, home, gain=1.0, limit_margin=1e-6).redundant_joint_velocity(q, J, np.zeros(6))
    np.testing.assert_allclose(J @ qd0, 0.0, atol=1e-12)
    assert qd0 @ pull > 0.0


def test_fr3_limits_are_the_fr3_urdf_and_its_kinematics_the_pandas(panda):
    # The reference: Franka's FR3 URDF as franky-sim ships it (franky_sim/assets/fr3.urdf).
    franky_sim = pytest.importorskip(
        "franky_sim", reason="the FR3 URDF comes with franky-sim: pip install 'coassist[franka]'"
    )
    import xml.etree.ElementTree as ET
    from importlib.resources import files

    root = ET.parse(str(files(franky_sim) / "assets" / "fr3.urdf")).getroot()
    limits = {j.get("name"): j.find("limit") for j in root.iter("joint") if j.get("type") == "revolute"}
    names = [f"fr3_joint{i}" for i in range(1, 8)]
    fr3 = arm_kinematics("fr3")
    np.testing.assert_array_equal(
        fr3.joint_position_limit, [(float(limits[n].get("lower")), float(limits[n].get("upper"))) for n in names]
    )
    np.testing.assert_array_equal(fr3.joint_velocity_limit, [float(limits[n].get("velocity")) for n in names])
    assert not np.array_equal(fr3.joint_position_limit, panda.joint_position_limit)  # joints 4 and 6 differ
    q = np.array(get_arm("fr3").home) + 0.1
    assert np.array_equal(fr3.pose(q), panda.pose(q))  # the same model: the same numbers


def test_the_ros2_nodes_ur_joint_names_are_the_urdfs():
    # ros2_world keeps its own copy (the ROS side never imports MuJoCo); it must stay the URDF's.
    from coassist.robot.arm_mjcf import arm_joint_names
    from coassist.robot.ros2_world import UR_JOINT_NAMES

    assert UR_JOINT_NAMES == arm_joint_names("ur5")
