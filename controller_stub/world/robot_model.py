"""The simulator's own forward model: URDF-style joint origins, not a DH product.

Every robot is a serial chain of revolute joints. Joint `i` (1-based) sits at a FIXED origin
transform `O_i = [R(rpy_i), xyz_i]` expressed in the body frame of joint `i-1` (the base for
joint 1), followed by a rotation about the local z axis by the physical joint angle; the body
frame of joint `i` is the frame after that rotation. A final fixed transform `O_flange` maps
the last body frame to the flange:

    T_base_body_i = T_base_body_{i-1} @ O_i @ Rz(q_i)        (T_base_body_0 = I)
    T_base_flange = T_base_body_n @ O_flange

The tables below are derived BY HAND from the published DH data (derivations in comments),
so that `base` is exactly DH frame 0 and `flange` exactly DH frame n of docs/conventions.md,
with the joint zero and sign of the DH table. This module never imports hostpc: the host's
DH implementation and this model must agree only because both are right.

Link-length errors perturb the same physical lengths as the DH `d_i` and `a_i`: each length
lives in one origin (or the flange transform) and moves it along a fixed direction of that
origin's parent frame; see `LengthSite` and the tables.

Gravity torque (conventions.md): tau_i = z_i . sum_{j>=i} (c_j - o_i) x (m_j g), with z_i, o_i
the axis and origin of body frame i in base and g = (0, 0, -9.81) m/s^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controller_stub.geometry import make_transform

GRAVITY = np.array([0.0, 0.0, -9.81])
HALF_PI = math.pi / 2


def rot_z(q: np.ndarray) -> np.ndarray:
    """(N,) angles (rad) -> (N, 4, 4) rotations about z."""
    q = np.asarray(q, dtype=float)
    T = np.zeros((q.shape[0], 4, 4))
    c, s = np.cos(q), np.sin(q)
    T[:, 0, 0] = c
    T[:, 0, 1] = -s
    T[:, 1, 0] = s
    T[:, 1, 1] = c
    T[:, 2, 2] = 1.0
    T[:, 3, 3] = 1.0
    return T


# ----------------------------------------------------------------------------------------
# model data


@dataclass(frozen=True)
class LengthSite:
    """Where a DH length lives: origin `site` (0..n-1 = joint 1..n origin, n = flange),
    moved along `direction` (unit (3,), parent-frame coordinates) by a delta of that length."""

    site: int
    direction: tuple[float, float, float]


@dataclass(frozen=True)
class RobotModel:
    """A serial robot for the simulator.

    origin_xyz, origin_rpy: (n, 3) joint origins in the previous body frame (m, rad).
    flange_xyz, flange_rpy: (3,) flange transform in the last body frame.
    d_sites, a_sites: per joint, where DH d_i / a_i live (see LengthSite).
    mass: (n,) kg; com_body: (n, 3) centre of mass of link i in body frame i (m).
    q_min, q_max: (n,) default joint limits (rad); max_speed: (n,) rad/s;
    home: (n,) default start pose (rad).
    """

    name: str
    origin_xyz: np.ndarray
    origin_rpy: np.ndarray
    flange_xyz: np.ndarray
    flange_rpy: np.ndarray
    d_sites: tuple[LengthSite, ...]
    a_sites: tuple[LengthSite, ...]
    mass: np.ndarray
    com_body: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    max_speed: np.ndarray
    home: np.ndarray

    @property
    def n_joints(self) -> int:
        return int(self.origin_xyz.shape[0])

    def origins(
        self, delta_d: np.ndarray | None = None, delta_a: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Fixed transforms with length deltas applied.

        delta_d, delta_a: (n,) m, deltas of the DH lengths d_i and a_i (or None).
        Returns (O (n, 4, 4) joint origins, O_flange (4, 4)).
        """
        n = self.n_joints
        xyz = np.vstack([self.origin_xyz, self.flange_xyz[None, :]]).astype(float)
        for deltas, sites in ((delta_d, self.d_sites), (delta_a, self.a_sites)):
            if deltas is None:
                continue
            for i in range(n):
                xyz[sites[i].site] += float(deltas[i]) * np.asarray(sites[i].direction)
        rpy = np.vstack([self.origin_rpy, self.flange_rpy[None, :]])
        O = np.stack([make_transform(xyz[k], rpy[k]) for k in range(n + 1)])
        return O[:n], O[n]


