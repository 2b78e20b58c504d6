"""Rotations and transforms of hostpc.kinematics.rotations, checked against scipy and by hand."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from hostpc.errors import InputError
from hostpc.kinematics import (
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

RNG = np.random.default_rng(1234)


def random_rotations(count: int) -> np.ndarray:
    return Rotation.random(count, random_state=42).as_matrix()


def test_elementary_rotations_by_hand() -> None:
    # Right-hand rule: a quarter turn about z takes x to y, about x takes y to z, about y
    # takes z to x.
    np.testing.assert_allclose(rot_z(np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rot_x(np.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(rot_y(np.pi / 2) @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    angles = RNG.uniform(-4, 4, size=(2, 5))
    assert rot_x(angles).shape == (2, 5, 3, 3)
    for axis, func in zip("xyz", (rot_x, rot_y, rot_z), strict=True):
        expected = Rotation.from_euler(axis, angles.reshape(-1, 1)).as_matrix().reshape(2, 5, 3, 3)
        np.testing.assert_allclose(func(angles), expected, atol=1e-14)


def test_skew_is_cross_product() -> None:
    v, x = RNG.normal(size=(2, 7, 3))
    np.testing.assert_allclose(skew(v) @ x[..., None], np.cross(v, x)[..., None], atol=1e-14)
    np.testing.assert_allclose(skew(v), -np.swapaxes(skew(v), -1, -2))


def test_rpy_convention_matches_fixed_axes_xyz() -> None:
    rpy = RNG.uniform(-np.pi, np.pi, size=(50, 3))
    R = rpy_to_matrix(rpy)
    # scipy lower-case "xyz" = extrinsic (fixed) axes: R = Rz(yaw) Ry(pitch) Rx(roll).
    np.testing.assert_allclose(R, Rotation.from_euler("xyz", rpy).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(
        R, rot_z(rpy[:, 2]) @ rot_y(rpy[:, 1]) @ rot_x(rpy[:, 0]), atol=1e-14
    )


@settings(max_examples=50, deadline=None)
@given(
    roll=st.floats(-np.pi + 1e-6, np.pi - 1e-6),
    pitch=st.floats(-np.pi / 2 + 1e-4, np.pi / 2 - 1e-4),
    yaw=st.floats(-np.pi + 1e-6, np.pi - 1e-6),
)
def test_rpy_round_trip(roll: float, pitch: float, yaw: float) -> None:
    rpy = np.array([roll, pitch, yaw])
    np.testing.assert_allclose(matrix_to_rpy(rpy_to_matrix(rpy)), rpy, atol=1e-9)


def test_matrix_to_rpy_round_trip_incl_gimbal_lock() -> None:
    R = np.concatenate([
        random_rotations(100),
        rpy_to_matrix(np.array([[0.3, np.pi / 2, -1.0], [1.2, -np.pi / 2, 2.0],
                                [0.0, np.pi / 2, 0.0]])),
    ])
    rpy = matrix_to_rpy(R)
    assert np.all(np.abs(rpy[:, 1]) <= np.pi / 2 + 1e-12)
    np.testing.assert_allclose(rpy_to_matrix(rpy), R, atol=1e-12)


def test_rotvec_to_matrix_matches_scipy() -> None:
    r = RNG.normal(size=(200, 3)) * RNG.uniform(0, 3.1, size=(200, 1))
    np.testing.assert_allclose(rotvec_to_matrix(r), Rotation.from_rotvec(r).as_matrix(),
                               atol=1e-14)


@pytest.mark.parametrize(
    "angle", [0.0, 1e-12, 1e-8, 9.99e-5, 1e-4, 1.001e-4, 1.5e-3, 1e-2, 1.0]
)
def test_rotvec_small_angles(angle: float) -> None:
    axis = np.array([0.48, -0.6, 0.64])
    r = axis * angle
    R = rotvec_to_matrix(r)
    np.testing.assert_allclose(R, Rotation.from_rotvec(r).as_matrix(), rtol=0, atol=4e-16)
    # Rodrigues: antisymmetric part sin(t)/t K, symmetric part I + (1 - cos t)/t^2 K^2,
    # with (1 - cos t)/t^2 = 2 sin^2(t/2)/t^2 (no cancellation).
    K = skew(r)
    sinc = np.sinc(angle / np.pi)
    half_sinc = np.sinc(angle / (2 * np.pi))
    np.testing.assert_allclose((R - R.T) / 2, sinc * K, rtol=1e-13, atol=0)
    if angle >= 1e-4:  # below, rounding of the O(t) entries swamps the O(t^2) part
        off = ~np.eye(3, dtype=bool)  # diagonal entries are 1 - O(t^2): no precision left
        np.testing.assert_allclose(((R + R.T) / 2)[off], (0.5 * half_sinc**2 * (K @ K))[off],
                                   rtol=1e-11, atol=0)
    np.testing.assert_allclose(matrix_to_rotvec(R), r, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("gap", [0.0, 1e-12, 1e-9, 1e-6, 1e-3])
def test_rotvec_near_pi(gap: float) -> None:
    axis = np.array([[1.0, 2.0, -2.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    r = axis * (np.pi - gap)
    R = rotvec_to_matrix(r)
    back = matrix_to_rotvec(R)
    np.testing.assert_allclose(np.linalg.norm(back, axis=1), np.pi - gap, atol=1e-9)
    # at exactly pi the sign of the axis is arbitrary: compare the rotations
    np.testing.assert_allclose(rotvec_to_matrix(back), R, atol=1e-12)
    if gap >= 1e-6:
        np.testing.assert_allclose(back, r, atol=1e-8)


def test_matrix_to_rotvec_round_trip_random() -> None:
    R = random_rotations(500)
    r = matrix_to_rotvec(R)
    assert np.all(np.linalg.norm(r, axis=1) <= np.pi + 1e-12)
    np.testing.assert_allclose(rotvec_to_matrix(r), R, atol=1e-13)
    np.testing.assert_allclose(r, Rotation.from_matrix(R).as_rotvec(), atol=1e-12)


def test_transforms() -> None:
    R = random_rotations(20)
    t = RNG.normal(size=(20, 3))
    T = make_transform(R, t)
    assert T.shape == (20, 4, 4)
    np.testing.assert_array_equal(T[:, 3], np.broadcast_to([0, 0, 0, 1.0], (20, 4)))
    T_inv = invert_transform(T)
    np.testing.assert_allclose(T_inv, np.linalg.inv(T), atol=1e-13)
    np.testing.assert_allclose(T @ T_inv, np.broadcast_to(np.eye(4), T.shape), atol=1e-13)
    np.testing.assert_allclose(invert_transform(T_inv), T, atol=1e-13)
    # x_a = T_a_b x_b and back
    x_b = np.append(RNG.normal(size=3), 1.0)
    np.testing.assert_allclose(T_inv[0] @ (T[0] @ x_b), x_b, atol=1e-13)


def test_pose_to_transform() -> None:
    T = pose_to_transform([0.1, 0.2, 0.3], [0.0, 0.0, np.pi / 2])
    expected = np.array([[0, -1, 0, 0.1], [1, 0, 0, 0.2], [0, 0, 1, 0.3], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(T, expected, atol=1e-15)


@given(arrays(np.float64, (3,), elements=st.floats(-3, 3)))
@settings(max_examples=30, deadline=None)
def test_rotation_matrices_are_orthonormal(r: np.ndarray) -> None:
    for R in (rotvec_to_matrix(r), rpy_to_matrix(r)):
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-13)
        assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("func", "args", "name"),
    [
        (skew, (np.zeros(4),), "v"),
        (rpy_to_matrix, (np.zeros((2, 2)),), "rpy"),
        (matrix_to_rpy, (np.zeros((3, 4)),), "R"),
        (rotvec_to_matrix, (np.zeros(2),), "r"),
        (matrix_to_rotvec, (np.eye(4),), "R"),
        (make_transform, (np.eye(3), np.zeros(4)), "t"),
        (make_transform, (np.eye(2), np.zeros(3)), "R"),
        (invert_transform, (np.eye(3),), "T"),
        (pose_to_transform, (np.zeros(2), np.zeros(3)), "xyz"),
    ],
)
def test_bad_shapes_raise_input_error(func, args, name) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match=rf"^{name}:"):
        func(*args)
