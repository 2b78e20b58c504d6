"""Static gravity load torque on every joint (definition in ``docs/conventions.md``).

    tau_i = z_i . sum_{j >= i} (c_j - o_i) x (m_j g),   g = [0, 0, -9.81] m/s^2 in base

With the outboard mass ``M_i = sum_{j >= i} m_j`` and first moment
``S_i = sum_{j >= i} m_j c_j`` this is ``tau_i = z_i . ((S_i - M_i o_i) x g)``, computed for
all joints at once with suffix sums. For a prismatic joint ``tau_i`` is the gravity force
along its axis, ``z_i . (M_i g)`` (N).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.jacobians import joint_axes
from hostpc.kinematics.poses import forward

__all__ = ["GRAVITY", "gravity_torque"]

FloatArray = NDArray[np.float64]

GRAVITY: FloatArray = np.array([0.0, 0.0, -9.81])
"""Gravity acceleration in base coordinates (m/s^2)."""
GRAVITY.flags.writeable = False


def gravity_torque(
    chain: Chain, q: ArrayLike, kin_delta: ArrayLike | None = None
) -> FloatArray:
    """Gravity load torque about every joint axis.

    Args:
        chain: a chain with ``mass`` and ``com`` data.
        q: joint angles (rad), shape ``(N, n)``.
        kin_delta: kinematic parameter deltas as in :func:`forward`, shape ``(N, 5n)``,
            ``(5n,)`` or None.

    Returns:
        ``tau`` (N m), shape ``(N, n)``: the torque gravity exerts on links ``i..n`` about
        joint ``i``'s axis (positive counter-clockwise about ``z_i``).
    """
    if chain.mass is None or chain.com is None:
        missing = "mass" if chain.mass is None else "com"
        raise InputError(f"{missing}: robot {chain.name!r} has no mass data for gravity torque")
    poses = forward(chain, q, kin_delta)
    T = poses.T_base_link[:, 1:]  # link frames 1..n, (N, n, 4, 4)
    c = np.einsum("nkij,kj->nki", T[..., :3, :3], chain.com) + T[..., :3, 3]
    moment = chain.mass[:, None] * c  # (N, n, 3): m_j c_j
    S = np.cumsum(moment[:, ::-1], axis=1)[:, ::-1]
    M = np.cumsum(chain.mass[::-1])[::-1]
    z, o = joint_axes(poses)
    lever = S - M[:, None] * o  # (N, n, 3)
    tau: FloatArray = np.einsum("nki,nki->nk", z, np.cross(lever, GRAVITY))
    prismatic = chain.joint_is_prismatic
    if prismatic.any():  # a prismatic joint carries a force along its axis (N)
        force = M[None, :, None] * GRAVITY  # (1, n, 3)
        tau[:, prismatic] = np.einsum("nki,nki->nk", z[:, prismatic], force[:, prismatic])
    return tau