def forward(
    model: RobotModel,
    q: np.ndarray,
    origins: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics at physical joint angles.

    q: (N, n) or (n,) rad. origins: from `model.origins(...)` (nominal if None): joint
    origins (n, 4, 4) and flange (4, 4), or per pose (N, n, 4, 4) and (N, 4, 4).
    Returns (T_base_body (N, n, 4, 4), T_base_flange (N, 4, 4)).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    O, O_flange = origins if origins is not None else model.origins()
    N, n = q.shape
    T_body = np.empty((N, n, 4, 4))
    T = np.broadcast_to(np.eye(4), (N, 4, 4))
    per_pose = O.ndim == 4
    for i in range(n):
        T = T @ (O[:, i] if per_pose else O[i]) @ rot_z(q[:, i])
        T_body[:, i] = T
    return T_body, T @ O_flange


def gravity_torque(
    model: RobotModel, q: np.ndarray, origins: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """Gravity load torque about each joint axis (N m), conventions.md definition.

    q: (N, n) or (n,) physical angles (rad). Returns (N, n).
    """
    T_body, _ = forward(model, q, origins)
    R = T_body[:, :, :3, :3]
    o = T_body[:, :, :3, 3]  # (N, n, 3) joint origins in base
    z = R[:, :, :, 2]  # (N, n, 3) joint axes in base
    c = np.einsum("nkij,kj->nki", R, model.com_body) + o  # (N, n, 3) COMs in base
    f = model.mass[None, :, None] * GRAVITY[None, None, :]  # (1, n, 3) weights
    n = model.n_joints
    tau = np.empty(q.shape if np.ndim(q) == 2 else (1, n))
    for i in range(n):
        moment = np.cross(c[:, i:] - o[:, i : i + 1], np.broadcast_to(f[:, i:], c[:, i:].shape))
        tau[:, i] = np.einsum("nj,nj->n", z[:, i], moment.sum(axis=1))
    return tau


def _com_in_body(
    origin_next_xyz: np.ndarray, origin_next_rpy: np.ndarray, com_dh: np.ndarray
) -> np.ndarray:
    """COMs given in DH frame i -> body frame i, for standard DH where DH frame i is body
    frame i followed by the NEXT origin (O_{i+1}, or O_flange for the last link)."""
    out = np.empty_like(com_dh)
    for i in range(com_dh.shape[0]):
        out[i] = (
            make_transform(origin_next_xyz[i], origin_next_rpy[i])[:3, :3] @ com_dh[i]
            + origin_next_xyz[i]
        )
    return out


# ----------------------------------------------------------------------------------------
# Universal Robots e-series (standard DH, Universal Robots' published table)
#
# DH (conventions.md, beta = 0):  T_{i-1}_{i} = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i).
# Regroup the product of all joints so every rotation by a joint angle comes LAST in its
# factor:  T_0_n = Rz(q_1) [Tz(d_1) Tx(a_1) Rx(alpha_1)] Rz(q_2) [Tz(d_2) ...] ... Rz(q_6)
#                  [Tz(d_6) Tx(a_6) Rx(alpha_6)].
# So: O_1 = I (joint 1 axis is base z through the base origin); for k >= 2,
# O_k = Tz(d_{k-1}) Tx(a_{k-1}) Rx(alpha_{k-1}) = translation (a_{k-1}, 0, d_{k-1}) followed by
# the rotation rpy (alpha_{k-1}, 0, 0) - exactly a URDF origin with xyz=(a, 0, d),
# rpy=(alpha, 0, 0); and O_flange = Tz(d_6) Tx(a_6) Rx(alpha_6) -> xyz (0, 0, d_6), rpy 0.
# Hence body frame i (after Rz(q_i)) is DH frame i-1 rotated by q_i, and DH frame i =
# body frame i @ O_{i+1}: the flange is DH frame 6.
# Length sites: d_i is the z component of O_{i+1} (site i in 0-based origin numbering,
# site 6 = flange), a_i the x component of the same origin.
#
# UR5e: d1 = 0.1625, a2 = -0.425, a3 = -0.3922, d4 = 0.1333, d5 = 0.0997, d6 = 0.0996,
#       alpha = (pi/2, 0, 0, pi/2, -pi/2, 0)
#   O_1 = xyz (0, 0, 0)          rpy (0, 0, 0)
#   O_2 = xyz (0, 0, 0.1625)     rpy (pi/2, 0, 0)     [d1, alpha1]
#   O_3 = xyz (-0.425, 0, 0)     rpy (0, 0, 0)        [a2]
#   O_4 = xyz (-0.3922, 0, 0)    rpy (0, 0, 0)        [a3]
#   O_5 = xyz (0, 0, 0.1333)     rpy (pi/2, 0, 0)     [d4, alpha4]
#   O_6 = xyz (0, 0, 0.0997)     rpy (-pi/2, 0, 0)    [d5, alpha5]
#   O_f = xyz (0, 0, 0.0996)     rpy (0, 0, 0)        [d6]
# UR10e: d1 = 0.1807, a2 = -0.6127, a3 = -0.57155, d4 = 0.17415, d5 = 0.11985, d6 = 0.11655.
# Masses (kg) and COMs (m, in DH frame i) from the same published table:
#   UR5e  m = 3.761, 8.058, 2.846, 1.37, 1.3, 0.365
#         c = (0, -0.02561, 0.00193), (0.2125, 0, 0.11336), (0.15, 0, 0.0265),
#             (0, -0.0018, 0.01634), (0, 0.0018, 0.01634), (0, 0, -0.001159)
#   UR10e m = 7.369, 13.051, 3.989, 2.1, 1.98, 0.615
#         c = (0.021, 0, 0.027), (0.38, 0, 0.158), (0.24, 0, 0.068),
#             (0, 0.007, 0.018), (0, 0.007, 0.018), (0, 0, -0.026)
# ----------------------------------------------------------------------------------------

_UR_RPY = np.array(
    [[0, 0, 0], [HALF_PI, 0, 0], [0, 0, 0], [0, 0, 0], [HALF_PI, 0, 0], [-HALF_PI, 0, 0]],
    dtype=float,
)
_Z = (0.0, 0.0, 1.0)
_X = (1.0, 0.0, 0.0)
_UR_D_SITES = tuple(LengthSite(i + 1, _Z) for i in range(6))
_UR_A_SITES = tuple(LengthSite(i + 1, _X) for i in range(6))


def _ur(
    name: str,
    d1: float,
    a2: float,
    a3: float,
    d4: float,
    d5: float,
    d6: float,
    mass: list[float],
    com_dh: list[list[float]],
    max_speed: list[float],
) -> RobotModel:
    origin_xyz = np.array(
        [[0, 0, 0], [0, 0, d1], [a2, 0, 0], [a3, 0, 0], [0, 0, d4], [0, 0, d5]], dtype=float
    )
    flange_xyz = np.array([0.0, 0.0, d6])
    next_xyz = np.vstack([origin_xyz[1:], flange_xyz])
    next_rpy = np.vstack([_UR_RPY[1:], np.zeros(3)])
    two_pi = 2 * math.pi
    return RobotModel(
        name=name,
        origin_xyz=origin_xyz,
        origin_rpy=_UR_RPY.copy(),
        flange_xyz=flange_xyz,
        flange_rpy=np.zeros(3),
        d_sites=_UR_D_SITES,
        a_sites=_UR_A_SITES,
        mass=np.array(mass, dtype=float),
        com_body=_com_in_body(next_xyz, next_rpy, np.array(com_dh, dtype=float)),
        # e-series: +-360 deg on every joint; the elbow is limited to +-180 deg in practice.
        q_min=np.array([-two_pi, -two_pi, -math.pi, -two_pi, -two_pi, -two_pi]),
        q_max=np.array([two_pi, two_pi, math.pi, two_pi, two_pi, two_pi]),
        max_speed=np.array(max_speed, dtype=float),
        home=np.array([0.0, -HALF_PI, HALF_PI, -HALF_PI, -HALF_PI, 0.0]),
    )


def _ur5e() -> RobotModel:
    return _ur(
        "ur5e",
        0.1625,
        -0.425,
        -0.3922,
        0.1333,
        0.0997,
        0.0996,
        [3.761, 8.058, 2.846, 1.37, 1.3, 0.365],
        [
            [0, -0.02561, 0.00193],
            [0.2125, 0, 0.11336],
            [0.15, 0, 0.0265],
            [0, -0.0018, 0.01634],
            [0, 0.0018, 0.01634],
            [0, 0, -0.001159],
        ],
        [math.pi] * 6,  # 180 deg/s on all joints
    )


def _ur10e() -> RobotModel:
    return _ur(
        "ur10e",
        0.1807,
        -0.6127,
        -0.57155,
        0.17415,
        0.11985,
        0.11655,
        [7.369, 13.051, 3.989, 2.1, 1.98, 0.615],
        [
            [0.021, 0, 0.027],
            [0.38, 0, 0.158],
            [0.24, 0, 0.068],
            [0, 0.007, 0.018],
            [0, 0.007, 0.018],
            [0, 0, -0.026],
        ],
        [2 * math.pi / 3] * 2 + [math.pi] * 4,  # 120 deg/s base/shoulder, 180 deg/s others
    )


# ----------------------------------------------------------------------------------------
# industrial6: PUMA 560, Craig's modified DH (Armstrong, Khatib & Burdick data as listed in
# Corke's Robotics Toolbox documentation):
#
#   row i:  alpha_{i-1}   a_{i-1}    d_i       (theta_i nominal 0)
#   1       0             0          0
#   2       -pi/2         0          0.2435
#   3       0             0.4318     -0.0934
#   4       pi/2          -0.0203    0.4331
#   5       -pi/2         0          0
#   6       pi/2          0          0
#
# MDH (conventions.md): T_{i-1}_{i} = Rx(alpha) Tx(a) Rz(q_i) Tz(d_i). Tz(d) commutes with
# Rz(q), and Tx(a) with Rx(alpha), so T = Tx(a) Rx(alpha) Tz(d) Rz(q)
#   = Trans(a, 0, 0) Trans(Rx(alpha) (0, 0, d)) Rx(alpha) Rz(q)
#   = Trans(a, -d sin(alpha), d cos(alpha)) Rx(alpha) Rz(q).
# So O_i = xyz (a_{i-1}, -d_i sin(alpha_{i-1}), d_i cos(alpha_{i-1})), rpy (alpha_{i-1}, 0, 0),
# body frame i IS MDH frame i, and O_flange = I (the flange is MDH frame 6).
#   O_1 = xyz (0, 0, 0)               rpy (0, 0, 0)
#   O_2 = xyz (0, 0.2435, 0)          rpy (-pi/2, 0, 0)    [-d2 sin(-pi/2) = +d2]
#   O_3 = xyz (0.4318, 0, -0.0934)    rpy (0, 0, 0)        [a2, d3]
#   O_4 = xyz (-0.0203, -0.4331, 0)   rpy (pi/2, 0, 0)     [a3, -d4 sin(pi/2) = -d4]
#   O_5 = xyz (0, 0, 0)               rpy (-pi/2, 0, 0)
#   O_6 = xyz (0, 0, 0)               rpy (pi/2, 0, 0)
# Length sites: the row-i `a` (a_{i-1}) is the x component of O_i; d_i moves O_i along
# Rx(alpha_{i-1}) z = (0, -sin(alpha_{i-1}), cos(alpha_{i-1})) - the joint-i axis.
# Masses (kg): 0, 17.4, 4.8, 0.82, 0.34, 0.09; COMs (m, MDH frame i = body frame i):
#   (0, 0, 0), (0.068, 0.006, -0.016), (0, -0.070, 0.014), (0, 0, -0.019), (0, 0, 0),
#   (0, 0, 0.032).
# Limits (deg, Corke's toolbox): +-160, +-110, +-135, +-266, +-100, +-266.
# ----------------------------------------------------------------------------------------


def _industrial6() -> RobotModel:
    alpha_prev = np.array([0.0, -HALF_PI, 0.0, HALF_PI, -HALF_PI, HALF_PI])
    origin_xyz = np.array(
        [
            [0.0, 0.0, 0.0],
            [0.0, 0.2435, 0.0],
            [0.4318, 0.0, -0.0934],
            [-0.0203, -0.4331, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
        ]
    )
    d_sites = tuple(
        LengthSite(
            i, (0.0, round(-math.sin(alpha_prev[i]), 12), round(math.cos(alpha_prev[i]), 12))
        )
        for i in range(6)
    )
    deg = math.pi / 180
    limits = np.array([160, 110, 135, 266, 100, 266], dtype=float) * deg
    return RobotModel(
        name="industrial6",
        origin_xyz=origin_xyz,
        origin_rpy=np.column_stack([alpha_prev, np.zeros(6), np.zeros(6)]),
        flange_xyz=np.zeros(3),
        flange_rpy=np.zeros(3),
        d_sites=d_sites,
        a_sites=tuple(LengthSite(i, _X) for i in range(6)),
        mass=np.array([0.0, 17.4, 4.8, 0.82, 0.34, 0.09]),
        com_body=np.array(
            [
                [0.0, 0.0, 0.0],
                [0.068, 0.006, -0.016],
                [0.0, -0.070, 0.014],
                [0.0, 0.0, -0.019],
                [0.0, 0.0, 0.0],
                [0.0, 0.0, 0.032],
            ]
        ),
        q_min=-limits,
        q_max=limits,
        max_speed=np.array([1.5, 1.5, 1.5, 3.0, 3.0, 3.0]),
        home=np.array([0.0, -HALF_PI, HALF_PI, 0.0, HALF_PI, 0.0]),
    )


_BUILDERS = {"ur5e": _ur5e, "ur10e": _ur10e, "industrial6": _industrial6}


def robot_names() -> list[str]:
    """Names of the built-in robots."""
    return sorted(_BUILDERS)


def get_robot(name: str) -> RobotModel:
    """The built-in robot model `name` (KeyError naming the known robots otherwise)."""
    try:
        return _BUILDERS[name]()
    except KeyError:
        raise KeyError(f"unknown robot {name!r}; known: {', '.join(robot_names())}") from None
