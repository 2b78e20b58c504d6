"""Renderer accuracy against OpenCV and exact projections."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from controller_stub.geometry import make_transform
from controller_stub.sensors.render import (
    CameraModel,
    DiskPattern,
    Renderer,
    project_points,
    undistort_pixels,
)
from controller_stub.world.simulation import Simulation

CAMERA = CameraModel(1280, 1024, 1400.0, 1395.0, 641.3, 509.7, (-0.08, 0.05, 4e-4, -3e-4, 0.01))
DISK = DiskPattern(radius=0.01, plate_radius=0.05, dot_level=30.0, plate_level=220.0)


def test_projection_matches_opencv() -> None:
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-0.2, 0.2, (50, 2)), rng.uniform(0.3, 0.9, 50)])
    ours = project_points(CAMERA, pts)
    cv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), CAMERA.K, np.array(CAMERA.distortion))
    np.testing.assert_allclose(ours, cv.reshape(-1, 2), atol=1e-9)


def test_undistort_inverts_distortion() -> None:
    rng = np.random.default_rng(1)
    uv = np.column_stack([rng.uniform(0, 1279, 200), rng.uniform(0, 1023, 200)])
    xy = undistort_pixels(CAMERA, uv)
    back = project_points(CAMERA, np.column_stack([xy, np.ones(len(xy))]))
    np.testing.assert_allclose(back, uv, atol=1e-9)


def test_one_pixel_undistort_is_bit_identical() -> None:
    """The board-view sampler's one-pixel path (Python floats) gives the same bits as the
    array path, so the simulated board poses did not change when it got faster."""
    from controller_stub.sensors.board_views import _undistort_pixel

    rng = np.random.default_rng(2)
    for u, v in np.column_stack([rng.uniform(0, 1279, 100), rng.uniform(0, 1023, 100)]):
        expected = undistort_pixels(CAMERA, np.array([[u, v]]))[0]
        assert np.array_equal(_undistort_pixel(CAMERA, float(u), float(v)), expected)


def _centroid(img: np.ndarray, centre: np.ndarray, radius_px: float, plate: float) -> np.ndarray:
    """Intensity-weighted centroid of the dark dot: weights plate - I inside a window."""
    r = int(radius_px * 1.6)
    x0, y0 = int(round(centre[0])) - r, int(round(centre[1])) - r
    win = img[y0 : y0 + 2 * r + 1, x0 : x0 + 2 * r + 1].astype(float)
    w = np.clip(plate - win, 0.0, None)
    ys, xs = np.mgrid[0 : win.shape[0], 0 : win.shape[1]]
    return np.array([np.sum(w * xs) / w.sum() + x0, np.sum(w * ys) / w.sum() + y0])


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.0123, -0.0071), (-0.031, 0.0207)])
def test_disk_centroid_subpixel_exact(offset: tuple[float, float]) -> None:
    renderer = Renderer(CAMERA, 0.0, 0.7, 120.0, np.random.default_rng(2))
    T = make_transform([offset[0], offset[1], 0.3], [0.0, 0.0, 0.3])  # fronto-parallel
    img = renderer.render_disk(T, DISK)
    expected = project_points(CAMERA, T[:3, 3][None])[0]
    found = _centroid(img, expected, 1400 * 0.01 / 0.3, 220.0)
    assert np.linalg.norm(found - expected) < 0.05, (found, expected)


def test_disk_centroid_with_noise() -> None:
    renderer = Renderer(CAMERA, 2.0, 0.7, 120.0, np.random.default_rng(3))
    T = make_transform([0.004, -0.003, 0.3], [0.0, 0.0, 0.0])
    expected = project_points(CAMERA, T[:3, 3][None])[0]
    errors = [
        np.linalg.norm(_centroid(renderer.render_disk(T, DISK), expected, 46.7, 220.0) - expected)
        for _ in range(5)
    ]
    assert np.mean(errors) < 0.05


def test_disk_moves_with_subpixel_shift() -> None:
    """A 0.1 px shift of the target moves the centroid by 0.1 px (no pixel locking)."""
    renderer = Renderer(CAMERA, 0.0, 0.7, 120.0, np.random.default_rng(4))
    px = 0.3 / 1400.0
    found = []
    for k in range(4):
        T = make_transform([k * 0.1 * px, 0.0, 0.3], [0.0, 0.0, 0.0])
        expected = project_points(CAMERA, T[:3, 3][None])[0]
        found.append(_centroid(renderer.render_disk(T, DISK), expected, 46.7, 220.0)[0])
    np.testing.assert_allclose(np.diff(found), 0.1, atol=0.01)


def _area_centroid_of_projected_disk(T_camera_target: np.ndarray, radius: float) -> np.ndarray:
    """(2,) area centroid (px) of the disk's image: its boundary projected (with the
    distortion) at 2048 points, the polygon's centroid by Green's theorem."""
    t = np.linspace(0.0, 2 * np.pi, 2048, endpoint=False)
    ring = np.column_stack([radius * np.cos(t), radius * np.sin(t), np.zeros_like(t)])
    uv = project_points(CAMERA, ring @ T_camera_target[:3, :3].T + T_camera_target[:3, 3])
    x, y = uv[:, 0] - uv[0, 0], uv[:, 1] - uv[0, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum()
    return uv[0] + np.array([((x + x1) * cross).sum(), ((y + y1) * cross).sum()]) / (6 * area)


def test_disk_centroid_is_its_images_area_centroid_at_any_tilt_and_phase() -> None:
    """Noise off: the intensity centroid of a tilted disk at a random sub-pixel phase is the
    area centroid of its (distorted) image to 1e-3 px, as for a sensor whose pixels
    integrate their area. A one-pixel ramp across the edge (the renderer before) left
    0.002-0.004 px RMS, up to ~0.008 px, varying with the phase and the edge direction."""
    renderer = Renderer(CAMERA, 0.0, 0.7, 120.0, np.random.default_rng(6))
    rng = np.random.default_rng(7)
    errors = []
    for _ in range(12):
        tilt, azimuth = np.radians(rng.uniform(10, 45)), rng.uniform(0, 2 * np.pi)
        axis = np.array([np.cos(azimuth), np.sin(azimuth), 0.0]) * tilt
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(axis)[0] @ np.diag([1.0, -1.0, -1.0])
        T[:3, 3] = [rng.uniform(-0.05, 0.05), rng.uniform(-0.04, 0.04), rng.uniform(0.4, 0.6)]
        expected = _area_centroid_of_projected_disk(T, DISK.radius)
        radius_px = 1400.0 * DISK.radius / T[2, 3]
        errors.append(_centroid(renderer.render_disk(T, DISK), expected, radius_px, 220.0)
                      - expected)
    assert np.max(np.abs(errors)) < 1e-3, np.abs(errors).max(axis=0)


def test_chessboard_corners_found_by_opencv(make_sim: Callable[..., Simulation]) -> None:
    sim = make_sim(seed=4)
    corners = sim.stereo.chessboard_corners()
    T_right_left = np.linalg.inv(sim.stereo.T_left_right)
    worst = 0.0
    for view in range(0, sim.scenario.chessboard.n_views, 7):
        frame = sim.capture_stereo("chessboard", view)
        T_left = sim.stereo.chessboard_poses()[view]
        for img, T in ((frame.left, T_left), (frame.right, T_right_left @ T_left)):
            exact = project_points(sim.stereo.camera, corners @ T[:3, :3].T + T[:3, 3])
            ok, found = cv2.findChessboardCornersSB(img, (9, 6), flags=cv2.CALIB_CB_ACCURACY)
            assert ok, f"view {view}: board not found"
            d = np.linalg.norm(found.reshape(-1, 1, 2) - exact[None], axis=2).min(axis=1)
            worst = max(worst, float(d.max()))
    assert worst < 0.1, worst


def test_chessboard_cornersubpix(make_sim: Callable[..., Simulation]) -> None:
    sim = make_sim(seed=4)
    frame = sim.capture_stereo("chessboard", 1)
    T = sim.stereo.chessboard_poses()[1]
    exact = project_points(sim.stereo.camera,
                           sim.stereo.chessboard_corners() @ T[:3, :3].T + T[:3, 3])
    ok, found = cv2.findChessboardCorners(frame.left, (9, 6))
    assert ok
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    refined = cv2.cornerSubPix(frame.left, found, (5, 5), (-1, -1), criteria).reshape(-1, 2)
    d = np.linalg.norm(refined[:, None] - exact[None], axis=2).min(axis=1)
    assert d.max() < 0.15 and d.mean() < 0.06


def test_target_capture_matches_true_projection(
    make_sim: Callable[..., Simulation], pose_looking_at: Callable[..., np.ndarray]
) -> None:
    """The rendered dot is where the TRUE camera pose projects the TRUE target centre."""
    sim = make_sim(seed=6, camera={"pixel_noise_sigma": 0.0})
    q = pose_looking_at(sim, sim.stereo.target_centre, sim.scenario.target.normal, 0.35)
    sim.move_joints(q, 0.5)
    frame = sim.capture_stereo("target")
    T_base_left = sim.camera_pose()
    T_left_base = np.linalg.inv(T_base_left)
    for img, T in (
        (frame.left, T_left_base),
        (frame.right, np.linalg.inv(sim.stereo.T_left_right) @ T_left_base),
    ):
        p = T[:3, :3] @ sim.stereo.target_centre + T[:3, 3]
        expected = project_points(sim.stereo.camera, p[None])[0]
        found = _centroid(img, expected, 1400 * 0.01 / 0.35, 220.0)
        assert np.linalg.norm(found - expected) < 0.1, (found, expected)


def test_target_out_of_view_is_background(make_sim: Callable[..., Simulation]) -> None:
    sim = make_sim()
    frame = sim.capture_stereo("target")  # home pose does not look at the target
    assert abs(float(frame.left.mean()) - 120.0) < 1.0
    assert frame.left.dtype == np.uint8 and frame.left.shape == (1024, 1280)


def test_ray_map_is_kept_between_processes_and_a_broken_cache_is_solved_anew(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The stub's ray map (a third of a second per process) comes from its disk cache the
    second time, equal to the solved one bit for bit; a truncated or wrongly shaped file is
    solved again and rewritten, never used."""
    from controller_stub.sensors import render

    monkeypatch.setenv("ZEROCAL_CACHE_DIR", str(tmp_path))
    camera = render.CameraModel(64, 48, 70.0, 71.0, 31.5, 23.5, (-0.2, 0.08, 1e-3, -2e-3, 0.01))
    render.ray_map.cache_clear()
    solved = render.ray_map(camera)
    path = render.ray_map_cache_file(camera)
    assert path.parent == tmp_path and path.is_file()
    render.ray_map.cache_clear()
    cached = render.ray_map(camera)
    assert all(np.array_equal(a, b) for a, b in zip(solved, cached, strict=True))
    for broken in (b"not a numpy file", None):
        if broken is None:  # a valid file of the wrong shape
            np.save(path, np.zeros((2, 4, 4), np.float32))
        else:
            path.write_bytes(broken)
        render.ray_map.cache_clear()
        again = render.ray_map(camera)
        assert all(np.array_equal(a, b) for a, b in zip(solved, again, strict=True))
        assert np.load(path).shape == (2, 48, 64)
    render.ray_map.cache_clear()


