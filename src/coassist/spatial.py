"""Rigid-body math the loop and the robot share: rotations, orientation errors, eq. 3.6's inverse.

Pure numpy, no robot model (``coassist.robot.kinematics`` adds the UR5's forward
kinematics and Jacobian on top). Conventions: a rotation vector rv = axis · angle [rad]
(angle in [0, π]); R = exp([rv]×) (Rodrigues); twists are [v; ω] in the base frame.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_positive_scalar

__all__ = [
    "damped_pseudo_inverse",
    "dls_joint_velocity",
    "joint_velocity",
    "continuous_rotation_vector",
    "manipulability",
    "orientation_error",
    "quaternion_from_rotation_vector",
    "rotation_matrix",
    "rotation_matrix_of",
    "rotation_vector",
    "rotation_vector_from_quaternion",
    "unwrap_rotation_vectors",
]


def checked_rotation(R: ArrayLike, name: str) -> np.ndarray:
    """``R`` as a finite (3, 3) float array; ValueError naming ``name`` otherwise."""
    arr = np.asarray(R, dtype=float)
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 rotation matrix, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} has non-finite entries")
    return arr


def checked_vector(v: ArrayLike, name: str, n: int) -> np.ndarray:
    """``v`` as a finite (n,) float array; ValueError naming ``name`` otherwise."""
    arr = np.asarray(v, dtype=float)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} has non-finite entries")
    return arr


def rotation_vector(R: ArrayLike) -> np.ndarray:
    """Rotation vector (axis times angle) of a rotation matrix, the SO(3) logarithm.

    Goes through the unit quaternion (Shepperd's method), ``rv = 2 atan2(|v|, w) v/|v|``,
    which is accurate for all angles, including near 0 and near π.

    Parameters
    ----------
    R : array_like, shape (3, 3)
        Rotation matrix.

    Returns
    -------
    rv : ndarray, shape (3,)
        Rotation vector in rad, with angle ``|rv|`` in [0, π].
    """
    return rotation_vector_unchecked(checked_rotation(R, "R"))


def rotation_vector_unchecked(R: np.ndarray) -> np.ndarray:
    """:func:`rotation_vector` without input checks, for the control tick (R a (3, 3) float array)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    tr = r00 + r11 + r22
    # Shepperd: take the square root of the largest of 4w², 4x², 4y², 4z².
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * math.sqrt(max(1.0 + tr, 0.0))
        w = 0.25 * s
        x = (r21 - r12) / s
        y = (r02 - r20) / s
        z = (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r00 - r11 - r22, 0.0))
        w = (r21 - r12) / s
        x = 0.25 * s
        y = (r01 + r10) / s
        z = (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(max(1.0 - r00 + r11 - r22, 0.0))
        w = (r02 - r20) / s
        x = (r01 + r10) / s
        y = 0.25 * s
        z = (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 - r00 - r11 + r22, 0.0))
        w = (r10 - r01) / s
        x = (r02 + r20) / s
        y = (r12 + r21) / s
        z = 0.25 * s
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    vn = math.sqrt(x * x + y * y + z * z)
    if vn < 1e-8:
        # angle = 2 atan2(vn, w) ≈ 2 vn / w (1 - vn²/(3 w²)); scale = angle / vn.
        scale = 2.0 / w * (1.0 - vn * vn / (3.0 * w * w))
    else:
        scale = 2.0 * math.atan2(vn, w) / vn
    return np.array([x * scale, y * scale, z * scale])


def rotation_matrix(rv: ArrayLike) -> np.ndarray:
    """Rotation matrix of a rotation vector, the SO(3) exponential (Rodrigues' formula).

    ``R = I + (sin θ / θ) [r]ₓ + ((1 - cos θ) / θ²) [r]ₓ²`` with ``θ = |r|``, the
    coefficients taken from their Taylor series for small θ.

    Parameters
    ----------
    rv : array_like, shape (3,)
        Rotation vector (axis times angle), rad.

    Returns
    -------
    R : ndarray, shape (3, 3)
        Rotation matrix.
    """
    x, y, z = checked_vector(rv, "rv", 3).tolist()
    return rotation_matrix_of(x, y, z)


