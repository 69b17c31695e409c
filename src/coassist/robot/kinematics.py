"""Arm kinematics (the UR5 here; others in :mod:`coassist.robot.arms`): FK, the TCP Jacobian, IK.

Each control tick turns a Cartesian twist command of the tool centre point (TCP)
into joint velocities with thesis eq. 3.6,

    q̇ = J⁺(q) ẋ,

where ``J(q)`` is the 6 x 6 TCP Jacobian and ``J⁺`` its (damped) pseudo-inverse.
This module provides ``J(q)``, the forward kinematics and the damped inverse.

Frames
------
The model is the UR5 description shipped by the ``example-robot-data`` package
(``ur_description/urdf/ur5_robot.urdf``), evaluated with pinocchio. Everything
this module returns is expressed in the UR controller's **base** frame, the frame
of the teach pendant and of RTDE's ``getActualTCPPose`` (ROS ``ur_description``'s
``base`` link, which equals the base frame of UR's published DH table). The URDF
root link ``base_link`` is that frame rotated by π about z, so

    p_base = R_z(π) p_base_link,    R_z(π) = diag(-1, -1, 1).

Checked against UR's standard-DH forward kinematics: with this rotation the URDF
``tool0`` (the tool flange) coincides with the DH frame 6 at every joint vector
(position to ~1e-12 m, no constant rotation between them). At q = 0 the flange sits
at (a2 + a3, -(d4 + d6), d1 - d5) = (-0.817, -0.191, -0.005) m in the base frame.

TCP offset
----------
The TCP is ``tool0`` composed with a constant offset, given as the TCP pose in the
``tool0`` frame, ``[x, y, z, rx, ry, rz]`` (m, rotation vector in rad), the same
convention as the UR controller's TCP setting. The default ``(0, 0, 0, 0, 0, 0)``
puts the TCP on the flange.

Dependencies
------------
The rotation helpers and the pseudo-inverse are plain numpy. :class:`UR5Kinematics`
needs the ``robot`` extra (``pin`` and ``example-robot-data``), imported only when
an instance is built.
"""

from __future__ import annotations

import math
from importlib import metadata
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

# The pure math lives below the runtime, so the loop can use it without the robot extra;
# re-exported here because it is half of what a user of this module wants.
from coassist._checks import check_int, check_positive_scalar
from coassist.errors import CoassistError
from coassist.robot.arm_descriptions import ARMS
from coassist.spatial import (
    checked_rotation,
    checked_vector,
    damped_pseudo_inverse,
    joint_velocity,
    manipulability,
    orientation_error,
    rotation_matrix,
    rotation_vector,
)

__all__ = [
    "ArmKinematics",
    "IKConvergenceError",
    "UR5Kinematics",
    "damped_pseudo_inverse",
    "robot_data_path",
    "joint_velocity",
    "manipulability",
    "orientation_error",
    "rotation_matrix",
    "rotation_vector",
    "solve_ik",
    "ur5_urdf_path",
]

_INSTALL_HINT = "install the robot extra: pip install 'coassist[robot]'"
_ROBOTS_RELATIVE = Path("cmeel.prefix/share/example-robot-data/robots")
_URDF_SUFFIX = ("ur_description", "urdf", "ur5_robot.urdf")


_TCP_FRAME_NAME = "coassist_tcp"


# ----------------------------------------------------------------------------
# Locating the model
# ----------------------------------------------------------------------------


def ur5_urdf_path() -> Path:
    """Return the path of the UR5 URDF installed by ``example-robot-data``.

    The file is looked up in the installed distribution; nothing is downloaded.

    Returns
    -------
    path : pathlib.Path
        ``.../cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf``.

    Raises
    ------
    ImportError
        If ``example-robot-data`` is not installed.
    FileNotFoundError
        If the distribution is installed but holds no UR5 URDF.
    """
    return robot_data_path(_URDF_SUFFIX, "the UR5 model")


def robot_data_path(parts: tuple[str, ...], what: str) -> Path:
    """Path of ``robots/<parts...>`` in the installed ``example-robot-data`` (nothing downloaded).

    ``parts`` : the last path components, e.g. ``("panda_description", "urdf", "panda.urdf")``;
    ``what`` names the model in the errors (ImportError: the package is missing;
    FileNotFoundError: it holds no such file).
    """
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise ImportError(f"{what} needs the example-robot-data package; {_INSTALL_HINT}") from None
    path = Path(dist.locate_file(_ROBOTS_RELATIVE.joinpath(*parts)))
    if path.is_file():
        return path
    # Other layouts of the wheel: search its file list.
    n = len(parts)
    for entry in dist.files or ():
        if tuple(entry.parts[-n:]) == tuple(parts):
            candidate = Path(dist.locate_file(entry))
            if candidate.is_file():
                return candidate
    raise FileNotFoundError(
        f"example-robot-data {dist.version} is installed but holds no {'/'.join(parts)}; "
        f"reinstall it: pip install --force-reinstall 'coassist[robot]'"
    )


