"""The disk centre's error against rendered truth: the detector's noise estimate and the
centroid covariance it reports (bench/bench_centre_error.py prints the full table)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from controller_stub.sensors.render import CameraModel as RenderCamera
from controller_stub.sensors.render import DiskPattern, Renderer
from hostpc.vision.target_detection import DiskBlob, detect_disk
from hostpc.vision.triangulation import CameraModel, disk_image_moments

DISTORTION = (-0.08, 0.05, 4e-4, -3e-4, 0.0)
CAMERA = RenderCamera(1280, 1024, 1400.0, 1400.0, 641.3, 509.7, DISTORTION)
MODEL = CameraModel(CAMERA.K, np.array(DISTORTION), np.eye(3), np.zeros(3))
DISK = DiskPattern(radius=0.01, plate_radius=0.05, dot_level=30.0, plate_level=220.0)
NOISE = 2.0


def _tilted(rng: np.random.Generator, tilt_deg: float, distance: float) -> np.ndarray:
    """T_camera_target: the plate tilted by tilt_deg about a random in-plane axis, the disk
    somewhere in the middle two thirds of the image at `distance` (m)."""
    azimuth = rng.uniform(0.0, 2 * math.pi)
    T = np.eye(4)
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0]) * math.radians(tilt_deg)
    T[:3, :3] = cv2.Rodrigues(axis)[0] @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [rng.uniform(-0.25, 0.25) * distance, rng.uniform(-0.2, 0.2) * distance,
                distance]
    return T


def _measured(seed: int, T: np.ndarray) -> DiskBlob:
    """The disk in one render with its own noise field (independent draws per image)."""
    renderer = Renderer(CAMERA, NOISE, 0.7, 120.0, np.random.default_rng(seed))
    blob = detect_disk(renderer.render_disk(T, DISK))
    assert isinstance(blob, DiskBlob), blob
    return blob


def test_plate_noise_estimate_is_unbiased_for_8_bit_images() -> None:
    """The noise on the plate (2 grey levels, then rounded to 8 bits: sqrt(4 + 1/12)) is
    estimated without bias. The first clip of the integer levels, at 4 MADs, cut at 2.5
    sigma and left the estimate 2.7 % low (5.5 % in the centroid's variance)."""
    rng = np.random.default_rng(11)
    estimates = [_measured(100 + k, _tilted(rng, 20.0, 0.5)).noise_sigma for k in range(30)]
    expected = math.sqrt(NOISE**2 + 1.0 / 12.0)
    assert abs(np.mean(estimates) / expected - 1.0) < 0.012, np.mean(estimates)


def test_whitened_centre_error_of_steep_views_has_unit_mean_square() -> None:
    """At 45 deg tilt, 0.5 m: the centroid minus the disk model's perspective bias (true
    normal, true camera) against the true projection, whitened by the reported centroid
    covariance, has a mean square of 1 per coordinate (60 images, 120 values: 0.75-1.3).
    A guard against a covariance that goes wrong, not a test of the fixes: the code before
    them gives 1.08 here (their effect, 1.18 -> 1.03 over many poses, is smaller than this
    test's resolution; bench/bench_centre_error.py measures it)."""
    rng = np.random.default_rng(12)
    whitened = []
    for k in range(60):
        T = _tilted(rng, 45.0, 0.5)
        blob = _measured(200 + k, T)
        normal = T[:3, 2] if T[2, 2] < 0 else -T[:3, 2]
        disk = disk_image_moments([MODEL], T[:3, 3][None], normal[None], DISK.radius)[0]
        error = blob.centroid - disk.centroid[0]
        whitened.append(0.5 * float(error @ np.linalg.solve(blob.centroid_cov, error)))
    assert 0.75 < np.mean(whitened) < 1.3, np.mean(whitened)
