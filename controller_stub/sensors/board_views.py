"""Chessboard views for the simulated rig calibration: board poses relative to the left
camera, drawn by rejection so the whole board is inside both images.

Split from render.py (the images) because it is its own concept: where the operator holds
the board. Angles in radians, lengths in metres, pixels with the origin at the first pixel's
centre (render.py).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from controller_stub.geometry import rpy_to_matrix
from controller_stub.sensors.render import CameraModel, ChessboardPattern, project_points


def _undistort_pixel(camera: CameraModel, u: float, v: float, tol: float = 1e-14
                     ) -> np.ndarray:
    """render.undistort_pixels for one pixel (2,), in Python floats: the same operations in the
    same order, so the same bits, without numpy's per-call overhead (the board-view
    sampler calls it thousands of times)."""
    k1, k2, p1, p2, k3 = (float(c) for c in camera.distortion)
    xd = (u - camera.cx) / camera.fx
    yd = (v - camera.cy) / camera.fy
    x, y = xd, yd
    for _ in range(20):
        x2, y2, xy = x * x, y * y, x * y
        r2 = x2 + y2
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        ex = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2) - xd
        ey = y * radial + p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy - yd
        jxx = radial + 2.0 * x2 * d_radial + 2.0 * p1 * y + 6.0 * p2 * x
        jyy = radial + 2.0 * y2 * d_radial + 6.0 * p1 * y + 2.0 * p2 * x
        jxy = 2.0 * xy * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
        det = jxx * jyy - jxy * jxy
        x -= (jyy * ex - jxy * ey) / det
        y -= (jxx * ey - jxy * ex) / det
        if abs(ex) < tol and abs(ey) < tol:
            break
    return np.array([x, y])


def chessboard_views(
    camera: CameraModel,
    T_left_right: np.ndarray,
    pattern: ChessboardPattern,
    n_views: int,
    distance_range: tuple[float, float],
    max_tilt_rad: float,
    rng: np.random.Generator,
    border_px: float = 12.0,
    centre_range: tuple[float, float] = (0.2, 0.8),
) -> np.ndarray:
    """(n_views, 4, 4) board poses T_leftcamera_board with the whole board (incl. margin)
    inside both images, distance of the board centre 0.3-0.8 m (distance_range), tilted up
    to max_tilt_rad about a random in-plane axis, rolled freely about the normal by up to
    +-30 deg around the upright orientation, its centre aimed at a pixel drawn within
    `centre_range` (fractions of the image size). Drawn from `rng` by rejection."""
    u_min, u_max, v_min, v_max = pattern.outline()
    centre = np.array([0.5 * (u_min + u_max), 0.5 * (v_min + v_max), 0.0])
    outline = pattern.outline_points(9)
    outline3 = np.column_stack([outline, np.zeros(len(outline))])
    T_right_left = np.linalg.inv(T_left_right)
    views: list[np.ndarray] = []
    d_lo, d_hi = distance_range
    attempts = 0
    while len(views) < n_views:
        attempts += 1
        if attempts > 200000:
            raise ValueError("chessboard: cannot place the board inside both images")
        dist = rng.uniform(d_lo, d_hi)  # rejection keeps the distances where the board fits
        tilt = rng.uniform(0.0, max_tilt_rad)
        axis_angle = rng.uniform(0.0, 2 * math.pi)
        roll = rng.uniform(-math.pi / 6, math.pi / 6)
        px = rng.uniform(*centre_range) * camera.width
        py = rng.uniform(*centre_range) * camera.height
        # board facing the camera: board z along camera +z (board behind its printed side)
        axis = np.array([math.cos(axis_angle), math.sin(axis_angle), 0.0])
        R_tilt = cv2.Rodrigues(axis * tilt)[0]
        R = R_tilt @ rpy_to_matrix([0.0, 0.0, roll])
        ray = _undistort_pixel(camera, px, py)
        p_centre = dist * np.array([ray[0], ray[1], 1.0]) / math.sqrt(1 + ray @ ray)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = p_centre - R @ centre
        ok = True
        for T_cam in (T, T_right_left @ T):
            pts = outline3 @ T_cam[:3, :3].T + T_cam[:3, 3]
            if np.any(pts[:, 2] < 0.05):
                ok = False
                break
            uv = project_points(camera, pts)
            if (
                uv[:, 0].min() < border_px
                or uv[:, 1].min() < border_px
                or uv[:, 0].max() > camera.width - 1 - border_px
                or uv[:, 1].max() > camera.height - 1 - border_px
            ):
                ok = False
                break
        if ok:
            views.append(T)
    return np.stack(views)