# ----------------------------------------------------------------------------
# Rotations (plain numpy)
# ----------------------------------------------------------------------------


def _import_pinocchio():
    try:
        import pinocchio
    except ImportError as exc:
        raise ImportError(f"arm kinematics need pinocchio (the 'pin' package); {_INSTALL_HINT}") from exc
    return pinocchio


def _check_tcp_offset(tcp_offset: ArrayLike) -> np.ndarray:
    try:
        arr = np.array(tcp_offset, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"tcp_offset must be 6 numbers [x, y, z, rx, ry, rz], got {tcp_offset!r}") from None
    if arr.shape != (6,):
        raise ValueError(f"tcp_offset must be 6 numbers [x, y, z, rx, ry, rz], got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"tcp_offset has non-finite entries: {arr.tolist()}")
    arr.setflags(write=False)
    return arr


class ArmKinematics:
    """Forward kinematics and TCP Jacobian of a serial arm, in its controller's base frame.

    The shared part of every arm (the UR5 here, the Panda in :mod:`coassist.robot.arms`):
    a pinocchio model of the URDF with the joints of ``locked`` fixed at 0 (a gripper's
    fingers), a TCP frame added at ``tcp_offset`` from ``tip_frame`` (the flange), and
    the results re-expressed in the base frame by the constant sign flips ``base_signs``
    (a rotation of the URDF root about z by 0 or π: (1, 1, 1) or (−1, −1, 1)).

    Parameters
    ----------
    urdf_path : the URDF file.
    tip_frame : the flange frame's name in it.
    n_joints : the arm's joints (checked against the model).
    tcp_offset : (6,) TCP pose in the flange frame, ``[x, y, z, rx, ry, rz]`` [m, rad].
    base_signs : (3,) the diagonal of the base rotation, each ±1.
    joint_velocity_limit : (n,) [rad/s].
    joint_position_limit : (n, 2) [rad]; None: the URDF's ``lower``/``upper``.
    locked : joint names fixed at 0.

    Notes
    -----
    One instance owns one pinocchio ``Data``; calls are not thread-safe. Every returned
    array is a fresh copy.
    """

    def __init__(
        self,
        urdf_path: Path,
        tip_frame: str,
        *,
        n_joints: int,
        tcp_offset: ArrayLike,
        base_signs: ArrayLike = (1.0, 1.0, 1.0),
        joint_velocity_limit: ArrayLike,
        joint_position_limit: ArrayLike | None = None,
        locked: tuple[str, ...] = (),
    ) -> None:
        self.tcp_offset = _check_tcp_offset(tcp_offset)
        pin = _import_pinocchio()
        self._pin = pin
        self.urdf_path = Path(urdf_path)
        self.n_joints = n = int(n_joints)
        model = pin.buildModelFromUrdf(str(self.urdf_path))
        if locked:
            ids = [model.getJointId(name) for name in locked]
            model = pin.buildReducedModel(model, ids, pin.neutral(model))
        if model.nq != n or model.nv != n:
            raise RuntimeError(f"{self.urdf_path} is not a {n}-joint arm (nq={model.nq}, nv={model.nv})")
        if not model.existFrame(tip_frame):
            raise RuntimeError(f"{self.urdf_path} has no frame {tip_frame!r}")
        tip = model.getFrameId(tip_frame)
        tool_frame = model.frames[tip]
        offset = pin.SE3(rotation_matrix(self.tcp_offset[3:]), self.tcp_offset[:3].copy())
        placement = tool_frame.placement * offset
        self._frame_id = model.addFrame(
            pin.Frame(_TCP_FRAME_NAME, tool_frame.parentJoint, tip, placement, pin.FrameType.OP_FRAME)
        )
        self._model = model
        self._data = model.createData()
        self._reference = pin.LOCAL_WORLD_ALIGNED
        self._compute_jacobian = pin.computeFrameJacobian
        self._frames_fk = pin.framesForwardKinematics
        signs = np.array(base_signs, dtype=float)
        self._sign3 = signs
        self._sign3_col = signs[:, None].copy()
        self._sign6_col = np.concatenate((signs, signs))[:, None].copy()

        vel = np.array(joint_velocity_limit, dtype=float)
        vel.setflags(write=False)
        self.joint_velocity_limit = vel
        if joint_position_limit is None:
            pos = np.stack((model.lowerPositionLimit, model.upperPositionLimit), axis=1).astype(float)
        else:
            pos = np.array(joint_position_limit, dtype=float)
        pos.setflags(write=False)
        self.joint_position_limit = pos

    def _as_q(self, q: ArrayLike) -> np.ndarray:
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape != (self.n_joints,):
            raise ValueError(f"q must have shape ({self.n_joints},), got {arr.shape}")
        if not np.isfinite(arr).all():
            raise ValueError("q has non-finite entries")
        return arr

    def forward(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """TCP position and orientation in the base frame.

        Parameters
        ----------
        q : array_like, shape (n,)
            Joint positions, rad.

        Returns
        -------
        position : ndarray, shape (3,)
            TCP position, m.
        rotation : ndarray, shape (3, 3)
            TCP rotation matrix (columns: TCP axes in the base frame).
        """
        q = self._as_q(q)
        self._frames_fk(self._model, self._data, q)
        M = self._data.oMf[self._frame_id]
        return M.translation * self._sign3, M.rotation * self._sign3_col

    def pose(self, q: ArrayLike) -> np.ndarray:
        """TCP pose ``[x, y, z, rx, ry, rz]`` in the base frame (m, rotation vector rad).

        Parameters
        ----------
        q : array_like, shape (n,)
            Joint positions, rad.

        Returns
        -------
        pose : ndarray, shape (6,)
            Same convention as the UR controller's ``getActualTCPPose``.
        """
        p, R = self.forward(q)
        return np.concatenate((p, rotation_vector(R)))

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """TCP Jacobian, world-aligned, in the base frame.

        ``[v; ω] = J(q) q̇`` where ``v`` is the velocity of the TCP point and ``ω``
        the angular velocity of the tool, both in base-frame coordinates
        (pinocchio's ``LOCAL_WORLD_ALIGNED`` re-expressed in the base frame).

        Parameters
        ----------
        q : array_like, shape (n,)
            Joint positions, rad.

        Returns
        -------
        J : ndarray, shape (6, n)
            Rows ``[v (m/s); ω (rad/s)]`` per rad/s of each joint.
        """
        q = self._as_q(q)
        J = self._compute_jacobian(self._model, self._data, q, self._frame_id, self._reference)
        return J * self._sign6_col

    def forward_and_jacobian(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`forward` and :meth:`jacobian` in one pinocchio pass (one per tick).

        Parameters
        ----------
        q : array_like, shape (n,)
            Joint positions, rad.

        Returns
        -------
        position : ndarray, shape (3,)
            TCP position in the base frame, m.
        rotation : ndarray, shape (3, 3)
            TCP rotation matrix in the base frame.
        J : ndarray, shape (6, n)
            World-aligned TCP Jacobian in the base frame, see :meth:`jacobian`.
        """
        q = self._as_q(q)
        # computeFrameJacobian runs the forward pass and updates data.oMf[frame_id].
        J = self._compute_jacobian(self._model, self._data, q, self._frame_id, self._reference)
        M = self._data.oMf[self._frame_id]
        return M.translation * self._sign3, M.rotation * self._sign3_col, J * self._sign6_col


class UR5Kinematics(ArmKinematics):
    """Forward kinematics and TCP Jacobian of the UR5, in the UR base frame.

    Parameters
    ----------
    tcp_offset : array_like, shape (6,), optional
        TCP pose in the ``tool0`` (flange) frame, ``[x, y, z, rx, ry, rz]`` in m and
        rad (rotation vector). Default: the flange itself.

    Attributes
    ----------
    n_joints : int
        6.
    joint_velocity_limit : ndarray, shape (6,)
        π rad/s for every joint (UR5 datasheet, 180°/s).
    joint_position_limit : ndarray, shape (6, 2)
        ``[lower, upper]`` = ±2π rad for every joint.
    tcp_offset : ndarray, shape (6,)
        The offset given to the constructor.
    urdf_path : pathlib.Path
        The URDF the model was built from.
    """

    n_joints = 6

    def __init__(self, tcp_offset: ArrayLike = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)) -> None:
        arm = ARMS["ur5"]
        super().__init__(
            ur5_urdf_path(),
            arm.tip_frame,
            n_joints=6,
            tcp_offset=tcp_offset,
            base_signs=arm.base_signs,
            joint_velocity_limit=arm.joint_velocity_limit,
            joint_position_limit=arm.joint_position_limit,
        )

    def __repr__(self) -> str:
        return f"UR5Kinematics(tcp_offset={self.tcp_offset.tolist()})"


# ----------------------------------------------------------------------------
# Inverse kinematics
# ----------------------------------------------------------------------------


class IKConvergenceError(CoassistError, RuntimeError):
    """:func:`solve_ik` did not reach the requested tolerance."""


def solve_ik(
    kin: ArmKinematics,
    position: ArrayLike,
    rotation: ArrayLike | None,
    q0: ArrayLike,
    *,
    tol_position: float = 1e-8,
    tol_rotation: float = 1e-8,
    max_iterations: int = 200,
    max_step: float = 0.5,
    sigma_threshold: float = 0.05,
    max_damping: float = 0.05,
) -> np.ndarray:
    """Damped Newton inverse kinematics for a TCP pose in the base frame.

    Iterates ``q ← q + J⁺(q) e`` with ``e = [p_d - p(q); log(R_d R(q)ᵀ)]`` and the
    damped pseudo-inverse of :func:`damped_pseudo_inverse`, the step scaled down to
    at most ``max_step`` rad (infinity norm) and ``q`` clipped to the joint limits.
    Converges to the solution in the branch (shoulder/elbow/wrist) of ``q0``.

    Parameters
    ----------
    kin : UR5Kinematics
        The model (its TCP offset applies).
    position : array_like, shape (3,)
        Desired TCP position, m.
    rotation : array_like, shape (3, 3), or None
        Desired TCP rotation matrix; ``None`` solves for the position only
        (3 rows of the Jacobian, orientation free).
    q0 : array_like, shape (6,)
        Initial guess, rad.
    tol_position : float, optional
        Position tolerance, m. Default 1e-8.
    tol_rotation : float, optional
        Orientation tolerance (rotation-vector norm), rad. Default 1e-8.
    max_iterations : int, optional
        Default 200.
    max_step : float, optional
        Largest joint step per iteration, rad. Default 0.5.
    sigma_threshold, max_damping : float, optional
        Damping options, see :func:`damped_pseudo_inverse`.

    Returns
    -------
    q : ndarray, shape (6,)
        Joint positions, rad.

    Raises
    ------
    IKConvergenceError
        If the tolerances are not met within ``max_iterations`` (unreachable pose,
        singular target or a poor ``q0``); the message gives the residuals.
    """
    p_d = checked_vector(position, "position", 3)
    R_d = None if rotation is None else checked_rotation(rotation, "rotation")
    q = kin._as_q(q0).copy()
    tol_position = check_positive_scalar(tol_position, "tol_position")
    tol_rotation = check_positive_scalar(tol_rotation, "tol_rotation")
    max_step = check_positive_scalar(max_step, "max_step")
    max_iterations = check_int(max_iterations, "max_iterations", 1)
    lower, upper = kin.joint_position_limit[:, 0], kin.joint_position_limit[:, 1]
    err_p = err_r = math.inf
    for _ in range(int(max_iterations)):
        p, R, J = kin.forward_and_jacobian(q)
        e_p = p_d - p
        err_p = float(np.linalg.norm(e_p))
        if R_d is None:
            err_r = 0.0
            e, J_task = e_p, J[:3]
        else:
            e_r = orientation_error(R_d, R)
            err_r = float(np.linalg.norm(e_r))
            e, J_task = np.concatenate((e_p, e_r)), J
        if err_p <= tol_position and err_r <= tol_rotation:
            return q
        J_pinv, _ = damped_pseudo_inverse(J_task, sigma_threshold=sigma_threshold, max_damping=max_damping)
        dq = J_pinv @ e
        peak = float(np.max(np.abs(dq)))
        if peak > max_step:
            dq *= max_step / peak
        q = np.clip(q + dq, lower, upper)
    raise IKConvergenceError(
        f"solve_ik did not converge in {max_iterations} iterations: position error {err_p:.3g} m "
        f"(tol {tol_position:g}), orientation error {err_r:.3g} rad (tol {tol_rotation:g}); "
        "the pose may be unreachable or singular, or q0 too far from a solution"
    )
