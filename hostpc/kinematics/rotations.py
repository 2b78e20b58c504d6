"""Rotations and homogeneous transforms, vectorised over any leading batch shape.

Conventions (``docs/conventions.md``): ``T_a_b`` maps coordinates in frame ``b`` to frame
``a``; roll-pitch-yaw is ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` stored ``[roll, pitch, yaw]``;
small rotations are rotation vectors (axis times angle). Angles in radians, lengths in metres.

Every function accepts arrays with arbitrary leading dimensions ``...`` and returns arrays
with the same leading dimensions.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.errors import InputError

__all__ = [
    "skew",
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_to_matrix",
    "matrix_to_rpy",
    "rotvec_to_matrix",
    "matrix_to_rotvec",
    "make_transform",
    "invert_transform",
    "pose_to_transform",
]

FloatArray = NDArray[np.float64]

# Below this angle (rad) the Rodrigues coefficients use their Taylor series.
_SMALL_ANGLE = 1e-4


def _as_trailing(value: ArrayLike, trailing: tuple[int, ...], name: str) -> FloatArray:
    """Convert to a float array and check its trailing shape; raise InputError naming it."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim < len(trailing) or arr.shape[arr.ndim - len(trailing) :] != trailing:
        want = "(..., " + ", ".join(str(s) for s in trailing) + ")"
        raise InputError(f"{name}: expected shape {want}, got {arr.shape}")
    return arr


def skew(v: ArrayLike) -> FloatArray:
    """Cross-product matrix: ``skew(v) @ x == cross(v, x)``.

    Args:
        v: vectors, shape ``(..., 3)``.

    Returns:
        Skew-symmetric matrices, shape ``(..., 3, 3)``.
    """
    v = _as_trailing(v, (3,), "v")
    out = np.zeros(v.shape[:-1] + (3, 3))
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out[..., 0, 1] = -z
    out[..., 0, 2] = y
    out[..., 1, 0] = z
    out[..., 1, 2] = -x
    out[..., 2, 0] = -y
    out[..., 2, 1] = x
    return out


