"""Rotations and rigid transforms of the simulated world (roll-pitch-yaw, docs/conventions.md).

The stub's own (it never imports hostpc): shared by the robot models, the sensors and the
scenario's truth. Angles in radians, lengths in metres.
"""

from __future__ import annotations

import math

import numpy as np


def rpy_to_matrix(rpy: np.ndarray | list[float]) -> np.ndarray:
    """(3,) [roll, pitch, yaw] rad -> (3, 3) R = Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (3,) [roll, pitch, yaw] rad (inverse of rpy_to_matrix)."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    roll = math.atan2(R[2, 1], R[2, 2])
    yaw = math.atan2(R[1, 0], R[0, 0])
    return np.array([roll, pitch, yaw])


def make_transform(xyz: np.ndarray | list[float], rpy: np.ndarray | list[float]) -> np.ndarray:
    """(4, 4) homogeneous transform from translation (m) and roll-pitch-yaw (rad)."""
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(rpy)
    T[:3, 3] = np.asarray(xyz, dtype=float)
    return T
