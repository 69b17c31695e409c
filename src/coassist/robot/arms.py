"""The arm registry: one :class:`ArmDescription` per arm family, and 7-DOF redundancy.

What differs between arms is data: where the URDF is (``example-robot-data``), the
flange frame, the joints to lock (a gripper's fingers), the base frame of the arm's
controller relative to the URDF root, the joint speed limits and a home pose
(:mod:`coassist.robot.arm_descriptions`, whose names are importable from here). Everything
else — forward kinematics, the TCP Jacobian, the limits, the start-up check that the
model and the robot agree — is shared (:class:`coassist.robot.kinematics.ArmKinematics`,
:func:`check_model_matches`), so a third arm costs one entry in :data:`ARMS`.

Redundancy (n > 6 joints). Eq. 3.6 gives the joint velocity of the task twist ẋ; on a
7-DOF arm a one-dimensional null space is left, used to hold the posture the run started
in (:class:`NullSpacePosture`)::

    q̇ = J⁺ ẋ + (I − V Vᵀ) k_n (q₀ − q)          J⁺ = Jᵀ (J Jᵀ + λ² I)⁻¹

with λ the damping of :func:`coassist.spatial.damped_pseudo_inverse` (0 away from a
singularity, so J q̇ = ẋ exactly) and V (n, 6) the right singular vectors of J: I − V Vᵀ
is the exact projector onto J's null space (= I − J⁺J when λ = 0), so the posture term
never moves the tool, near a singularity either. Joint
position limits: the command is then scaled uniformly (its direction, hence the tool's
direction of motion, kept) so that no joint gets closer than ``limit_margin`` to a limit
within ``limit_horizon`` seconds: |q̇_i| τ ≤ max(distance to the limit − margin, 0) for
each joint moving toward its limit.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_positive_scalar
from coassist.robot.arm_descriptions import ARMS, ArmDescription, get_arm  # the registry's data, re-exported
from coassist.robot.kinematics import ArmKinematics, robot_data_path
from coassist.spatial import damped_svd

__all__ = ["ARMS", "ArmDescription", "NullSpacePosture", "arm_kinematics", "check_model_matches", "get_arm"]


def arm_kinematics(name: str, tcp_offset: ArrayLike = (0.0,) * 6) -> ArmKinematics:
    """:class:`ArmKinematics` of the registered arm ``name`` with the TCP at ``tcp_offset`` (flange frame)."""
    arm = get_arm(name)
    return ArmKinematics(
        robot_data_path(arm.urdf, f"the {arm.name} model"),
        arm.tip_frame,
        n_joints=arm.n_joints,
        tcp_offset=tcp_offset,
        base_signs=arm.base_signs,
        joint_velocity_limit=arm.joint_velocity_limit,
        joint_position_limit=arm.joint_position_limit,
        locked=arm.locked,
    )


def check_model_matches(
    kin: ArmKinematics,
    q: ArrayLike,
    reported_pose: ArrayLike,
    *,
    tol_position: float = 1e-3,
    tol_rotation: float = 1e-2,
    what: str = "the robot",
) -> None:
    """Start-up check: the model's TCP pose at ``q`` equals the one ``what`` reports.

    ``reported_pose`` : (6,) ``[x, y, z, rx, ry, rz]`` [m, rad] in the base frame.
    Raises ValueError with both poses when the position differs by more than
    ``tol_position`` [m] or the orientation by more than ``tol_rotation`` [rad]: the TCP
    offset, the base frame or the arm model is wrong, and eq. 3.6 would move the tool
    the wrong way.
    """
    from coassist.spatial import orientation_error, rotation_matrix

    p, R = kin.forward(q)
    reported = np.asarray(reported_pose, dtype=float)
    dp = float(np.linalg.norm(p - reported[:3]))
    dr = float(np.linalg.norm(orientation_error(rotation_matrix(reported[3:6]), R)))
    if dp > tol_position or dr > tol_rotation:
        raise ValueError(
            f"the arm model does not match {what}: at q = {np.round(np.asarray(q, float), 4).tolist()} the model puts "
            f"the TCP at {np.round(p, 4).tolist()} but {what} reports {np.round(reported[:3], 4).tolist()} "
            f"({dp * 1000:.1f} mm, {dr:.3f} rad apart); check the robot model (--robot), the TCP/end-effector "
            "setting and the base frame"
        )


class NullSpacePosture:
    """Eq. 3.6 on a redundant arm with the posture held in the null space (module docstring).

    Wraps an :class:`ArmKinematics` (``n_joints``, ``forward_and_jacobian`` delegate to
    it) and adds :meth:`redundant_joint_velocity`, which the control tick calls instead
    of the square solve when it exists.

    kinematics : the arm.  posture : (n,) q₀, the posture to hold [rad] (the start).
    gain : k_n [1/s].  limit_margin : [rad] kept from each joint limit.
    limit_horizon : τ [s].  sigma_threshold, max_damping : the damping rule.
    """

    def __init__(
        self,
        kinematics: ArmKinematics,
        posture: ArrayLike,
        *,
        gain: float = 1.0,
        limit_margin: float = 0.05,
        limit_horizon: float = 0.1,
        sigma_threshold: float = 0.05,
        max_damping: float = 0.05,
    ) -> None:
        self.kinematics = kinematics
        self.n_joints = kinematics.n_joints
        self.posture = kinematics._as_q(posture).copy()
        self.gain = check_positive_scalar(gain, "NullSpacePosture.gain")
        self.limit_margin = check_positive_scalar(limit_margin, "NullSpacePosture.limit_margin")
        self.limit_horizon = check_positive_scalar(limit_horizon, "NullSpacePosture.limit_horizon")
        self.sigma_threshold = check_positive_scalar(sigma_threshold, "NullSpacePosture.sigma_threshold")
        self.max_damping = check_positive_scalar(max_damping, "NullSpacePosture.max_damping")
        lim = kinematics.joint_position_limit
        self._lower = lim[:, 0] + self.limit_margin
        self._upper = lim[:, 1] - self.limit_margin
        self.joint_position_limit = lim

    def forward_and_jacobian(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The wrapped kinematics' (p (3,), R (3, 3), J (6, n))."""
        return self.kinematics.forward_and_jacobian(q)

    def forward(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The wrapped kinematics' (p (3,), R (3, 3))."""
        return self.kinematics.forward(q)

    def redundant_joint_velocity(self, q: np.ndarray, J: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """(n,) q̇ [rad/s] for the task twist (6,) at q (n,) with J (6, n): posture and limits (module docstring)."""
        # One SVD per tick serves both: the damped J⁺ (spatial.damped_pseudo_inverse's rule) and
        # the null-space projector from the exact row space of J (its right singular vectors),
        # not I − J⁺J with the damped J⁺: near a singularity that one is no projector and leaks
        # the posture pull into the tool's motion (J (I − J⁺J) ≠ 0 once λ > 0).
        U, inv_s, row, _ = damped_svd(J, self.sigma_threshold, self.max_damping)
        qd = row.T @ (inv_s * (U.T @ twist))
        pull = self.gain * (self.posture - q)
        qd += pull - row.T @ (row @ pull)
        return self.limit_to_joint_range(q, qd)

    def limit_to_joint_range(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """qd scaled by the largest s ∈ [0, 1] with |s q̇_i| τ ≤ max(room_i, 0) toward each limit."""
        room = np.where(qd > 0.0, self._upper - q, q - self._lower)
        travel = np.abs(qd) * self.limit_horizon
        moving = travel > 0.0
        if not moving.any():
            return qd
        s = float(np.min(np.maximum(room[moving], 0.0) / travel[moving], initial=1.0))
        return qd * min(1.0, s)
