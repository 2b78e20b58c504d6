"""The stub's URDF-style model against an independent DH/MDH product written here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller_stub.world.robot_model import forward, get_robot, gravity_torque, robot_names

HP = math.pi / 2
# (a, alpha, d) per joint as published (see robot_model.py comments), theta nominal 0.
DH_TABLES = {
    "ur5e": (
        "dh",
        [0, -0.425, -0.3922, 0, 0, 0],
        [HP, 0, 0, HP, -HP, 0],
        [0.1625, 0, 0, 0.1333, 0.0997, 0.0996],
    ),
    "ur10e": (
        "dh",
        [0, -0.6127, -0.57155, 0, 0, 0],
        [HP, 0, 0, HP, -HP, 0],
        [0.1807, 0, 0, 0.17415, 0.11985, 0.11655],
    ),
    "industrial6": (
        "mdh",
        [0, 0, 0.4318, -0.0203, 0, 0],
        [0, -HP, 0, HP, -HP, HP],
        [0, 0.2435, -0.0934, 0.4331, 0, 0],
    ),
}


def _rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _tr(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


def dh_forward(
    name: str, q: np.ndarray, dd: np.ndarray | None = None, da: np.ndarray | None = None
) -> list[np.ndarray]:
    """DH frames 0..n (conventions.md product), with optional d/a deltas."""
    conv, a, alpha, d = DH_TABLES[name]
    a = np.array(a, float) + (0 if da is None else da)
    d = np.array(d, float) + (0 if dd is None else dd)
    frames = [np.eye(4)]
    T = np.eye(4)
    for i in range(len(q)):
        if conv == "dh":
            T = T @ _rz(q[i]) @ _tr(0, 0, d[i]) @ _tr(a[i], 0, 0) @ _rx(alpha[i])
        else:
            T = T @ _rx(alpha[i]) @ _tr(a[i], 0, 0) @ _rz(q[i]) @ _tr(0, 0, d[i])
        frames.append(T)
    return frames


@pytest.mark.parametrize("name", robot_names())
def test_flange_equals_dh_frame_n(name: str) -> None:
    model = get_robot(name)
    rng = np.random.default_rng(3)
    for q in rng.uniform(-3, 3, (20, 6)):
        _, T = forward(model, q)
        np.testing.assert_allclose(T[0], dh_forward(name, q)[-1], atol=1e-12)


def test_ur5e_zero_pose_golden() -> None:
    _, T = forward(get_robot("ur5e"), np.zeros(6))
    # at q = 0: x = a2 + a3, y = -(d4 + d6), z = d1 - d5
    np.testing.assert_allclose(T[0, :3, 3], [-0.8172, -0.2329, 0.0628], atol=1e-12)


@pytest.mark.parametrize("name", robot_names())
def test_length_errors_perturb_dh_lengths(name: str) -> None:
    model = get_robot(name)
    rng = np.random.default_rng(4)
    dd, da = rng.normal(0, 1e-3, 6), rng.normal(0, 1e-3, 6)
    origins = model.origins(dd, da)
    for q in rng.uniform(-3, 3, (5, 6)):
        _, T = forward(model, q, origins)
        np.testing.assert_allclose(T[0], dh_forward(name, q, dd, da)[-1], atol=1e-12)


@pytest.mark.parametrize("name", robot_names())
def test_gravity_torque_is_minus_potential_gradient(name: str) -> None:
    model = get_robot(name)
    rng = np.random.default_rng(5)
    q = rng.uniform(-2, 2, 6)

    def potential(qq: np.ndarray) -> float:
        T_body, _ = forward(model, qq)
        c = np.einsum("kij,kj->ki", T_body[0, :, :3, :3], model.com_body) + T_body[0, :, :3, 3]
        return float(np.sum(model.mass * 9.81 * c[:, 2]))

    h = 1e-6
    numeric = np.array(
        [-(potential(q + h * e) - potential(q - h * e)) / (2 * h) for e in np.eye(6)]
    )
    np.testing.assert_allclose(gravity_torque(model, q)[0], numeric, atol=1e-6)


def test_ur5e_com_in_dh_frames() -> None:
    """COMs are published in DH frame i; check link 2's COM lands where DH frame 2 puts it."""
    model = get_robot("ur5e")
    q = np.array([0.3, -1.1, 0.7, 0.2, -0.4, 0.9])
    T_body, _ = forward(model, q)
    frames = dh_forward("ur5e", q)
    c_model = T_body[0, 1, :3, :3] @ model.com_body[1] + T_body[0, 1, :3, 3]
    c_dh = frames[2][:3, :3] @ np.array([0.2125, 0, 0.11336]) + frames[2][:3, 3]
    np.testing.assert_allclose(c_model, c_dh, atol=1e-12)


def test_shoulder_torque_sign_ur5e() -> None:
    """q = 0 stretches the arm along base -x. For a weight m g at r = (-L, 0, 0):
    r x F = (-L, 0, 0) x (0, 0, -m g) = (0, -L m g, 0), so the torque about joint 2's axis
    z_1 is negative along base +y."""
    model = get_robot("ur5e")
    tau = gravity_torque(model, np.zeros(6))[0]
    z1 = forward(model, np.zeros(6))[0][0, 1, :3, 2]
    assert abs(z1[1]) > 0.99
    assert tau[1] * z1[1] < -10.0  # tens of N m for a UR5e
