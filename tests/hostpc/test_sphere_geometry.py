"""Closed-form sphere_probe estimates (hostpc.kinds.sphere_probe.planning.geometry)."""

from __future__ import annotations

import numpy as np
import pytest

from hostpc.kinds.sphere_probe.planning.geometry import (
    SphereFitError,
    fit_sphere,
    initial_estimate,
    mean_rotation,
    orientation_centres,
    tip_and_centre_linear,
)
from hostpc.kinematics import rotvec_to_matrix

RHO = 0.014
CENTRE = np.array([0.45, -0.15, 0.05])
TIP = np.array([0.0004, -0.0003, 0.1206])


def cap_points(centre: np.ndarray, radius: float, n: int, rng: np.random.Generator,
               half_angle: float = 0.7) -> np.ndarray:
    polar = half_angle * np.sqrt(rng.uniform(0, 1, n))
    azimuth = rng.uniform(0, 2 * np.pi, n)
    u = np.column_stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                         np.cos(polar)])
    return centre + radius * u


def test_fit_sphere_free_and_known_radius() -> None:
    rng = np.random.default_rng(1)
    points = cap_points(CENTRE, RHO, 12, rng)
    free = fit_sphere(points)
    assert np.allclose(free.centre, CENTRE, atol=1e-12) and free.radius == pytest.approx(RHO)
    known = fit_sphere(points[:3], RHO, centre_guess=CENTRE + 1e-3)
    assert np.allclose(known.centre, CENTRE, atol=1e-12) and known.rms < 1e-12


def test_fit_sphere_with_noise_has_geometric_residuals() -> None:
    rng = np.random.default_rng(2)
    points = cap_points(CENTRE, RHO, 200, rng, half_angle=1.2)
    points += rng.normal(0, 1e-6, points.shape)
    result = fit_sphere(points, RHO)
    assert np.linalg.norm(result.centre - CENTRE) < 1e-6
    assert result.rms == pytest.approx(1e-6, rel=0.2)


def test_fit_sphere_rejects_degenerate_input() -> None:
    with pytest.raises(SphereFitError):
        fit_sphere(np.zeros((2, 3)), RHO)
    with pytest.raises(SphereFitError):
        fit_sphere(np.zeros((5, 2)))
    circle = np.array([[np.cos(a), np.sin(a), 0.0] for a in np.linspace(0, 5, 6)])
    with pytest.raises(SphereFitError):
        fit_sphere(circle)  # coplanar: radius and centre height not determined


def contacts(n_orientations: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Exact flange poses (N, 4, 4) touching the sphere, 5 per orientation, and groups."""
    T = []
    groups = []
    for g in range(n_orientations):
        R = rotvec_to_matrix(rng.normal(0, 0.4, 3)) @ np.diag([1.0, -1.0, -1.0])
        for u in cap_points(np.zeros(3), 1.0, 5, rng, half_angle=0.8):
            tip = CENTRE + RHO * (R @ u)  # on the stylus side of the sphere (R z = -z)
            pose = np.eye(4)
            pose[:3, :3] = R
            pose[:3, 3] = tip - R @ TIP
            T.append(pose)
            groups.append(g)
    return np.array(T), np.array(groups)


def test_initial_estimate_recovers_centre_and_tip() -> None:
    T, groups = contacts(20, np.random.default_rng(3))
    estimate = initial_estimate(T, groups, RHO)
    assert np.linalg.norm(estimate.sphere_centre - CENTRE) < 1e-10
    assert np.linalg.norm(estimate.tip - TIP) < 1e-10
    # the patent's own steps (S4, S7, S8-S9) are exact on exact data too
    assert np.linalg.norm(estimate.patent_sphere_centre - CENTRE) < 1e-8
    assert np.linalg.norm(estimate.patent_tip - TIP) < 1e-8
    assert len(estimate.centres) == 20 and estimate.rms < 1e-12
    for c in estimate.centres:  # S4: P_c = P_b - R_k P_t
        assert np.allclose(c.centre, CENTRE - c.rotation @ TIP, atol=1e-10)


def test_known_frames_are_held() -> None:
    T, groups = contacts(6, np.random.default_rng(4))
    shifted = CENTRE + np.array([1e-3, 0, 0])
    estimate = initial_estimate(T, groups, RHO, known_sphere_centre=shifted)
    assert np.array_equal(estimate.sphere_centre, shifted)
    estimate = initial_estimate(T, groups, RHO, known_tip=TIP)
    assert np.array_equal(estimate.tip, TIP)
    assert np.linalg.norm(estimate.sphere_centre - CENTRE) < 1e-10


def test_too_few_orientations_is_an_error() -> None:
    T, groups = contacts(1, np.random.default_rng(5))
    with pytest.raises(SphereFitError, match="orientations"):
        initial_estimate(T, groups, RHO)
    centres = orientation_centres(T, groups, RHO)
    with pytest.raises(SphereFitError):
        tip_and_centre_linear(np.array([c.centre for c in centres] * 3),
                              np.array([c.rotation for c in centres] * 3))


def test_mean_rotation_of_identical_rotations() -> None:
    R = rotvec_to_matrix(np.array([0.1, -0.2, 0.3]))
    assert np.allclose(mean_rotation(np.array([R, R, R])), R)
