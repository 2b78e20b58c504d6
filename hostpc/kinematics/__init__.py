"""Pure-numpy kinematics: rotations, DH/MDH chains, forward kinematics, screws, gravity.

Conventions (frames, DH/MDH equations, parameter order, derivative layout) are in
``docs/conventions.md``. Everything is vectorised over N poses.
"""

from hostpc.kinematics.chain import KIN_KINDS, Chain, kin_index
from hostpc.kinematics.gravity import GRAVITY, gravity_torque
from hostpc.kinematics.jacobians import (
    KinematicScrews,
    joint_axes,
    joint_screws,
    point_jacobian,
    rotation_jacobian,
    screws,
)
from hostpc.kinematics.poses import ChainPoses, forward
from hostpc.kinematics.robots import get_robot, names
from hostpc.kinematics.rotations import (
    invert_transform,
    make_transform,
    matrix_to_rotvec,
    matrix_to_rpy,
    pose_to_transform,
    rot_x,
    rot_y,
    rot_z,
    rotvec_to_matrix,
    rpy_to_matrix,
    skew,
)
from hostpc.kinematics.tables import chain_from_table

__all__ = [
    "GRAVITY",
    "KIN_KINDS",
    "Chain",
    "ChainPoses",
    "KinematicScrews",
    "chain_from_table",
    "forward",
    "get_robot",
    "gravity_torque",
    "invert_transform",
    "joint_axes",
    "joint_screws",
    "kin_index",
    "make_transform",
    "matrix_to_rotvec",
    "matrix_to_rpy",
    "names",
    "point_jacobian",
    "pose_to_transform",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_jacobian",
    "rotvec_to_matrix",
    "rpy_to_matrix",
    "screws",
    "skew",
]
