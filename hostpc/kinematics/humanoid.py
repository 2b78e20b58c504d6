"""The built-in kinematic tree ``humanoid_upper``: a pan-tilt head and two 7-DoF arms.

A stated design (no vendor publishes it; the simulated controller ``controller_stub/
humanoid.py`` carries the same design, re-derived by hand in URDF form). All tables are
standard DH (conventions.md), units m, rad, kg.

Root frame = the head chain's base (``head base``): at the neck, x forward, y to the
robot's left, z up.

``head`` - 2-DoF pan-tilt unit:

=====  =====  ======  ======  =====  ==========================
joint  a (m)  alpha   d (m)   theta  range
=====  =====  ======  ======  =====  ==========================
pan    0      +pi/2   0.12    0      -100 .. +100 deg (about z)
tilt   0.06   0       0       0      -70 .. +35 deg (+ = up)
=====  =====  ======  ======  =====  ==========================

The head end frame (DH frame 2) sits 6 cm in front of the tilt axis; at ``q = 0`` its x
axis points forward, y up and z to the robot's right (the tilt axis is ``-y`` of the
root). Masses 0.6 kg (pan link), 1.2 kg (tilt link with the stereo camera).

``left`` / ``right`` - 7-DoF S-R-S arms (a KUKA-iiwa-like table scaled to a human arm:
upper arm 0.28 m, forearm 0.25 m, hand 0.10 m to the flange):

=====  =====  ======  ======  =====  ===========
joint  a (m)  alpha   d (m)   theta  range (deg)
=====  =====  ======  ======  =====  ===========
1      0      -pi/2   0       0      +-170
2      0      +pi/2   0       0      +-120
3      0      +pi/2   0.28    0      +-170
4      0      -pi/2   0       0      +-120
5      0      -pi/2   0.25    0      +-170
6      0      +pi/2   0       0      +-120
7      0      0       0.10    0      +-175
=====  =====  ======  ======  =====  ===========

Link masses 2.0, 1.8, 1.5, 1.2, 0.8, 0.5, 0.4 kg, each a point mass at its link frame
origin (design values, used only by gravity-dependent effects).

Nominal mounts (the dual_loop frames, :data:`HUMANOID_FRAMES`): each arm base is at the
shoulder, ``(0, +-0.20, -0.10)`` m in the head base, z axis pointing down (rpy
``(pi, 0, 0)``), so at ``q = 0`` the arm hangs straight down; the stereo camera's optical
frame (x right, y down, z forward, pitched 0.15 rad down) is ``(0.02, 0.04, 0)`` m in the
head end frame; each
arm's target point is ``(0, 0.03, 0.04)`` m in its flange frame.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hostpc.errors import InputError
from hostpc.kinematics.chain import Chain
from hostpc.kinematics.rotations import matrix_to_rpy, pose_to_transform, rot_z
from hostpc.kinematics.tables import chain_from_table
from hostpc.kinematics.tree import Branch, KinematicTree

__all__ = ["HUMANOID_FRAMES", "HUMANOID_HOME", "get_tree", "humanoid_upper", "tree_names"]

_HALF_PI = np.pi / 2.0
_DEG = np.pi / 180.0

# camera optical frame in the head end frame: z_cam = x_end (forward), y_cam = -y_end (down),
# x_cam = z_end (right), then pitched 0.15 rad down about z_end (the tilt axis)
_R_END_CAMERA = rot_z(-0.15) @ np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])

HUMANOID_FRAMES: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]
                      | tuple[float, float, float]] = {
    "camera": ((0.02, 0.04, 0.0), tuple(float(v) for v in matrix_to_rpy(_R_END_CAMERA))),  # type: ignore[dict-item]
    "left_base": ((0.0, 0.20, -0.10), (np.pi, 0.0, 0.0)),
    "right_base": ((0.0, -0.20, -0.10), (np.pi, 0.0, 0.0)),
    "left_target": (0.0, 0.03, 0.04),
    "right_target": (0.0, 0.03, 0.04),
}
"""Nominal dual_loop frames: poses as ``(xyz, rpy)``, points as ``xyz`` (m, rad)."""

HUMANOID_HOME: dict[str, tuple[float, ...]] = {
    "head": (0.0, -0.45),
    # hands 0.35 m in front of the neck, 0.3 m below it, elbows bent
    "left": (0.1, 0.05, 0.1, -1.45, 0.0, 0.8, 0.0),
    "right": (-0.1, 0.05, -0.1, -1.45, 0.0, 0.8, 0.0),
}
"""A pose with both targets in front of the camera (rad), the centre of planned poses."""


def _head() -> Chain:
    return chain_from_table(
        "humanoid_upper.head",
        "dh",
        a=[0.0, 0.06],
        alpha=[_HALF_PI, 0.0],
        d=[0.12, 0.0],
        theta=[0.0, 0.0],
        q_min=np.array([-100.0, -70.0]) * _DEG,
        q_max=np.array([100.0, 35.0]) * _DEG,
        mass=[0.6, 1.2],
        com=np.zeros((2, 3)),
    )


def _arm(side: str) -> Chain:
    limits = np.array([170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 175.0]) * _DEG
    return chain_from_table(
        f"humanoid_upper.{side}",
        "dh",
        a=np.zeros(7),
        alpha=[-_HALF_PI, _HALF_PI, _HALF_PI, -_HALF_PI, -_HALF_PI, _HALF_PI, 0.0],
        d=[0.0, 0.0, 0.28, 0.0, 0.25, 0.0, 0.10],
        theta=np.zeros(7),
        q_min=-limits,
        q_max=limits,
        mass=[2.0, 1.8, 1.5, 1.2, 0.8, 0.5, 0.4],
        com=np.zeros((7, 3)),
    )


def _pose(name: str) -> np.ndarray:
    xyz, rpy = HUMANOID_FRAMES[name]  # type: ignore[misc]
    return pose_to_transform(np.asarray(xyz, float), np.asarray(rpy, float))


def humanoid_upper() -> KinematicTree:
    """The ``humanoid_upper`` tree: chains ``head`` (2), ``left`` (7), ``right`` (7).

    Both arms hang from the head chain's BASE (the torso), not from the moving head; their
    nominal mounts and the other dual_loop frames are :data:`HUMANOID_FRAMES`."""
    frames = {name: _pose(name) for name in ("camera", "left_base", "right_base")}
    frames["left_target"] = np.asarray(HUMANOID_FRAMES["left_target"], float)
    frames["right_target"] = np.asarray(HUMANOID_FRAMES["right_target"], float)
    return KinematicTree(
        name="humanoid_upper",
        branches=(
            Branch("head", _head()),
            Branch("left", _arm("left"), parent="head", attach="base",
                   T_parent_base=frames["left_base"]),
            Branch("right", _arm("right"), parent="head", attach="base",
                   T_parent_base=frames["right_base"]),
        ),
        frames=frames,
    )


_TREES: dict[str, Callable[[], KinematicTree]] = {"humanoid_upper": humanoid_upper}


def tree_names() -> list[str]:
    """Names of the built-in kinematic trees, sorted."""
    return sorted(_TREES)


def get_tree(name: str) -> KinematicTree:
    """The built-in kinematic tree ``name`` (see :func:`tree_names`).

    Raises:
        InputError: unknown name; the message lists the built-in trees.
    """
    factory = _TREES.get(name)
    if factory is None:
        raise InputError(f"unknown kinematic tree {name!r}; built-in trees: "
                         f"{', '.join(tree_names())}")
    return factory()