def rotation_matrix_of(x: float, y: float, z: float) -> np.ndarray:
    """:func:`rotation_matrix` of the rotation vector (x, y, z), finite floats, unchecked (the control tick's: its
    pose is checked finite already)."""
    t2 = x * x + y * y + z * z
    if t2 < 1e-8:
        a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
    else:
        t = math.sqrt(t2)
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / t2
    # I + a [r]x + b [r]x², with [r]x² = r rᵀ - θ² I.
    c = 1.0 - b * t2
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    ax, ay, az = a * x, a * y, a * z
    return np.array(
        [
            [c + b * x * x, bxy - az, bxz + ay],
            [bxy + az, c + b * y * y, byz - ax],
            [bxz - ay, byz + ax, c + b * z * z],
        ]
    )


def orientation_error(R_desired: ArrayLike, R_actual: ArrayLike) -> np.ndarray:
    """Orientation error ``e = log(R_d R_aᵀ)`` as a rotation vector in the base frame.

    ``e`` is the rotation that takes the actual orientation to the desired one,
    expressed in the base frame, so an angular velocity ``ω = K_R e`` (P-control)
    turns the tool towards ``R_d``.

    Parameters
    ----------
    R_desired, R_actual : array_like, shape (3, 3)
        Desired and actual rotation matrices (tool in base frame).

    Returns
    -------
    e : ndarray, shape (3,)
        Rotation vector in rad, ``|e|`` in [0, π].
    """
    Rd = checked_rotation(R_desired, "R_desired")
    Ra = checked_rotation(R_actual, "R_actual")
    return rotation_vector(Rd @ Ra.T)


def continuous_rotation_vector(rv: ArrayLike, previous: ArrayLike) -> np.ndarray:
    """The rotation vector of the same rotation as ``rv`` nearest to ``previous``.

    A rotation by θ about the unit axis n is also (θ + 2πk)·n for every integer k.
    :func:`rotation_vector` returns the one with |rv| ≤ π, which jumps from ≈ +π·n to
    ≈ −π·n when a rotation crosses π (a UR tool pointing down sits at |rv| ≈ π). Like
    ``numpy.unwrap`` for angles, this picks the k that keeps a sequence continuous::

        n = rv/|rv|,   k = round((n·previous − |rv|) / 2π),   rv' = (|rv| + 2πk)·n

    (k minimises ||(|rv| + 2πk)·n − previous||). ``rv`` unchanged when |rv| = 0 or either
    input is not finite.

    Parameters
    ----------
    rv, previous : array_like, shape (3,)
        This sample's rotation vector and the previous (already continuous) one, in rad.

    Returns
    -------
    ndarray, shape (3,)
        The continuous rotation vector, in rad (its norm may exceed π).
    """
    r = np.asarray(rv, dtype=float)
    if r.shape != (3,):
        raise ValueError(f"rv must have shape (3,), got {r.shape}")
    p = np.asarray(previous, dtype=float).reshape(-1)
    theta = float(np.linalg.norm(r))
    if theta == 0.0 or p.shape != (3,) or not (np.isfinite(r).all() and np.isfinite(p).all()):
        return r.copy()
    n = r / theta
    k = round((float(n @ p) - theta) / (2.0 * math.pi))
    return (theta + 2.0 * math.pi * k) * n


def unwrap_rotation_vectors(rvs: ArrayLike, start: ArrayLike) -> np.ndarray:
    """A sequence of rotation vectors (n, 3) made continuous from ``start`` (3,), row by row
    with :func:`continuous_rotation_vector` (a row that is not finite is kept and skipped)."""
    a = np.array(rvs, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"rvs must have shape (n, 3), got {a.shape}")
    prev = np.asarray(start, dtype=float)
    for i in range(a.shape[0]):
        a[i] = continuous_rotation_vector(a[i], prev)
        if np.isfinite(a[i]).all():
            prev = a[i]
    return a