def _axis_rotation(angle: ArrayLike, axis: int) -> FloatArray:
    """Rotation by ``angle`` (rad, shape ``(...)``) about coordinate axis 0, 1 or 2."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rot_x(angle: ArrayLike) -> FloatArray:
    """Rotation about x by ``angle`` (rad, shape ``(...)``) -> ``(..., 3, 3)``."""
    return _axis_rotation(angle, 0)


def rot_y(angle: ArrayLike) -> FloatArray:
    """Rotation about y by ``angle`` (rad, shape ``(...)``) -> ``(..., 3, 3)``."""
    return _axis_rotation(angle, 1)


def rot_z(angle: ArrayLike) -> FloatArray:
    """Rotation about z by ``angle`` (rad, shape ``(...)``) -> ``(..., 3, 3)``."""
    return _axis_rotation(angle, 2)


def rpy_to_matrix(rpy: ArrayLike) -> FloatArray:
    """Roll-pitch-yaw to rotation matrix, ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.

    Args:
        rpy: ``[roll, pitch, yaw]`` in rad, shape ``(..., 3)``.

    Returns:
        Rotation matrices, shape ``(..., 3, 3)``.
    """
    rpy = _as_trailing(rpy, (3,), "rpy")
    cr, cp, cy = np.cos(rpy[..., 0]), np.cos(rpy[..., 1]), np.cos(rpy[..., 2])
    sr, sp, sy = np.sin(rpy[..., 0]), np.sin(rpy[..., 1]), np.sin(rpy[..., 2])
    out = np.empty(rpy.shape[:-1] + (3, 3))
    out[..., 0, 0] = cy * cp
    out[..., 0, 1] = cy * sp * sr - sy * cr
    out[..., 0, 2] = cy * sp * cr + sy * sr
    out[..., 1, 0] = sy * cp
    out[..., 1, 1] = sy * sp * sr + cy * cr
    out[..., 1, 2] = sy * sp * cr - cy * sr
    out[..., 2, 0] = -sp
    out[..., 2, 1] = cp * sr
    out[..., 2, 2] = cp * cr
    return out


def matrix_to_rpy(R: ArrayLike) -> FloatArray:
    """Rotation matrix to ``[roll, pitch, yaw]`` (rad), inverse of :func:`rpy_to_matrix`.

    Pitch is in ``[-pi/2, pi/2]``, roll and yaw in ``(-pi, pi]``. At gimbal lock
    (``|pitch| = pi/2``) roll is set to 0 and the whole rotation about z goes to yaw.

    Args:
        R: rotation matrices, shape ``(..., 3, 3)``.

    Returns:
        ``[roll, pitch, yaw]``, shape ``(..., 3)``.
    """
    R = _as_trailing(R, (3, 3), "R")
    cos_pitch = np.hypot(R[..., 0, 0], R[..., 1, 0])
    pitch = np.arctan2(-R[..., 2, 0], cos_pitch)
    locked = cos_pitch < 1e-9
    roll = np.where(locked, 0.0, np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.where(
        locked,
        np.arctan2(-R[..., 0, 1], R[..., 1, 1]),
        np.arctan2(R[..., 1, 0], R[..., 0, 0]),
    )
    return np.stack([roll, pitch, yaw], axis=-1)


def rotvec_to_matrix(r: ArrayLike) -> FloatArray:
    """Rotation vector (axis times angle, rad) to rotation matrix (Rodrigues' formula).

    ``R = I + A K + B K^2`` with ``K = skew(r)``, ``A = sin(t)/t``, ``B = (1 - cos t)/t^2``
    (evaluated as ``2 sin^2(t/2)/t^2``), ``t = |r|``; ``A`` and ``B`` switch to their Taylor
    series for small ``t``, so the result is accurate (and smooth) down to ``r = 0``.

    Args:
        r: rotation vectors, shape ``(..., 3)``.

    Returns:
        Rotation matrices, shape ``(..., 3, 3)``.
    """
    r = _as_trailing(r, (3,), "r")
    theta2 = np.einsum("...i,...i->...", r, r)
    theta = np.sqrt(theta2)
    small = theta < _SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, np.sin(safe) / safe)
    # (1 - cos t) / t^2 = 2 sin^2(t/2) / t^2, without the cancellation of 1 - cos t.
    half_sinc = np.sin(0.5 * safe) / (0.5 * safe)
    b = np.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, 0.5 * half_sinc**2)
    K = skew(r)
    out = a[..., None, None] * K + b[..., None, None] * (K @ K)
    out[..., 0, 0] += 1.0
    out[..., 1, 1] += 1.0
    out[..., 2, 2] += 1.0
    return out


def _matrix_to_quaternion(R: FloatArray) -> FloatArray:
    """Unit quaternions ``[w, x, y, z]`` with ``w >= 0`` (Shepperd's method), ``(..., 4)``."""
    r00, r11, r22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    trace = r00 + r11 + r22
    # Pick, per matrix, the largest of 4w^2-1, 4x^2-1, 4y^2-1, 4z^2-1 to divide by.
    pivots = np.stack([trace, r00, r11, r22], axis=-1)
    choice = np.argmax(pivots, axis=-1)
    pivot = np.take_along_axis(pivots, choice[..., None], axis=-1)[..., 0]
    # 4w^2 = 1 + trace, 4x^2 = 1 + 2 r00 - trace, and so on: the chosen component.
    big = 0.5 * np.sqrt(np.maximum(1.0 + 2.0 * pivot - trace, 0.0))
    inv = 0.25 / big
    d21 = R[..., 2, 1] - R[..., 1, 2]
    d02 = R[..., 0, 2] - R[..., 2, 0]
    d10 = R[..., 1, 0] - R[..., 0, 1]
    s01 = R[..., 0, 1] + R[..., 1, 0]
    s02 = R[..., 0, 2] + R[..., 2, 0]
    s12 = R[..., 1, 2] + R[..., 2, 1]
    candidates = np.stack(
        [
            np.stack([big, d21 * inv, d02 * inv, d10 * inv], axis=-1),
            np.stack([d21 * inv, big, s01 * inv, s02 * inv], axis=-1),
            np.stack([d02 * inv, s01 * inv, big, s12 * inv], axis=-1),
            np.stack([d10 * inv, s02 * inv, s12 * inv, big], axis=-1),
        ],
        axis=-2,
    )
    quat = np.take_along_axis(candidates, choice[..., None, None], axis=-2)[..., 0, :]
    quat = np.where(quat[..., :1] < 0.0, -quat, quat)
    unit: FloatArray = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    return unit


def matrix_to_rotvec(R: ArrayLike) -> FloatArray:
    """Rotation matrix to rotation vector (axis times angle, angle in ``[0, pi]``).

    Goes through a unit quaternion (Shepperd's method), which is accurate near 0 and near
    ``pi``; at exactly ``pi`` the sign of the axis is arbitrary.

    Args:
        R: rotation matrices, shape ``(..., 3, 3)``.

    Returns:
        Rotation vectors in rad, shape ``(..., 3)``.
    """
    R = _as_trailing(R, (3, 3), "R")
    quat = _matrix_to_quaternion(R)
    w = quat[..., 0]
    v = quat[..., 1:]
    v_norm = np.linalg.norm(v, axis=-1)
    small = v_norm < 1e-8
    safe = np.where(small, 1.0, v_norm)
    # angle = 2 atan2(|v|, w); for small |v|, angle / |v| -> 2 / w (w ~ 1 there).
    scale = np.where(small, 2.0 / np.maximum(w, 0.5), 2.0 * np.arctan2(safe, w) / safe)
    return v * scale[..., None]


def make_transform(R: ArrayLike, t: ArrayLike) -> FloatArray:
    """Homogeneous transform ``[[R, t], [0, 1]]``.

    Args:
        R: rotations, shape ``(..., 3, 3)``.
        t: translations (m), shape ``(..., 3)``; leading dimensions broadcast with ``R``'s.

    Returns:
        Transforms, shape ``(..., 4, 4)``.
    """
    R = _as_trailing(R, (3, 3), "R")
    t = _as_trailing(t, (3,), "t")
    lead = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    out = np.zeros(lead + (4, 4))
    out[..., :3, :3] = R
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def invert_transform(T: ArrayLike) -> FloatArray:
    """Inverse of rigid transforms: ``T_b_a`` from ``T_a_b``, ``[[R^T, -R^T t], [0, 1]]``.

    Args:
        T: rigid transforms, shape ``(..., 4, 4)``.

    Returns:
        Inverse transforms, shape ``(..., 4, 4)``.
    """
    T = _as_trailing(T, (4, 4), "T")
    R_t = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros(T.shape)
    out[..., :3, :3] = R_t
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", R_t, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def pose_to_transform(xyz: ArrayLike, rpy: ArrayLike) -> FloatArray:
    """Transform from a position (m, ``(..., 3)``) and roll-pitch-yaw (rad, ``(..., 3)``).

    Returns:
        ``make_transform(rpy_to_matrix(rpy), xyz)``, shape ``(..., 4, 4)``.
    """
    xyz = _as_trailing(xyz, (3,), "xyz")
    return make_transform(rpy_to_matrix(rpy), xyz)
