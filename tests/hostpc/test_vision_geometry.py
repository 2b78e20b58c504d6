"""Triangulation, its derivative and covariance, the disk projection model, rectification."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from controller_stub.geometry import make_transform
from controller_stub.sensors.render import CameraModel, DiskPattern, Renderer
from hostpc.vision import StereoRig
from hostpc.vision.rectification import rectification_for
from hostpc.vision.target_detection import DiskBlob, detect_disk
from hostpc.vision.triangulation import (
    CameraModel as DiskCamera,
)
from hostpc.vision.triangulation import (
    disk_image_moments,
    propagate_covariance,
    triangulate,
)

K = np.array([[1400.0, 0.0, 641.3], [0.0, 1400.0, 509.7], [0.0, 0.0, 1.0]])
DIST = np.array([-0.08, 0.05, 4e-4, -3e-4, 0.0])
R = cv2.Rodrigues(np.array([-0.0015, 0.004, -0.001]))[0]
T = np.array([-0.12, 1.2e-4, 4.8e-4])
RIG = StereoRig((1280, 1024), K, DIST, K, DIST, R, T)


def _project(points: np.ndarray, side: str) -> np.ndarray:
    rvec = np.zeros(3) if side == "left" else cv2.Rodrigues(R)[0].ravel()
    tvec = np.zeros(3) if side == "left" else T
    return cv2.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, K, DIST)[0].reshape(-1, 2)


def test_triangulation_inverts_projection_and_derivative_matches() -> None:
    rect = rectification_for(RIG)
    assert rectification_for(RIG) is rect  # cached per rig
    assert rect.baseline == pytest.approx(0.12, rel=1e-5)
    rng = np.random.default_rng(0)
    for p in np.column_stack([rng.uniform(-0.1, 0.2, 5), rng.uniform(-0.1, 0.1, 5),
                              rng.uniform(0.3, 1.0, 5)]):
        uv_l, uv_r = _project(p, "left")[0], _project(p, "right")[0]
        tri = triangulate(rect, uv_l, uv_r)
        np.testing.assert_allclose(tri.p, p, atol=1e-9)
        assert abs(tri.dy) < 1e-6
        h = 1e-3
        numeric = np.empty((3, 4))
        for k in range(4):
            du = np.zeros(4)
            du[k] = h
            plus = triangulate(rect, uv_l + du[:2], uv_r + du[2:]).p
            minus = triangulate(rect, uv_l - du[:2], uv_r - du[2:]).p
            numeric[:, k] = (plus - minus) / (2 * h)
        np.testing.assert_allclose(tri.dp_duv, numeric, rtol=1e-4, atol=1e-10)


def test_covariance_scales_with_depth() -> None:
    rect = rectification_for(RIG)
    sigmas = []
    for z in (0.5, 1.0):
        p = np.array([0.06, 0.0, z])
        tri = triangulate(rect, _project(p, "left")[0], _project(p, "right")[0])
        cov = propagate_covariance(tri.dp_duv, 0.01 * np.eye(2), 0.01 * np.eye(2))
        sigmas.append(np.sqrt(np.diag(cov)))
        # depth: Z^2 / (f B) * sqrt(2) * 0.1 px
        assert sigmas[-1][2] == pytest.approx(z * z / (1400 * 0.12) * math.sqrt(2) * 0.1,
                                              rel=0.05)
    assert sigmas[1][2] / sigmas[0][2] == pytest.approx(4.0, rel=0.05)  # depth ~ Z^2
    assert sigmas[1][1] / sigmas[0][1] == pytest.approx(2.0, rel=0.05)  # lateral ~ Z


def test_disk_model_fronto_parallel_is_unbiased() -> None:
    cam = DiskCamera(K, np.zeros(5), np.eye(3), np.zeros(3))
    image = disk_image_moments([cam], np.array([[0.05, -0.03, 0.5]]),
                               np.array([[0.0, 0.0, -1.0]]), 0.01)[0]
    r_px = 1400 * 0.01 / 0.5
    np.testing.assert_allclose(image.bias, 0.0, atol=1e-9)
    assert image.area[0] == pytest.approx(math.pi * r_px**2, rel=1e-3)
    np.testing.assert_allclose(image.moments[0], np.eye(2) * r_px**2 / 4, rtol=1e-3, atol=1e-9)


@pytest.mark.parametrize("rpy", [(math.pi + 0.4, 0.0, 0.0), (math.pi, 0.5, 0.7)])
def test_disk_model_matches_renderer_and_detector(rpy: tuple[float, float, float]) -> None:
    """The model's area centroid equals the rendered disk's intensity centroid (found by
    the detector) and differs from the projected centre by the perspective bias."""
    camera = CameraModel(1280, 1024, 1400.0, 1400.0, 641.3, 509.7, tuple(DIST))  # type: ignore[arg-type]
    renderer = Renderer(camera, 0.0, 0.7, 120.0, np.random.default_rng(0))
    T_cam_target = make_transform([0.04, 0.03, 0.3], list(rpy))
    image = renderer.render_disk(T_cam_target, DiskPattern(0.01, 0.05, 30.0, 220.0))
    blob = detect_disk(image)
    assert isinstance(blob, DiskBlob), blob
    cam = DiskCamera(K, DIST, np.eye(3), np.zeros(3))
    model = disk_image_moments([cam], T_cam_target[:3, 3][None], T_cam_target[:3, 2][None],
                               0.01)[0]
    np.testing.assert_allclose(blob.centroid, model.centroid[0], atol=0.01)
    assert np.linalg.norm(model.bias[0]) > 0.2  # 0.3 m, tilted: the bias is real
    assert blob.area == pytest.approx(model.area[0], rel=0.01)
    anisotropy = blob.moments[0, 0] - blob.moments[1, 1]
    assert anisotropy == pytest.approx(model.moments[0, 0, 0] - model.moments[0, 1, 1],
                                       abs=0.5)
    assert blob.plate_offset is not None and np.linalg.norm(blob.plate_offset) > 3.0


def test_rectified_images_are_row_aligned() -> None:
    rect = rectification_for(RIG)
    maps = rect.maps()
    assert rect.maps() is maps  # built once
    p = np.array([0.05, 0.02, 0.6])
    rows = [rect.rectify_points(_project(p, side), side)[0, 1] for side in ("left", "right")]
    assert rows[0] == pytest.approx(rows[1], abs=1e-6)
