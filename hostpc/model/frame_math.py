"""Small rigid-body helpers for frame effects: perturbed poses and their derivatives.

A pose delta is ``[dx, dy, dz, rx, ry, rz]``: ``T = T_nom @ [exp([r]x), t]`` means
``R = R_nom @ exp([r]x)`` and ``t = t_nom + dt`` (docs/conventions.md).
"""

from __future__ import annotations

import numpy as np

from hostpc.kinematics.rotations import rotvec_to_matrix, skew


def so3_right_jacobian(rotvec: np.ndarray) -> np.ndarray:
    """Right Jacobian J_r (3, 3) of SO(3) at rotvec (3,): exp(r + dr) ~ exp(r) exp(J_r dr)."""
    r = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(r))
    K = skew(r)
    if angle < 1e-6:
        return np.eye(3) - 0.5 * K + (K @ K) / 6.0
    return (
        np.eye(3)
        - (1.0 - np.cos(angle)) / angle**2 * K
        + (angle - np.sin(angle)) / angle**3 * (K @ K)
    )


def perturbed_pose(
    R_nominal: np.ndarray, t_nominal: np.ndarray, delta: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R, t, J_r) of a nominal pose perturbed by a 6-vector delta (or unperturbed)."""
    if delta is None:
        return R_nominal, t_nominal, np.eye(3)
    R = R_nominal @ rotvec_to_matrix(delta[3:6])
    return R, t_nominal + delta[0:3], so3_right_jacobian(delta[3:6])


def inverse_point_derivatives(
    point_in_b: np.ndarray, R_a_b: np.ndarray, J_r: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives of y = R_a_b^T (x - t_a_b) (a point mapped from frame a into frame b) by the
    pose delta of T_a_b: returns (dy/dt (3, 3), dy/dr (N, 3, 3)) for y = point_in_b (N, 3)."""
    dy_dt = -R_a_b.T
    dy_dr = skew(point_in_b) @ J_r
    return dy_dt, dy_dr
