"""Numerical inverse kinematics (damped least squares), vectorised over N goals.

Used to turn wanted sensor poses (look at a target from here) into joint angles, for
synthetic datasets and for the pose planner. Not a motion planner: no collision checks.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from hostpc.kinematics.chain import Chain
from hostpc.kinematics.rotations import matrix_to_rotvec


def _kinematics() -> ModuleType:
    from hostpc import kinematics  # package top level (avoids an import cycle)

    return kinematics


def solve_ik(
    chain: Chain,
    T_base_flange_goal: np.ndarray,
    q_seed: np.ndarray,
    *,
    iterations: int = 60,
    damping: float = 1e-3,
    position_tolerance: float = 1e-7,
    rotation_tolerance: float = 1e-7,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles reaching each goal flange pose.

    T_base_flange_goal: (N, 4, 4) goals; q_seed: (N, n) start angles (rad).
    Returns q (N, n) and ok (N,) bool: converged and inside the chain's joint limits.
    """
    q = np.array(q_seed, dtype=float, copy=True)
    n = chain.n
    goal_R = T_base_flange_goal[:, :3, :3]
    goal_t = T_base_flange_goal[:, :3, 3]
    converged = np.zeros(q.shape[0], dtype=bool)
    for _ in range(iterations):
        k = _kinematics()
        poses = k.forward(chain, q)
        T = poses.T_base_flange
        e_pos = goal_t - T[:, :3, 3]
        e_rot = matrix_to_rotvec(goal_R @ np.swapaxes(T[:, :3, :3], 1, 2))
        converged = (np.linalg.norm(e_pos, axis=1) < position_tolerance) & (
            np.linalg.norm(e_rot, axis=1) < rotation_tolerance
        )
        if np.all(converged):
            break
        S = k.screws(chain, poses)
        J = np.concatenate(
            [k.point_jacobian(S, T[:, :3, 3])[:, :, :n], k.rotation_jacobian(S)[:, :, :n]], axis=1
        )
        error = np.concatenate([e_pos, e_rot], axis=1)
        JJt = J @ np.swapaxes(J, 1, 2) + damping**2 * np.eye(6)
        step = np.einsum("nji,nj->ni", J, np.linalg.solve(JJt, error[:, :, None])[:, :, 0])
        step_norm = np.linalg.norm(step, axis=1, keepdims=True)
        step *= np.minimum(1.0, 0.5 / np.maximum(step_norm, 1e-300))  # at most 0.5 rad a step
        q[~converged] += step[~converged]
    within = np.all((q >= chain.q_min) & (q <= chain.q_max), axis=1)
    return q, converged & within


def look_at(camera_position: np.ndarray, aim_point: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """Camera poses T_base_camera (N, 4, 4): z axis from the camera toward the aim point,
    rotated by roll (rad) about it. camera_position, aim_point: (N, 3)."""
    z = aim_point - camera_position
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    helper = np.where(np.abs(z[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x_rolled = c * x + s * y
    y_rolled = np.cross(z, x_rolled)
    T = np.zeros((z.shape[0], 4, 4))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2] = x_rolled, y_rolled, z
    T[:, :3, 3] = camera_position
    T[:, 3, 3] = 1.0
    return T
