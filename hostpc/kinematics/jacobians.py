"""Instantaneous flange motions per kinematic parameter, and the Jacobians built from them.

For each of the ``5n`` kinematic parameters (``theta, d, a, alpha, beta`` of every joint,
``docs/conventions.md``) a unit increase moves everything outboard of that factor of the
joint transform rigidly, in base coordinates:

DH row ``i``, ``Rz(t) Tz(d) Tx(a) Rx(al) Ry(b)``:

- ``theta_i``: rotation about ``z_{i-1}`` through ``o_{i-1}``
- ``d_i``: translation along ``z_{i-1}``
- ``a_i``: translation along ``x' = cos(b) x_i + sin(b) z_i``
- ``alpha_i``: rotation about ``x'`` through ``o_i``
- ``beta_i``: rotation about ``y_i`` through ``o_i``

MDH row ``i``, ``Rx(al) Ry(b) Tx(a) Rz(t) Tz(d)``:

- ``theta_i``: rotation about ``z_i`` through ``o_i``
- ``d_i``: translation along ``z_i``
- ``a_i``: translation along ``cos(t) x_i - sin(t) y_i``
- ``alpha_i``: rotation about ``x_{i-1}`` through ``o_{i-1}``
- ``beta_i``: rotation about ``cos(al) y_{i-1} + sin(al) z_{i-1}`` through ``o_{i-1}``

For a prismatic joint the ``theta`` slot is its joint variable (a translation along the
joint axis) and the ``d`` slot its fixed rotation about that axis: the two screws swap.
A chain's base mount is already in the link frames; its flange mount moves nothing.

``x_i, y_i, z_i, o_i`` are the axes and origin of link frame ``i`` in base; ``t, al, b`` the
effective row angles. ``x'`` (DH) is link ``i``'s x axis before the Hayati ``Ry(b)``; the MDH
``a`` direction is link ``i``'s x axis before ``Rz(t)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.poses import ChainPoses

__all__ = ["KinematicScrews", "joint_axes", "joint_screws", "screws", "point_jacobian",
           "rotation_jacobian"]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class KinematicScrews:
    """Flange motion per unit increase of each kinematic parameter, in base coordinates.

    Attributes:
        axis: shape ``(N, 5n, 3)``; unit angular velocity (rotations) or unit linear
            velocity (translations), base coordinates.
        point: shape ``(N, 5n, 3)``; a point on the rotation axis in base (m); 0 for
            translations.
        is_rotation: shape ``(5n,)``; True for ``theta``, ``alpha``, ``beta`` entries.
    """

    axis: FloatArray
    point: FloatArray
    is_rotation: BoolArray


def joint_axes(poses: ChainPoses) -> tuple[FloatArray, FloatArray]:
    """Axis and a point of every joint in base coordinates.

    Args:
        poses: output of :func:`forward`.

    Returns:
        ``(z, o)``: unit joint axes and points on them (m), each shape ``(N, n, 3)``.
        DH joint ``i`` turns about ``z_{i-1}`` through ``o_{i-1}``; MDH about ``z_i``
        through ``o_i``.
    """
    frames = poses.T_base_link[:, :-1] if poses.convention == "dh" else poses.T_base_link[:, 1:]
    return frames[..., :3, 2], frames[..., :3, 3]


def screws(chain: Chain, poses: ChainPoses) -> KinematicScrews:
    """Screws of all ``5n`` kinematic parameters at each pose (table in the module doc).

    Args:
        chain: the chain ``poses`` was computed for.
        poses: output of :func:`forward` (any ``kin_delta``).

    Returns:
        :class:`KinematicScrews` with ``axis`` and ``point`` of shape ``(N, 5n, 3)``
        (views of component-major ``(3, 5n, N)`` buffers).
    """
    if poses.n != chain.n or poses.convention != chain.convention:
        raise InputError(
            f"poses: computed for a {poses.n}-joint {poses.convention} chain, "
            f"not for {chain.name!r} ({chain.n}-joint {chain.convention})"
        )
    n = chain.n
    # Component-major frames: Tc[i, row, col, pose]; a contiguous buffer from forward().
    Tc = poses.T_base_link.transpose(1, 2, 3, 0)
    N = Tc.shape[-1]
    # Axes and origins of link frames 0..n, each (3, n+1, N): [component, frame, pose].
    x = Tc[:, :3, 0].transpose(1, 0, 2)
    y = Tc[:, :3, 1].transpose(1, 0, 2)
    z = Tc[:, :3, 2].transpose(1, 0, 2)
    o = Tc[:, :3, 3].transpose(1, 0, 2)
    axis = np.empty((3, 5 * n, N))
    point = np.empty((3, 5 * n, N))
    theta_s, d_s, a_s, alpha_s, beta_s = (slice(k * n, (k + 1) * n) for k in range(5))
    point[:, d_s] = 0.0
    point[:, a_s] = 0.0
    if poses.convention == "dh":
        axis[:, theta_s] = z[:, :-1]
        point[:, theta_s] = o[:, :-1]
        axis[:, d_s] = z[:, :-1]
        # x' = cos(b) x_i + sin(b) z_i: link i's x axis before Ry(beta).
        np.multiply(poses.cos_beta.T, x[:, 1:], out=axis[:, a_s])
        axis[:, a_s] += poses.sin_beta.T * z[:, 1:]
        axis[:, alpha_s] = axis[:, a_s]
        point[:, alpha_s] = o[:, 1:]
        axis[:, beta_s] = y[:, 1:]
        point[:, beta_s] = o[:, 1:]
    else:
        axis[:, theta_s] = z[:, 1:]
        point[:, theta_s] = o[:, 1:]
        axis[:, d_s] = z[:, 1:]
        # cos(t) x_i - sin(t) y_i: link i's x axis before Rz(theta).
        np.multiply(poses.cos_theta.T, x[:, 1:], out=axis[:, a_s])
        axis[:, a_s] -= poses.sin_theta.T * y[:, 1:]
        axis[:, alpha_s] = x[:, :-1]
        point[:, alpha_s] = o[:, :-1]
        # cos(al) y_{i-1} + sin(al) z_{i-1}: y axis of frame i-1 after Rx(alpha).
        np.multiply(poses.cos_alpha.T, y[:, :-1], out=axis[:, beta_s])
        axis[:, beta_s] += poses.sin_alpha.T * z[:, :-1]
        point[:, beta_s] = o[:, :-1]
    is_rotation = np.ones(5 * n, dtype=bool)
    is_rotation[d_s] = False
    is_rotation[a_s] = False
    prismatic = np.flatnonzero(chain.joint_is_prismatic)
    if prismatic.size:
        # Both slots share the joint axis z; the joint slot translates along it and the d
        # slot turns about it, through the point the theta screw uses.
        joint_cols, d_cols = prismatic, n + prismatic
        point[:, d_cols] = point[:, joint_cols]
        point[:, joint_cols] = 0.0
        is_rotation[joint_cols] = False
        is_rotation[d_cols] = True
    return KinematicScrews(
        axis=axis.transpose(2, 1, 0), point=point.transpose(2, 1, 0), is_rotation=is_rotation
    )


def joint_screws(chain: Chain, poses: ChainPoses) -> KinematicScrews:
    """The screws of the ``n`` joint (theta) parameters only: rows ``0..n-1`` of
    :func:`screws`, without computing the other ``4n`` (what an offsets-only fit needs).

    Returns:
        :class:`KinematicScrews` with ``axis`` and ``point`` of shape ``(N, n, 3)``.
    """
    if poses.n != chain.n or poses.convention != chain.convention:
        raise InputError(
            f"poses: computed for a {poses.n}-joint {poses.convention} chain, "
            f"not for {chain.name!r} ({chain.n}-joint {chain.convention})"
        )
    axis, point = joint_axes(poses)
    prismatic = chain.joint_is_prismatic
    if prismatic.any():  # a prismatic joint's slot translates along its axis
        point = point.copy()
        point[:, prismatic] = 0.0
    return KinematicScrews(axis=axis, point=point, is_rotation=~prismatic)


def point_jacobian(screws: KinematicScrews, x_base: ArrayLike) -> FloatArray:
    """Derivative of a flange-fixed point by every kinematic parameter.

    Args:
        screws: output of :func:`screws`, ``N`` poses, ``m = 5n`` parameters.
        x_base: the point in base coordinates (m), shape ``(N, 3)``.

    Returns:
        ``dx_dparam``, shape ``(N, 3, m)`` (m per m or m per rad):
        ``axis x (x - point)`` for rotations, ``axis`` for translations. A view of a
        component-major ``(3, m, N)`` buffer.
    """
    N, m, _ = screws.axis.shape
    x = np.asarray(x_base, dtype=np.float64)
    if x.shape != (N, 3):
        raise InputError(f"x_base: expected shape ({N}, 3), got {x.shape}")
    axis = screws.axis.transpose(2, 1, 0)  # (3, m, N)
    r = x.T[:, None, :] - screws.point.transpose(2, 1, 0)  # (3, m, N): x - point
    out = np.empty((3, m, N))
    tmp = np.empty((m, N))
    for k in range(3):  # out_k = axis_i r_j - axis_j r_i, (k, i, j) cyclic
        i, j = (k + 1) % 3, (k + 2) % 3
        np.multiply(axis[i], r[j], out=out[k])
        out[k] -= np.multiply(axis[j], r[i], out=tmp)
    translation = ~screws.is_rotation
    out[:, translation] = axis[:, translation]
    return out.transpose(2, 0, 1)


def rotation_jacobian(screws: KinematicScrews) -> FloatArray:
    """Angular velocity of the flange per unit increase of every kinematic parameter.

    ``dR_base_flange = skew(w) @ R_base_flange`` with ``w = J @ dparam``.

    Args:
        screws: output of :func:`screws`, ``N`` poses, ``m = 5n`` parameters.

    Returns:
        ``J``, shape ``(N, 3, m)`` (rad per rad; 0 for translations), base coordinates.
    """
    return np.swapaxes(screws.axis, 1, 2) * screws.is_rotation