# ----------------------------------------------------------------------------
# Jacobian tools (plain numpy)
# ----------------------------------------------------------------------------


def _as_jacobian(J: ArrayLike) -> np.ndarray:
    arr = np.asarray(J, dtype=float)
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"J must be a non-empty 2-D matrix, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError("J has non-finite entries")
    return arr


def manipulability(J: ArrayLike) -> float:
    """Yoshikawa's manipulability measure ``w = sqrt(det(J Jᵀ))``.

    Computed as the product of the singular values of ``J`` (equal to the
    determinant form for ``m <= n`` and better conditioned: it stays at roundoff
    level, not its square root, at a singularity). Zero for ``m > n``.

    Parameters
    ----------
    J : array_like, shape (m, n)
        Jacobian.

    Returns
    -------
    w : float
        Manipulability (units of the product of the rows' units).
    """
    J = _as_jacobian(J)
    if J.shape[0] > J.shape[1]:
        return 0.0
    return float(np.prod(np.linalg.svd(J, compute_uv=False)))


def damped_pseudo_inverse(
    J: ArrayLike, *, sigma_threshold: float = 0.05, max_damping: float = 0.05
) -> tuple[np.ndarray, float]:
    """Damped least-squares (DLS) pseudo-inverse with singular-value-based damping.

    ``J⁺ = Jᵀ (J Jᵀ + λ² I)⁻¹ = V diag(σᵢ / (σᵢ² + λ²)) Uᵀ`` with the damping
    (Nakamura & Hanafusa 1986; Maciejewski & Klein 1988)

        λ² = 0                                               if σ_min >= sigma_threshold,
        λ² = max_damping² (1 - (σ_min / sigma_threshold)²)   otherwise,

    where ``σ_min`` is the smallest of the ``min(m, n)`` singular values of ``J``.
    It is evaluated through the SVD ``J = U diag(σ) Vᵀ``, which also covers
    ``m > n`` with ``λ = 0`` (then ``J Jᵀ`` is singular and the result is the left
    inverse ``(JᵀJ)⁻¹Jᵀ``).
    ``λ`` is continuous in ``σ_min`` (zero at the threshold, ``max_damping`` at a
    singularity).

    Norm bound: with ``λ = 0`` the result is the exact Moore-Penrose pseudo-inverse,
    ``‖J⁺‖₂ = 1/σ_min <= 1/sigma_threshold``; with ``λ > 0``,
    ``‖J⁺‖₂ = max σᵢ / (σᵢ² + λ²) <= min(1/σ_min, 1/(2λ))``, so a commanded twist
    never produces a joint velocity larger than ``|ẋ| / (2λ)``.

    Parameters
    ----------
    J : array_like, shape (m, n)
        Jacobian.
    sigma_threshold : float, optional
        Singular value below which damping starts (> 0). Default 0.05.
    max_damping : float, optional
        Damping ``λ`` at an exact singularity (> 0). Default 0.05.

    Returns
    -------
    J_pinv : ndarray, shape (n, m)
        Damped pseudo-inverse.
    damping : float
        The ``λ`` used (0 when undamped).
    """
    U, inv_s, Vt, lam = damped_svd(_as_jacobian(J), sigma_threshold, max_damping)
    return (Vt.T * inv_s) @ U.T, lam