def test_captures_drawn_in_threads_and_ahead_are_the_images_drawn_in_turn(
        make_sim: Callable[..., Simulation], pose_looking_at: Callable[..., np.ndarray]) -> None:
    """`StereoCamera.render` draws left and right in two threads and the next chessboard view
    ahead (the rig calibration's waits overlap); the noise is added in capture order, so any
    sequence of captures (views in turn, a skipped view, an extra view, the target between
    them) is bit for bit what one renderer pair drawing one image after the other makes."""
    sim, plain = make_sim(seed=3), make_sim(seed=3)
    left_r, right_r = plain.stereo.renderers()
    T_right_left = np.linalg.inv(plain.stereo.T_left_right)
    n_views = sim.scenario.chessboard.n_views
    q = pose_looking_at(sim, sim.stereo.target_centre, sim.scenario.target.normal, 0.35)
    for sim_ in (sim, plain):
        sim_.move_joints(q, 0.5)
    for pattern, view in (("chessboard", 0), ("chessboard", 1), ("target", 0),
                          ("chessboard", 2), ("chessboard", 4), ("chessboard", n_views + 1),
                          ("chessboard", 5)):
        frame = sim.capture_stereo(pattern, view)
        if pattern == "target":
            T = np.linalg.inv(plain.camera_pose()) @ plain.stereo.T_base_target
            expected = (left_r.render_disk(T, plain.stereo.disk_pattern),
                        right_r.render_disk(T_right_left @ T, plain.stereo.disk_pattern))
        else:
            T = (plain.stereo.chessboard_poses()[view] if view < n_views
                 else plain.stereo.extra_chessboard_poses()[view - n_views])
            expected = (left_r.render_chessboard(T, plain.stereo.board_pattern),
                        right_r.render_chessboard(T_right_left @ T, plain.stereo.board_pattern))
            assert (view + 1 in sim.stereo._board_ahead) is (view + 1 < n_views)
        assert np.array_equal(frame.left, expected[0]), (pattern, view)
        assert np.array_equal(frame.right, expected[1]), (pattern, view)
