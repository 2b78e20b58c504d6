"""Euler angle sequences as tracker software writes them, turned into rotation matrices.

Tracker and motion-capture software give a measured frame's orientation as three angles
about a named axis sequence (``zyx``, ``xyz``, ``zyz``...), either *intrinsic* (each turn
about the axes of the already turned frame) or *extrinsic* (each turn about the fixed world
axes). The dataset stores roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll)
(docs/conventions.md), which is ``xyz-extrinsic``; any sequence is converted exactly by
building the rotation matrix and reading roll, pitch, yaw back from it:

- intrinsic ``abc`` with angles (e1, e2, e3): R = Ra(e1) Rb(e2) Rc(e3);
- extrinsic ``abc`` with angles (e1, e2, e3): R = Rc(e3) Rb(e2) Ra(e1).

(These are the conventions of ``scipy.spatial.transform.Rotation.from_euler``: upper case
for intrinsic, lower case for extrinsic.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hostpc.errors import InputError
from hostpc.importing.imported import FloatArray

__all__ = ["EULER_SEQUENCES", "EulerConvention", "euler_to_matrix", "parse_euler"]

#: the twelve sequences: six Tait-Bryan (three different axes), six proper Euler
EULER_SEQUENCES = ("xyz", "xzy", "yxz", "yzx", "zxy", "zyx",
                   "xyx", "xzx", "yxy", "yzy", "zxz", "zyz")
_KINDS = ("intrinsic", "extrinsic")


@dataclass(frozen=True)
class EulerConvention:
    """An axis sequence (``"zyx"``) and whether the turns are about the moving axes."""

    sequence: str
    intrinsic: bool


def parse_euler(spec: str) -> EulerConvention:
    """``SEQ-intrinsic`` or ``SEQ-extrinsic`` (``--euler``); InputError naming the choices."""
    sequence, _, kind = spec.strip().lower().partition("-")
    if sequence not in EULER_SEQUENCES or kind not in _KINDS:
        raise InputError(f"--euler: {spec!r} is not SEQ-intrinsic or SEQ-extrinsic with SEQ "
                         f"one of {', '.join(EULER_SEQUENCES)} (e.g. --euler zyx-intrinsic)")
    return EulerConvention(sequence=sequence, intrinsic=kind == "intrinsic")


def _axis_rotation(axis: str, angle: FloatArray) -> FloatArray:
    """Rotations about ``axis`` ("x", "y" or "z") by ``angle`` (N,), shape (N, 3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    i = "xyz".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    out = np.zeros(angle.shape + (3, 3))
    out[:, i, i] = 1.0
    out[:, j, j] = c
    out[:, k, k] = c
    out[:, k, j] = s
    out[:, j, k] = -s
    return out


def euler_to_matrix(angles: FloatArray, convention: EulerConvention) -> FloatArray:
    """Rotation matrices (N, 3, 3) of the angles (N, 3) rad, in sequence order."""
    turns = [_axis_rotation(axis, angles[:, n]) for n, axis in enumerate(convention.sequence)]
    first, second, third = turns if convention.intrinsic else turns[::-1]
    return np.asarray(first @ second @ third, dtype=np.float64)