def damped_svd(
    J: np.ndarray, sigma_threshold: float, max_damping: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``J⁺ = Vt.T diag(inv_s) U.T``: the factors of the damped inverse, and λ."""
    sigma_threshold = check_positive_scalar(sigma_threshold, "sigma_threshold")
    max_damping = check_positive_scalar(max_damping, "max_damping")
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    sigma_min = float(s[-1])
    if sigma_min >= sigma_threshold:
        return U, 1.0 / s, Vt, 0.0
    ratio = sigma_min / sigma_threshold
    lam = max_damping * math.sqrt(1.0 - ratio * ratio)
    return U, s / (s * s + lam * lam), Vt, lam


def dls_joint_velocity(
    J: np.ndarray, twist: np.ndarray, sigma_threshold: float = 0.05, max_damping: float = 0.05
) -> tuple[np.ndarray, float]:
    """Eq. 3.6 with the damping rule of :func:`damped_pseudo_inverse`, for a square J, fast.

    q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ ẋ, with σ_min² the smallest eigenvalue of J Jᵀ; when
    λ = 0 this is J⁻¹ ẋ, solved directly (no SVD). Equal to
    ``damped_pseudo_inverse(J)[0] @ twist`` (tested); for the control tick, which has
    checked its inputs (J (n, n), twist (n,), finite).
    """
    JJt = J @ J.T
    sigma_min = math.sqrt(max(float(np.linalg.eigvalsh(JJt)[0]), 0.0))
    if sigma_min >= sigma_threshold:
        return np.linalg.solve(J, twist), 0.0
    ratio = sigma_min / sigma_threshold
    lam = max_damping * math.sqrt(1.0 - ratio * ratio)
    JJt[np.diag_indices_from(JJt)] += lam * lam
    return J.T @ np.linalg.solve(JJt, twist), lam


def joint_velocity(
    J: ArrayLike, twist: ArrayLike, *, sigma_threshold: float = 0.05, max_damping: float = 0.05
) -> np.ndarray:
    """Joint velocities of a Cartesian twist, thesis eq. 3.6: ``q̇ = J⁺(q) ẋ``.

    ``J⁺`` is the damped pseudo-inverse of :func:`damped_pseudo_inverse`, so
    ``|q̇| <= |ẋ| / (2λ)`` near singularities.

    Parameters
    ----------
    J : array_like, shape (m, n)
        Jacobian, e.g. :meth:`UR5Kinematics.jacobian` (m = n = 6).
    twist : array_like, shape (m,)
        Twist command ``ẋ``; for the UR5 ``[v; ω]`` of the TCP in the base frame,
        m/s and rad/s.
    sigma_threshold, max_damping : float, optional
        Damping options, see :func:`damped_pseudo_inverse`.

    Returns
    -------
    qdot : ndarray, shape (n,)
        Joint velocities, rad/s for the UR5.
    """
    J = _as_jacobian(J)
    twist = checked_vector(twist, "twist", J.shape[0])
    U, inv_s, Vt, _ = damped_svd(J, sigma_threshold, max_damping)
    return Vt.T @ (inv_s * (U.T @ twist))


# ----------------------------------------------------------------------------
# The UR5 model
# ----------------------------------------------------------------------------


def quaternion_from_rotation_vector(rv: ArrayLike) -> np.ndarray:
    """Unit quaternion ``[x, y, z, w]`` (ROS order) of a rotation vector, ``w >= 0`` for ``|rv| <= π``.

    ``q = [sin(θ/2) r/θ, cos(θ/2)]`` with ``θ = |r|``; ``sin(θ/2)/θ`` from its Taylor
    series ``1/2 − θ²/48`` for small θ. Inverse: :func:`rotation_vector_from_quaternion`.
    """
    x, y, z = checked_vector(rv, "rv", 3).tolist()
    t2 = x * x + y * y + z * z
    if t2 < 1e-8:
        s, w = 0.5 - t2 / 48.0, 1.0 - t2 / 8.0
    else:
        t = math.sqrt(t2)
        s, w = math.sin(0.5 * t) / t, math.cos(0.5 * t)
    return np.array([s * x, s * y, s * z, w])


def rotation_vector_from_quaternion(q: ArrayLike) -> np.ndarray:
    """Rotation vector of a quaternion ``[x, y, z, w]`` (normalised here), angle in [0, π]."""
    x, y, z, w = checked_vector(q, "q", 4).tolist()
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n == 0.0:
        raise ValueError("q must not be zero")
    x, y, z, w = x / n, y / n, z / n, w / n
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    vn = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 / w * (1.0 - vn * vn / (3.0 * w * w)) if vn < 1e-8 else 2.0 * math.atan2(vn, w) / vn
    return np.array([x * scale, y * scale, z * scale])
